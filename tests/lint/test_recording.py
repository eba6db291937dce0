"""Recordings: our JSON Lines format, mosquitto_sub -F %j / -F %J output (the real program
against the local Mosquitto), malformed lines."""

from __future__ import annotations

import io
import queue
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest

from conformance import recording
from conformance.client import BrokerURL, Message, MqttClient
from conformance.recording import (
    FORMAT_MOSQUITTO_J,
    FORMAT_MOSQUITTO_JJ,
    FORMAT_MOSQUITTO_V,
    UNTIMED,
    Event,
    RecordingReader,
    RecordingWriter,
    encode_message,
    parse_tst,
)


def read(data: bytes) -> tuple[list[Message | Event], RecordingReader]:
    reader = RecordingReader(io.BytesIO(data), "test.jsonl")
    return list(reader), reader


MESSAGES = [
    Message(1763706393.546275, "waraps/unit/air/simulation/dji0/heartbeat",
            b'{"name": "dji0", "rate": 1.0}', 0, False),
    Message(1763706393.6, "waraps/unit/air/simulation/dji0/sensor/speed", b"3.5", 1, True),
    Message(1763706393.7, "waraps/unit/air/simulation/dji0/sensor/x", b"\xff\xfe\x00bin", 0, False),
    Message(1763706393.8, "waraps/unit/air/simulation/dji0/sensor/y", b"", 2, False),
    Message(1763706393.9, "waraps/unit/air/simulation/dji0/sensor/z", "é\u0001\"\\\n".encode(), 0, False),
]


def test_jsonl_round_trip_is_byte_exact_with_events() -> None:
    out = io.BytesIO()
    w = RecordingWriter(out)
    w.write(MESSAGES[0])
    w.write(Event(1763706393.55, "disconnected", "connection lost"))
    w.write(Event(1763706393.56, "connected"))
    w.write(Event(1763706393.57, "unexamined", "fell behind", 42))
    for m in MESSAGES[1:]:
        w.write(m)
    items, reader = read(out.getvalue())
    assert [i for i in items if isinstance(i, Message)] == MESSAGES
    assert [i for i in items if isinstance(i, Event)] == [
        Event(1763706393.55, "disconnected", "connection lost"), Event(1763706393.56,
                                                                        "connected"),
        Event(1763706393.57, "unexamined", "fell behind", 42)]
    assert reader.problem_count == 0 and reader.messages == len(MESSAGES)
    assert w.messages == len(MESSAGES)
    # Binary payloads go as base64, text as text (readable with jq).
    assert b'"payload_b64"' in encode_message(MESSAGES[2])
    assert orjson.loads(encode_message(MESSAGES[0]))["payload"] == '{"name": "dji0", "rate": 1.0}'


def test_minimal_lines_from_other_tools_are_read() -> None:
    items, reader = read(b'{"ts": 1700000000, "topic": "a/b", "payload": "x"}\n'
                         b'{"ts": 1700000001.5, "topic": "a/c", "payload_b64": "AAE=", "retain": 1}\r\n')
    assert items == [Message(1700000000.0, "a/b", b"x"),
                     Message(1700000001.5, "a/c", b"\x00\x01", 0, True)]


def test_malformed_lines_are_reported_with_their_number_and_the_rest_is_read() -> None:
    lines = [
        b'{"ts": 1.0, "topic": "a/b", "payload": "ok1"}',
        b"this is not json",
        b"[1, 2]",
        b'{"ts": 2.0, "payload": "no topic"}',
        b'{"ts": "yesterday", "topic": "a/b", "payload": "x"}',
        b'{"ts": 3.0, "topic": "a/b", "payload_b64": "***"}',
        b'{"ts": 3.0, "topic": "a/b"}',
        b'{"ts": 3.0, "topic": "a/b", "payload": "x", "qos": 7}',
        b'{"topic": "a/b", "payload": "x"}',
        b'{"ts": 3.0, "event": "exploded"}',
        b"",
        b'{"ts": 4.0, "topic": "a/b", "payload": "ok2"}',
    ]
    items, reader = read(b"\n".join(lines) + b"\n")
    assert [m.payload for m in items] == [b"ok1", b"ok2"]
    assert [p.line for p in reader.problems] == [2, 3, 4, 5, 6, 7, 8, 9, 10]
    text = "\n".join(map(str, reader.problems))
    for expected in ["line 2: not JSON", "line 3: a list, not an object", "'topic' is missing",
                     "'ts' is 'yesterday'", "not base64", "neither 'payload'",
                     "'qos' is 7", "neither 'ts'", "event 'exploded'"]:
        assert expected in text
    assert reader.lines == 12 and reader.blank_lines == 1


def test_overlong_line_is_skipped_and_reading_goes_on(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(recording, "MAX_LINE_BYTES", 64)
    data = (b'{"ts": 1.0, "topic": "a/b", "payload": "' + b"x" * 500 + b'"}\n'
            b'{"ts": 2.0, "topic": "a/b", "payload": "ok"}\n')
    items, reader = read(data)
    assert [m.payload for m in items] == [b"ok"]
    assert reader.problems[0].line == 1 and "longer than" in reader.problems[0].problem


def test_problems_kept_are_bounded() -> None:
    items, reader = read(b"garbage\n" * 1000)
    assert reader.problem_count == 1000 and len(reader.problems) == recording.MAX_PROBLEMS_KEPT


@pytest.mark.parametrize(("tst", "expected"), [
    ("2026-11-21T06:26:33.546275Z+0000", 1795242393.546275),
    ("2026-11-21T07:26:33.546275Z+0100", 1795242393.546275),
    ("2026-11-21T01:26:33.546275Z-0500", 1795242393.546275),
    ("2026-11-21T06:26:33Z", 1795242393.0),
    ("2026-11-21T06:26:33.5Z+00:00", 1795242393.5),
])
def test_mosquitto_tst_is_local_time_with_a_stray_z_and_the_offset(tst: str, expected: float) -> None:
    assert parse_tst(tst) == pytest.approx(expected, abs=1e-6)


def test_bad_tst_is_a_line_problem() -> None:
    items, reader = read(b'{"tst": "yesterday", "topic": "a", "qos": 0, "retain": 0, '
                         b'"payloadlen": 1, "payload": "x"}\n')
    assert not items and "ISO 8601" in reader.problems[0].problem


# --- the real mosquitto_sub 2.0.11 --------------------------------------------------------------

SAMPLES = [
    ("json", b'{"a": 1, "b": "x"}'),
    ("text", b'hello "world"'),
    ("binary", b"\xff\xfe\x01bin"),
    ("nul", b'{"a": 1}\x00tail'),
    ("empty", b""),
    ("control", "a\u0001bé\x7f\"\\\nz".encode()),
    ("number", b"42"),
    ("nan", b'{"a": NaN}'),
    ("string", b'"just a string"'),
]


@pytest.fixture
def publisher(mosquitto: str, prefix: str) -> Iterator[MqttClient]:
    with MqttClient(BrokerURL.parse(mosquitto), may_publish=lambda t: t.startswith(prefix + "/")) as c:
        yield c


def capture_mosquitto_sub(fmt: str, prefix: str, publisher: MqttClient) -> bytes:
    """Run mosquitto_sub -F FMT, wait (deadline) until it receives, publish SAMPLES, return
    its output from the first sample on."""
    exe = shutil.which("mosquitto_sub")
    if exe is None:
        pytest.skip("mosquitto_sub is not installed")
    form = ["-v"] if fmt == "-v" else ["-F", fmt]
    proc = subprocess.Popen([exe, "-h", "127.0.0.1", "-p", "1883", "-t", f"{prefix}/#", *form],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    lines: queue.Queue[bytes] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(ln) for ln in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
    try:
        deadline = time.monotonic() + 10
        while True:  # mosquitto_sub has no "subscribed" signal: probe until it sees one
            assert time.monotonic() < deadline, "mosquitto_sub never received a probe"
            publisher.publish(f"{prefix}/probe", b'"probe"', qos=1)
            try:
                if b"probe" in lines.get(timeout=0.3):
                    break
            except queue.Empty:
                pass
        for name, payload in SAMPLES:
            publisher.publish(f"{prefix}/s/{name}", payload, qos=1)
        publisher.publish(f"{prefix}/end", b'"end"', qos=1)
        got: list[bytes] = []
        while not got or b"/end" not in got[-1]:
            got.append(lines.get(timeout=10))
        return b"".join(ln for ln in got if b"/probe" not in ln and b"/end" not in ln)
    finally:
        proc.terminate()
        proc.wait(5)


@pytest.mark.mosquitto
def test_mosquitto_sub_j_format_recovers_every_payload(prefix: str, publisher: MqttClient) -> None:
    data = capture_mosquitto_sub("%j", prefix, publisher)
    items, reader = read(data)
    got = {m.topic.rsplit("/", 1)[1]: m.payload for m in items}
    assert reader.problem_count == 0 and reader.formats == {FORMAT_MOSQUITTO_J}
    for name, payload in SAMPLES:
        if name == "nul":  # cut at the NUL by mosquitto_sub: the cut marked by one NUL
            assert got[name] == b'{"a": 1}' + b"\x00"
        else:
            assert got[name] == payload, name
    assert any("cut at a NUL byte" in n for n in reader.notes)
    assert all(abs(m.time - time.time()) < 60 for m in items)  # tst read as the right instant


@pytest.mark.mosquitto
def test_mosquitto_sub_big_j_format_reserialises_and_loses_non_json(prefix: str,
                                                                    publisher: MqttClient) -> None:
    data = capture_mosquitto_sub("%J", prefix, publisher)
    items, reader = read(data)
    got = {m.topic.rsplit("/", 1)[1]: m.payload for m in items}
    assert reader.formats == {FORMAT_MOSQUITTO_JJ} and reader.problem_count == 0
    assert orjson.loads(got["json"]) == {"a": 1, "b": "x"}
    assert got["number"] == b"42" and got["empty"] == b"" and got["string"] == b'"just a string"'
    lost = {"text", "binary", "nul", "control", "nan"}
    assert not lost & set(got)
    assert reader.unprintable == len(lost)
    assert any("missing from this mosquitto_sub -F %J recording" in n for n in reader.notes)


@pytest.mark.mosquitto
def test_mosquitto_sub_v_format_is_told_from_its_content(prefix: str,
                                                         publisher: MqttClient) -> None:
    """TOPIC PAYLOAD per line, no times; read as messages of the time they were
    read, after an UNTIMED event (the rules that need times are not judged). A payload with a
    newline is cut there by the format itself: its continuation is a problem of its line."""
    data = capture_mosquitto_sub("-v", prefix, publisher)
    before = time.time()
    items, reader = read(data)
    assert reader.formats == {FORMAT_MOSQUITTO_V}
    assert isinstance(items[0], Event) and items[0].kind == UNTIMED
    got = {m.topic.rsplit("/", 1)[1]: m.payload for m in items if isinstance(m, Message)}
    for name, payload in SAMPLES:
        if name == "nul":  # mosquitto_sub -v prints up to the NUL (the rest is lost)
            assert got[name].startswith(b'{"a": 1}'), got[name]
        elif name == "control":  # the newline ends the line
            assert got[name] == payload.split(b"\n")[0]
        else:
            assert got[name] == payload, name  # "(null)" read back as the empty payload
    assert all(before <= m.time <= time.time() for m in items)
    assert reader.problem_count == 1 and reader.problems[0].text == "z"


@pytest.mark.mosquitto
def test_record_to_a_pipe_passes_on_a_steady_trickle(mosquitto: str, prefix: str,
                                                     publisher: MqttClient) -> None:
    """``record -o -`` feeds a live pipe (``lint --from -``): a stream that never pauses is
    still written out as it comes, not when an output buffer fills."""
    import os

    from lint_helpers import Process

    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # a real pipe
    proc = Process(["record", "--broker", mosquitto, "--topic", f"{prefix}/#", "-o", "-"],
                   env=env)
    try:
        proc.wait_for("recording ")
        sent = 0
        while not any('"topic"' in line for line in proc.lines):
            assert sent < 25, f"nothing written after {sent} messages at 10/s: {proc.output}"
            publisher.publish(f"{prefix}/unit/air/simulation/dji0/sensor/speed", b"1.0", qos=0)
            sent += 1
            time.sleep(0.1)  # the trickle's pace (a schedule, not a wait for a result)
    finally:
        proc.interrupt()


def test_json_text_is_written_without_recursion_at_any_depth() -> None:
    """What orjson writes where it can; deeper (999 levels: once a RecursionError
    in the json fallback) with an explicit stack; a string of surrogate escapes (a line that
    was not UTF-8) as the bytes it stands for."""
    import json

    import orjson

    from conformance.jsontext import dumps

    shallow = {"a": [1, 2.5, None, True, "x\u00e9"], "b": {}}
    assert dumps(shallow) == orjson.dumps(shallow)
    deep = orjson.loads(b"[" * 999 + b'{"k":1}' + b"]" * 999)
    assert dumps(deep) == b"[" * 999 + b'{"k":1}' + b"]" * 999
    mixed: object = [{"k": [1]}]
    for _ in range(300):
        mixed = {"a": mixed, "b": [mixed and 2]}
    assert json.loads(dumps(mixed)) == mixed
    escaped = b'{"volt\xb1age":1}'.decode("utf-8", "surrogateescape")
    assert dumps(json.loads(escaped)) == b'{"volt\xb1age":1}'


# --- record -o FILE: never destroys a file, writes nothing it could not record ---------------
def record_main(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``waraps-conformance record ARGS`` in process: its exit status and standard error."""
    from conformance.cli import main

    try:
        status = main(["record", *args])
    except SystemExit as e:  # argparse's own errors
        status = int(e.code or 0)
    return status, capsys.readouterr().err


UNREACHABLE = ["--broker", "mqtt://127.0.0.1:1", "--duration", "1s"]


def test_record_over_an_existing_file_leaves_it_intact_without_force(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "field-test.jsonl"
    kept = b'{"kind":"start"}\n' * 1000  # an earlier recording
    out.write_bytes(kept)
    status, err = record_main([*UNREACHABLE, "-o", str(out)], capsys)
    assert status == 2, err
    assert f"{out} exists; pass --force to replace it" in err
    assert out.read_bytes() == kept


def test_record_writes_nothing_when_it_cannot_connect(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "never.jsonl"
    status, err = record_main([*UNREACHABLE, "-o", str(out)], capsys)
    assert status == 3 and "cannot reach the broker" in err, err
    assert not out.exists()  # no 0-byte file
    # and --force over an existing file replaces it only once there is a recording
    kept = b'{"kind":"start"}\n'
    out.write_bytes(kept)
    status, err = record_main([*UNREACHABLE, "--force", "-o", str(out)], capsys)
    assert status == 3, err
    assert out.read_bytes() == kept


@pytest.mark.mosquitto
def test_record_force_replaces_an_existing_file(mosquitto: str, prefix: str, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "field-test.jsonl"
    out.write_bytes(b"old\n")
    status, err = record_main(["--broker", mosquitto, "--topic", f"{prefix}/#",
                               "--duration", "0.5s", "--force", "-o", str(out)], capsys)
    assert status == 0, err
    events = [item for item in read(out.read_bytes())[0] if isinstance(item, Event)]
    assert [e.kind for e in events] == ["start", "end"], out.read_bytes()

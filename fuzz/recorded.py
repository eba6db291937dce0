"""What the recording targets share: lines of each recording format built from fuzzed fields
(``conformance.recording``), and the reader's invariant.

The invariant of a recording: ``RecordingReader`` never raises; it yields only
``Message`` and ``Event`` items, messages at times within ``bounds`` (a ``-v`` line: now), and
every bad line is a one-line ``LineProblem``; each message it yields (held one at a time) is
within 1 MiB + 64 times the input (padding is never materialised to ``payloadlen``); the ``Monitor`` judges every message without
raising; all within ``harness.within_time``.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable

import atheris
import orjson

from conformance.bounds import MAX_TIME, MIN_TIME
from conformance.checks import Monitor
from conformance.message import Message
from conformance.recording import Event, RecordingReader
from fuzz.harness import Broken, one_line, proportional, within_time

UNIT = "waraps/unit/air/simulation/dji0"
TOPICS = [f"{UNIT}/{sub}" for sub in (
    "heartbeat", "sensor_info", "direct_execution_info", "sensor/position", "sensor/speed",
    "exec/command", "exec/response", "exec/feedback", "tst_execution_info")] + [
    "waraps/unit/ground/real/husky0/heartbeat", "waraps/unit/a#b/heartbeat", "a/b"]
PAYLOADS = [
    b'{"name":"dji0","agent-type":"air","agent-description":"d","agent-uuid":"u","levels":'
    b'["sensor"],"rate":1.0,"stamp":1763700000.0,"type":"HeartBeat"}',
    b'{"latitude":57.7,"longitude":11.9,"altitude":10.0}', b"0.1", b'"x"', b"[]", b"{}",
    b'{"command":"ping","com-uuid":"c","sender":"op0"}', b"", b"null", b"\xff\xfe",
    b"[" * 300 + b"]" * 300, b"NaN"]
T0 = 1_763_700_000.0


def topic(fdp: atheris.FuzzedDataProvider) -> str:
    if fdp.ConsumeBool():
        return fdp.PickValueInList(TOPICS)
    return fdp.ConsumeUnicode(fdp.ConsumeIntInRange(0, 80))


def payload(fdp: atheris.FuzzedDataProvider) -> bytes:
    if fdp.ConsumeBool():
        return fdp.PickValueInList(PAYLOADS)
    return fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 400))


def number(fdp: atheris.FuzzedDataProvider, near: float) -> object:
    """A time or a count: usually plausible, sometimes of a wrong type or out of range."""
    pick = fdp.ConsumeIntInRange(0, 7)
    if pick < 4:
        return near + fdp.ConsumeFloatInRange(-10.0, 100.0)
    return (fdp.ConsumeFloat(), fdp.ConsumeInt(8), fdp.ConsumeUnicode(8), None)[pick - 4]


def lines(fdp: atheris.FuzzedDataProvider, make, count: int = 24) -> bytes:
    """Up to ``count`` lines, each from ``make(fdp)`` or (sometimes) raw bytes."""
    out = []
    for _ in range(fdp.ConsumeIntInRange(1, count)):
        if fdp.remaining_bytes() == 0:
            break
        out.append(make(fdp) if fdp.ConsumeProbability() < 0.9
                   else fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 200)))
    return b"\n".join(out) + (b"\n" if fdp.ConsumeBool() else b"")


def text(raw: bytes) -> str:
    return raw.decode("utf-8", "surrogateescape")


def dumps(obj: dict) -> bytes:
    try:
        return orjson.dumps(obj)
    except orjson.JSONEncodeError:  # surrogates: bytes as they are, as mosquitto_sub copies them
        import json
        return json.dumps(obj, ensure_ascii=False).encode("utf-8", "surrogatepass")


def jsonl_line(fdp: atheris.FuzzedDataProvider) -> bytes:
    obj: dict[str, object] = {"ts": number(fdp, T0)}
    if fdp.ConsumeProbability() < 0.15:
        obj["event"] = fdp.PickValueInList(["disconnected", "connected", "unexamined", "start",
                                            "end", "x"])
        obj["count"] = number(fdp, 0)
        return dumps(obj)
    obj["topic"] = topic(fdp)
    raw = payload(fdp)
    if fdp.ConsumeBool():
        obj["payload"] = text(raw)
    else:
        import base64
        obj["payload_b64"] = base64.b64encode(raw).decode()
    if fdp.ConsumeBool():
        obj["qos"], obj["retain"] = fdp.ConsumeIntInRange(-1, 3), fdp.ConsumeBool()
    return dumps(obj)


def _tst(fdp: atheris.FuzzedDataProvider) -> str:
    if fdp.ConsumeProbability() < 0.8:
        second = fdp.ConsumeIntInRange(0, 59)
        return f"2026-11-21T07:26:{second:02d}.807087Z+0100"
    return fdp.ConsumeUnicode(32)


def mosquitto_j_line(fdp: atheris.FuzzedDataProvider) -> bytes:
    raw = payload(fdp)
    length = len(raw) if fdp.ConsumeProbability() < 0.7 else number(fdp, len(raw) + 1000)
    return dumps({"tst": _tst(fdp), "topic": topic(fdp), "qos": 0, "retain": 0,
                  "payloadlen": length, "payload": text(raw) if raw else None})


def mosquitto_jj_line(fdp: atheris.FuzzedDataProvider) -> bytes:
    raw = payload(fdp)
    try:
        value = orjson.loads(raw)
    except orjson.JSONDecodeError:
        return b""  # -F %J prints an empty line for a payload that is not JSON
    head = (b'{"tst":"' + _tst(fdp).encode("utf-8", "surrogatepass") + b'","topic":'
            + dumps({"t": topic(fdp)})[5:-1] + b',"qos":0,"retain":0,"payloadlen":'
            + str(len(raw)).encode() + b',"payload":')
    del value  # JSON: embedded as it is (mosquitto_sub re-serialises it without whitespace)
    return head + raw + b"}"


def mosquitto_v_line(fdp: atheris.FuzzedDataProvider) -> bytes:
    raw = payload(fdp)
    return topic(fdp).encode("utf-8", "surrogatepass") + b" " + (raw or b"(null)")


def check(data: bytes) -> None:
    """The reader's and the Monitor's invariant on a recording of bytes ``data``."""
    with within_time(len(data)):
        reader = RecordingReader(io.BytesIO(data), "<fuzz>")
        monitor = Monitor(kind="lint")
        started = time.time()
        for item in reader:
            if type(item) is Event:
                continue
            if type(item) is not Message:
                raise Broken(f"the reader yielded {type(item).__name__}")
            if not (MIN_TIME <= item.time <= MAX_TIME) and not item.time >= started:
                raise Broken(f"a message at {item.time!r}, outside the bounds")
            if type(item.payload) is not bytes or type(item.topic) is not str:
                raise Broken(f"a message of {type(item.topic)}, {type(item.payload)}")
            # Held one at a time: each within the bound (a payload declared over 1 MiB and cut
            # at a NUL is padded to the examined bound + 1 at most, never to payloadlen).
            proportional(len(item.payload) + len(item.topic), len(data), what="a message")
            monitor.feed(item)
        for problem in reader.problems:
            one_line(problem, "a line problem", shown=True)
        for note in reader.notes:
            one_line(note, "a note", shown=True)
        monitor.finish(time.time())


def target(make: Callable[[atheris.FuzzedDataProvider], bytes]
           ) -> tuple[Callable[[], None], Callable[[bytes], None]]:
    """``prepare`` and ``test_one_input`` of the target of one recording format: lines made by
    ``make`` from the fuzzed fields."""

    def prepare() -> None:
        """Nothing to build: the recording is made from the input."""

    def test_one_input(data: bytes) -> None:
        check(lines(atheris.FuzzedDataProvider(data), make))

    return prepare, test_one_input

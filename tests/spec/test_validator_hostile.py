"""Hostile payloads: each is a violation of the rule that names the problem, never an
exception (item 7)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import orjson
import pytest

from conformance.cli import main as cli_main
from conformance.validator import validate

TOPICS = ["waraps/unit/air/simulation/dji0/heartbeat",
          "waraps/unit/air/simulation/dji0/exec/command",
          "waraps/unit/air/simulation/dji0/sensor/position",
          "waraps/unit/air/simulation/dji0/sensor/heading",
          "waraps/unit/air/simulation/dji0/tst/command",
          "not/a/unit/topic"]

HOSTILE = {
    "non-utf8": (b'{"name": "\xff\xfe"}', "MSG-001"),
    "invalid-json": (b'{"command": "ping",}', "MSG-002"),
    "unquoted-signal": (b'{"command": "signal-task", signal: $abort}', "MSG-002"),
    "nan": (b'{"rate": NaN}', "MSG-002"),
    "infinity": (b'{"rate": Infinity}', "MSG-002"),
    "empty": (b"", "MSG-002"),
    "huge-int": (b'{"rate": 1' + b"0" * 400 + b"}", "MSG-002"),
    "10MB": (b'{"name": "' + b"x" * (10 * 1024 * 1024) + b'"}', "MSG-004"),
    "nested-100000": (b"[" * 100_000 + b"]" * 100_000, "MSG-004"),
    "nested-objects": (b'{"a":' * 100_000 + b"1" + b"}" * 100_000, "MSG-004"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
@pytest.mark.parametrize("topic", TOPICS)
def test_hostile_payload_is_a_violation_not_an_exception(name: str, topic: str) -> None:
    payload, rule = HOSTILE[name]
    v = validate(topic, payload, 1.0)
    assert v.message is None
    assert [x.rule for x in v.violations if not x.rule.startswith("TOPIC")] == [rule]


@pytest.mark.parametrize("topic", TOPICS)
@pytest.mark.parametrize("message", [[], [1, 2], 0, -1.5, "s", None, True, {}, {"": {}},
                                     {"command": None}, {"command": ["ping"]},
                                     {"task": {"params": None}, "command": "start-task"},
                                     {"tst": {"children": [[]]}, "command": "start-tst"},
                                     {"levels": "sensor"}, [[[[[]]]]]])
def test_wrong_shapes_never_raise(topic: str, message: object) -> None:
    v = validate(topic, orjson.dumps(message), 1.0)
    assert v.decoded or message is None
    for x in v.violations:
        assert x.rule and x.expected


def test_deep_but_allowed_nesting_is_validated() -> None:
    deep = {"command": "start-tst", "com-uuid": "b992552b-90b0-4911-8707-d6f808362bd2",
            "tst": {"name": "seq", "params": {}}}
    node = deep["tst"]
    for i in range(25):  # 2 levels per node: 50 deep, under MSG-004's 64
        child = {"name": "seq" if i < 24 else "move-to", "params": {}}
        node["children"] = [child]
        node = child
    v = validate("waraps/unit/ground/simulation/op0/tst/command", json.dumps(deep), 1.0)
    assert v.decoded
    assert [(x.rule, x.path.count("children")) for x in v.violations] == [
        ("TASK-001", 25)]  # the leaf at the bottom misses its waypoint


def test_cli_prints_kind_and_violations_and_exit_code(tmp_path) -> None:  # type: ignore[no-untyped-def]
    good = tmp_path / "ping.json"
    good.write_text('{"com-uuid": "b992552b-90b0-4911-8707-d6f808362bd2", "command": "ping"}')
    topic = "waraps/unit/air/simulation/dji0/exec/command"
    run = [sys.executable, "-m", "conformance.cli", "validate", topic]
    ok = subprocess.run([*run, str(good)], capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0, ok.stderr
    assert "kind      exec/command/ping" in ok.stdout and "verdict   pass" in ok.stdout
    bad = subprocess.run([*run, "-"], input='{"command": "ping"}', capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 1
    assert "EXEC-001" in bad.stdout and "$.com-uuid" in bad.stdout
    warn = subprocess.run([*run, "-", "--json"], capture_output=True, text=True, timeout=60,
                          input='{"com-uuid": "79d118b0-501a-4156-83c2-95fd9aaafb2", '
                                '"command": "ping"}')
    assert warn.returncode == 0 and json.loads(warn.stdout)["verdict"] == "warn"
    strict = subprocess.run([*run, "-", "--profile", "strict"], capture_output=True, text=True,
                            timeout=60, input='{"com-uuid": "79d118b0-501a-4156-83c2-95fd9aaa'
                                              'fb2", "command": "ping"}')
    assert strict.returncode == 1 and "[fail]" in strict.stdout
    missing = subprocess.run([*run, str(tmp_path / "nope.json")], capture_output=True,
                             text=True, timeout=60)
    assert missing.returncode == 2 and "cannot read" in missing.stderr



@pytest.mark.parametrize("topic", ["dji1/heartbeat", "waraps/air/simulation/dji0/heartbeat"])
def test_cli_refuses_a_topic_it_cannot_place_and_lists_the_forms(
        topic: str, tmp_path, capsys: pytest.CaptureFixture[str]) -> None:  # type: ignore[no-untyped-def]
    from conformance.cli.validate import main

    payload = tmp_path / "hb.json"
    payload.write_text('{"rate": 1}')
    assert main([topic, str(payload)]) == 2
    err = capsys.readouterr().err
    assert f"cannot place topic {topic!r}" in err
    assert "<prefix>/unit/<agent-type>/<role>/<name>/heartbeat" in err


def _heartbeat(stamp: object) -> bytes:
    return json.dumps({"name": "dji0", "rate": 1.0, "stamp": stamp, "type": "HeartBeat",
                       "agent-type": "air", "levels": ["sensor"],
                       "agent-uuid": "1b0c5c5e-58f3-4a43-9e77-47b2b8a0e6a1"}).encode()


@pytest.mark.parametrize(("scale", "offset", "code", "finding"), [  # stamp = now * scale + offset
    (1000, 0.0, 1, "looks like milliseconds"),  # judged without --now: MSG-008
    (1e6, 0.0, 1, "looks like microseconds"),
    # a clock left at 1970: MSG-005, a decided rule (rules.toml), warns by default
    (0, 12.0, 0, "behind the arrival time"),
    (1, -3 * 86400, 0, None),                   # a recording from last week: plausible
], ids=["milliseconds", "microseconds", "1970", "last-week"])  # (ids: the same in each worker)
def test_validate_without_an_arrival_time_judges_the_stamp_for_plausibility_and_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], scale: float, offset: float,
        code: int, finding: str | None) -> None:
    stamp = time.time() * scale + offset  # taken now, not at collection (a slow run drifts)
    path = tmp_path / "hb.json"
    path.write_bytes(_heartbeat(stamp))
    assert cli_main(["validate", "waraps/unit/air/simulation/dji0/heartbeat", str(path)]) == code
    out = capsys.readouterr().out
    assert "the stamp was judged for plausibility only" in out and "pass --now" in out
    assert (finding in out) if finding else "MSG-005" not in out.split("note")[0]
    # with --now the stamp is judged within the profile's 30 s (none of these is), no note:
    # in another unit it fails (MSG-008, 5.1's words), a clock off only warns (MSG-005)
    assert cli_main(["validate", "--now", "waraps/unit/air/simulation/dji0/heartbeat",
                     str(path)]) == (1 if "looks like" in (finding or "") else 0)
    assert "plausibility" not in capsys.readouterr().out


def test_cli_shows_what_the_message_holds_escaped(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A value, a key and the topic holding escape sequences, a bidi override and zero-width
    characters are shown escaped in validate's text, on one line each."""
    hostile = "\x1b]52;c;cHduZWQ=\x07\x1b[2J\u202e\u200b"
    path = tmp_path / "hb.json"
    path.write_bytes(orjson.dumps({"name": "dji0", "rate": hostile, "type": "HeartBeat",
                                   hostile: 1}))
    topic = "waraps/unit/air/simulation/dji0\u202e/heartbeat"
    assert cli_main(["validate", topic, str(path)]) == 1
    out = capsys.readouterr().out
    assert "dji0\\u202e/heartbeat" in out and "observed  string" in out
    assert not any(c in out for c in "\x1b\x07\u202e\u200b"), out


def test_a_field_past_the_nesting_bound_leaves_the_top_level_fields_judged(
        tmp_path, capsys: pytest.CaptureFixture[str]) -> None:  # type: ignore[no-untyped-def]
    """One field nested 65 levels once hid the whole heartbeat (rate, stamp) from every rule:
    now the other top-level fields are read, the schema is not examined on a part, and the
    message is could-not-test (validate: exit 1), never a pass or a warn."""
    from conformance.cli.validate import main
    from conformance.validator import Validator

    payload = json.loads(_heartbeat(1_763_700_000.0))
    payload["extra"] = json.loads("[" * 65 + "]" * 65)
    raw = json.dumps(payload).encode()
    topic = "waraps/unit/air/simulation/dji0/heartbeat"
    v = validate(topic, raw, 1_763_700_000.0)
    assert v.kind == "heartbeat" and v.message["rate"] == 1.0 and "extra" not in v.message
    assert [x.rule for x in v.violations] == ["MSG-004"]
    assert "deeper in 1 top-level field(s); judged on the other 7" in v.violations[0].observed
    examined = set(Validator().examined(v))
    assert "MSG-004" in examined and "HB-001" not in examined
    path = tmp_path / "deep.json"
    path.write_bytes(raw)
    assert main([topic, str(path)]) == 1
    assert "verdict   could-not-test" in capsys.readouterr().out


@pytest.mark.parametrize(("payload", "named"), [
    (b'{"name": "dji0", "rate": 1.0, "rate": 0.5}', '"rate"'),
    (b'{"name" : "a", "name" : "b"}', '"name"'),
    (b'{"a": {"x": 1, "x": 2}, "b": [{"y": 1, "y": 1}]}', '"x", "y"'),
])
def test_a_member_named_twice_is_named(payload: bytes, named: str) -> None:
    """A parser differential (one reader takes the last value, another the first): named, a
    decided condition of MSG-002 that warns by default."""
    from conformance.explanation import verdict_of
    from conformance.profile import Profile
    from conformance.validator import NAMES_CHECKED, Validator

    validator = Validator()  # names are counted on a topic's first messages, then sampled
    v = validator.validate("waraps/unit/air/simulation/dji0/heartbeat", payload, 1.0)
    (twice,) = [x for x in v.violations if x.condition == "duplicate-names"]
    assert twice.rule == "MSG-002" and twice.observed == f"named twice: {named}"
    assert verdict_of("MSG-002", Profile(), "duplicate-names").value == "warn"
    # Past the first messages of a topic, every 16th is counted: a serializer's habit is seen.
    seen = sum(any(x.condition == "duplicate-names" for x in validator.validate(
        "waraps/unit/air/simulation/dji0/heartbeat", payload, 1.0).violations)
        for _ in range(NAMES_CHECKED + 63))
    assert seen == NAMES_CHECKED - 1 + 4


@pytest.mark.parametrize("payload", [b'{"a": "\\":", "b": 1}', b'{"a": "x\\" :", "b": {"c": 1}}',
                                     b'{"a": 1, "b": 2}', b'[{"a": 1}, {"a": 1}]'])
def test_names_in_strings_or_in_other_objects_are_not_twice(payload: bytes) -> None:
    from conformance.validator import Validator

    v = Validator().validate("waraps/unit/air/simulation/dji0/heartbeat", payload, 1.0)
    assert not [x for x in v.violations if x.condition == "duplicate-names"]


def test_a_microsecond_stamp_of_a_clock_off_is_explained_alike_by_validate_and_lint(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A stamp in microseconds from a clock 40 s ahead (past the profile's clock tolerance):
    one explanation, microseconds (MSG-008), from `validate --time` and from lint of the
    recorded message; never a clock decades ahead (MSG-005)."""
    from conformance.message import Message
    from conformance.recording import RecordingWriter

    arrival = 1_763_706_393.5
    payload = _heartbeat(int((arrival + 40.0) * 1e6))
    topic = "waraps/unit/air/simulation/dji0/heartbeat"
    path = tmp_path / "hb.json"
    path.write_bytes(payload)
    assert cli_main(["validate", "--time", str(arrival), topic, str(path)]) == 1
    out = capsys.readouterr().out
    assert "looks like microseconds" in out and "ahead of" not in out, out
    recording = tmp_path / "hb.jsonl"
    with recording.open("wb") as f:
        RecordingWriter(f).write(Message(arrival, topic, payload, 0, False))
    assert cli_main(["lint", "--from", str(recording), "--plain", "--reports-dir",
                     str(tmp_path / "r")]) == 1
    out = capsys.readouterr().out
    assert "looks like microseconds" in out and "ahead of" not in out, out

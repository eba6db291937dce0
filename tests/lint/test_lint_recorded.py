"""``waraps-conformance lint --from``: recordings judged at their recorded times."""

from __future__ import annotations

import base64
from datetime import UTC
from pathlib import Path

import orjson
import pytest
from lint_helpers import (
    T0,
    failed_rules,
    fleet_traffic,
    run_lint,
    unit_traffic,
    verdicts,
    write_recording,
)

from conformance.client import Message
from conformance.recording import Event


def test_conformant_fleet_passes_and_every_report_is_written(tmp_path: Path, reports_dir: Path,
                                                            prefix: str) -> None:
    rec = write_recording(tmp_path / "field-test.jsonl",
                          fleet_traffic(prefix, ["dji0", "dji1", "piraya0"], seconds=30))
    run = run_lint(["--from", str(rec)], reports_dir)
    assert run.code == 0, run.out
    assert "CLEAN: no unit or commander fails" in run.out and "\nverdict: clean (" in run.out
    assert run.report is not None and run.report["kind"] == "lint"
    units = run.report["units"]
    assert set(units) == {f"{prefix}/unit/air/simulation/{n}" for n in ("dji0", "dji1", "piraya0")}
    for unit in units:
        assert not failed_rules(run.report, unit)
        assert verdicts(run.report, unit)["HB-003"] == "pass"  # rates judged at recorded times
    assert run.report["meta"]["source"] == str(rec)
    assert {p.name for p in run.reports} >= {"lint-field-test.json"}
    for name in ("dji0", "dji1", "piraya0"):  # the scorecard lists every unit
        assert f"{prefix}/unit/air/simulation/{name} " in run.out


def test_exactly_the_faulty_unit_fails_and_the_exit_code_says_so(tmp_path: Path,
                                                                  reports_dir: Path,
                                                                  prefix: str) -> None:
    msgs = fleet_traffic(prefix, ["dji0", "dji1"], seconds=30)
    msgs += unit_traffic(prefix, "slow0", seconds=30, heartbeat_every=2)  # declares 1 Hz, 0.5 Hz
    rec = write_recording(tmp_path / "rec.jsonl", msgs)
    run = run_lint(["--from", str(rec)], reports_dir)
    assert run.code == 1
    slow = f"{prefix}/unit/air/simulation/slow0"
    assert "HB-003" in failed_rules(run.report, slow)
    for good in ("dji0", "dji1"):
        assert not failed_rules(run.report, f"{prefix}/unit/air/simulation/{good}")
    assert f"FAIL: {slow}" in run.out
    assert f"{slow}" in run.out and "HB-003x" in run.out
    # The evidence a person reads before opening the reports: the failed rule, what was
    # expected and observed, and how to rerun it for that unit alone.
    evidence = run.out[run.out.index(f"{slow}\nHB-003 "):]
    assert "expected  1.00 Hz +-20% (declared in heartbeat.rate)" in evidence
    assert "observed  0.50 Hz over" in evidence
    assert f"rerun     waraps-conformance lint --from {rec} --unit {slow}" in evidence


def test_the_evidence_printed_is_capped_and_says_where_the_rest_is(prefix: str) -> None:
    from conformance.checks import Monitor
    from conformance.lint.runner import failures

    m = Monitor()
    for name in ("slow0", "slow1", "slow2"):  # each declares 1 Hz and heartbeats at 0.5 Hz
        for msg in unit_traffic(prefix, name, seconds=30, heartbeat_every=2):
            m.feed(msg)
    m.finish()
    report = m.report()
    assert failures(report).count("HB-003 heartbeat rate") == 3
    capped = failures(report, limit=2)
    assert capped.count("HB-003 heartbeat rate") == 2
    assert capped.endswith("... and 1 more failed rule: every violation is in the reports")


def test_hostile_messages_each_become_a_violation_of_the_right_rule(tmp_path: Path,
                                                                     reports_dir: Path,
                                                                     prefix: str) -> None:
    base = f"{prefix}/unit/air/simulation/dji0"
    msgs = unit_traffic(prefix, "dji0", seconds=15)
    t = T0 + 5
    hostile = [
        Message(t, f"{base}/sensor/speed", b"not json at all"),
        Message(t + 0.1, f"{base}/sensor/heading", b"\xff\xfe\x00\x01binary"),
        Message(t + 0.2, f"{base}/sensor/course", b'"' + b"x" * (10 << 20) + b'"'),
        Message(t + 0.3, f"{base}/sensor/position", b"[" * 100_000 + b"]" * 100_000),
        Message(t + 0.4, f"{prefix}/unit/air/simulation/dji 0+#/heartbeat", b"{}"),
        Message(t + 0.5, f"{base}/sensor/speed", b'{"a": NaN}'),
    ]
    rec = write_recording(tmp_path / "hostile.jsonl", msgs + hostile)
    # --strict: MSG-004 and TOPIC-008 are decided rules (rules.toml), failing only when adopted
    run = run_lint(["--from", str(rec), "--strict"], reports_dir)
    assert run.code == 1
    failed = failed_rules(run.report, base)
    assert {"MSG-001", "MSG-002", "MSG-004"} <= failed
    assert run.report["units"][base]["violation_counts"]["MSG-004"] == 2  # size and depth
    assert run.report["units"][base]["violation_counts"]["MSG-002"] == 2
    odd = [u for u in run.report["units"] if "dji 0" in u]
    assert odd and "TOPIC-008" in failed_rules(run.report, odd[0])
    # The rest of the unit's traffic was still judged after the flood.
    assert verdicts(run.report, base)["HB-003"] == "pass"


def test_malformed_lines_are_reported_with_line_numbers_and_the_rest_judged(
        tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    rec = write_recording(tmp_path / "rec.jsonl", unit_traffic(prefix, "dji0", seconds=20))
    lines = rec.read_bytes().splitlines()
    lines.insert(4, b"{this is not json")
    lines.insert(50, b'{"ts": 1.0, "payload": "no topic"}')
    rec.write_bytes(b"\n".join(lines) + b"\n")
    run = run_lint(["--from", str(rec)], reports_dir)
    assert run.code == 4, run.out  # what the damaged lines held was not examined: never clean
    assert "malformed line 5: not JSON" in run.out
    assert "malformed line 51: 'topic' is missing" in run.out
    assert run.report["meta"]["recording_problems"] == "2"
    # the keys a recording's lint has always written (RunMeta's, results.py): none dropped
    assert sorted(run.report["meta"]) == ["duration_s", "recording_formats", "recording_lines",
                                          "recording_problem_lines", "recording_problems",
                                          "source"]
    assert run.report["units"][f"{prefix}/unit/air/simulation/dji0"]["message_count"] == 140


def test_mosquitto_sub_output_on_standard_input(reports_dir: Path, prefix: str) -> None:
    """``mosquitto_sub -F %j | lint --from -``: tst times drive the rate checks."""
    from datetime import datetime

    lines = []
    for m in unit_traffic(prefix, "dji0", seconds=20):
        tst = datetime.fromtimestamp(m.time, UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ+0000")
        lines.append(orjson.dumps({"tst": tst, "topic": m.topic, "qos": 0, "retain": 0,
                                   "payloadlen": len(m.payload), "payload": m.payload.decode()}))
    run = run_lint(["--from", "-"], reports_dir, stdin=b"\n".join(lines) + b"\n")
    assert run.code == 0, run.out
    unit = f"{prefix}/unit/air/simulation/dji0"
    assert verdicts(run.report, unit)["HB-003"] == "pass"
    assert run.report["meta"]["recording_formats"] == "mosquitto_sub -F %j"


def test_unit_option_limits_the_judgement(tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    msgs = unit_traffic(prefix, "dji0", seconds=15) + unit_traffic(prefix, "bad0", seconds=15,
                                                                    heartbeat_every=2)
    rec = write_recording(tmp_path / "rec.jsonl", msgs)
    run = run_lint(["--from", str(rec), "--unit", f"{prefix}/unit/air/simulation/dji0"],
                   reports_dir)
    assert run.code == 0 and set(run.report["units"]) == {f"{prefix}/unit/air/simulation/dji0"}


def test_a_recorded_connection_gap_is_not_judged_as_silence(tmp_path: Path, reports_dir: Path,
                                                             prefix: str) -> None:
    """The recorder lost the broker for 20 s: nobody's silence is judged over the gap. The same
    hole without the recorded gap is a silence of every unit (HB-010: the test can fail)."""
    msgs = fleet_traffic(prefix, ["dji0", "dji1"], seconds=60, skip=(20.0, 40.0))
    gap = [Event(T0 + 19.9, "disconnected", "connection lost"), Event(T0 + 39.9, "connected")]
    with_gap = run_lint(["--from", str(write_recording(tmp_path / "gap.jsonl", msgs + gap))],
                        reports_dir / "a")
    without = run_lint(["--from", str(write_recording(tmp_path / "hole.jsonl", msgs))],
                       reports_dir / "b")
    unit = f"{prefix}/unit/air/simulation/dji0"
    assert with_gap.code == 0, with_gap.out
    assert "connection gap:" in with_gap.out and "for 20.0 s" in with_gap.out
    # Not judged until both units are heard again (their second heartbeat after it: 41 s).
    assert with_gap.report["gaps"] == [[T0 + 19.9, T0 + 41.0]]
    assert verdicts(with_gap.report, unit)["HB-010"] == "pass"
    assert verdicts(without.report, unit)["HB-010"] == "warn"
    assert "HB-010 the unit does not fall silent" in without.out


def test_a_command_sent_before_the_unit_is_back_after_a_gap_is_not_failed(
        tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    """The recorder is back at 39.9 s, the unit only at 44 s (it reconnects on its own time):
    a ping sent at 41 s may never have reached it. The same ping once the unit is back fails
    EXEC-PING-001 (the test can fail), as the suite judges it."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    msgs = unit_traffic(prefix, "dji0", seconds=60, skip=(20.0, 44.0))
    gap = [Event(T0 + 19.9, "disconnected", "connection lost"), Event(T0 + 39.9, "connected")]

    def ping(t: float) -> Message:
        return Message(T0 + t, f"{unit}/exec/command", orjson.dumps({
            "com-uuid": f"00000000-0000-4000-8000-0000000000{int(t):02d}", "command": "ping",
            "sender": "op0"}))

    early = run_lint(["--from", str(write_recording(tmp_path / "early.jsonl",
                                                    [*msgs, *gap, ping(41.0)]))],
                     reports_dir / "a")
    late = run_lint(["--from", str(write_recording(tmp_path / "late.jsonl",
                                                   [*msgs, *gap, ping(50.0)]))],
                    reports_dir / "b")
    assert verdicts(late.report, unit)["EXEC-PING-001"] == "fail", late.out
    assert verdicts(early.report, unit)["EXEC-PING-001"] != "fail", early.out
    assert early.code == 0, early.out
    assert early.report["gaps"] == [[T0 + 19.9, T0 + 45.0]]


def test_recorded_unexamined_messages_are_reported(tmp_path: Path, reports_dir: Path,
                                                    prefix: str) -> None:
    msgs = unit_traffic(prefix, "dji0", seconds=15)
    items = msgs + [Event(T0 + 7, "unexamined", "recorder fell behind", 250)]
    run = run_lint(["--from", str(write_recording(tmp_path / "r.jsonl", items))], reports_dir)
    assert run.report["unexamined"] == 250
    assert "not examined: 250 messages" in run.out


def test_nothing_to_lint_is_not_a_pass(tmp_path: Path, reports_dir: Path) -> None:
    empty = tmp_path / "empty.jsonl"
    empty.write_bytes(b"garbage\n")
    run = run_lint(["--from", str(empty)], reports_dir)
    assert run.code == 3 and "malformed line 1" in run.out
    missing = run_lint(["--from", str(tmp_path / "nope.jsonl")], reports_dir)
    assert missing.code == 3


def test_usage_errors_exit_2(tmp_path: Path, reports_dir: Path) -> None:
    assert run_lint(["--from", "x", "--broker", "mqtt://127.0.0.1:1"], reports_dir).code == 2
    assert run_lint(["--from", "x", "--format", "pdf"], reports_dir).code == 2
    assert run_lint(["--from", "x", "--profile", "nonexistent"], reports_dir).code == 2
    assert run_lint(["--from", "x", "--unit", "not/a/unit"], reports_dir).code == 2
    assert run_lint(["--from", "x", "--duration", "soon"], reports_dir).code == 2


def test_payload_b64_lines_are_judged(tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    base = f"{prefix}/unit/air/simulation/dji0"
    rec = write_recording(tmp_path / "r.jsonl", unit_traffic(prefix, "dji0", seconds=12))
    extra = orjson.dumps({"ts": T0 + 12.5, "topic": f"{base}/sensor/speed",
                          "payload_b64": base64.b64encode(b"\x80abc").decode()})
    rec.write_bytes(rec.read_bytes() + extra + b"\n")
    run = run_lint(["--from", str(rec)], reports_dir)
    assert "MSG-001" in failed_rules(run.report, base)


def test_a_unit_silent_until_the_recording_ends_has_died(tmp_path: Path, reports_dir: Path,
                                                         prefix: str) -> None:
    """The recorder writes when it stopped listening: a unit silent from its last message
    until then has stopped for good (HB-012; with no command before it, it may have been
    switched off: the decided 'no-command' condition, a warning). Without that mark the
    silence was not observed."""
    traffic = unit_traffic(prefix, "dji0", seconds=12)
    unit = f"{prefix}/unit/air/simulation/dji0"
    ended = write_recording(tmp_path / "ended.jsonl", [
        Event(T0 - 0.5, "start", "subscribed"), *traffic, Event(T0 + 30, "end", "stopped")])
    run = run_lint(["--from", str(ended)], reports_dir / "ended")
    hb012 = run.report["units"][unit]["rules"]["HB-012"]
    assert hb012["verdict"] == "warn" and "never came back" in hb012["violations"][0]["observed"]
    assert hb012["violations"][0]["condition"] == "no-command"
    cut = write_recording(tmp_path / "cut.jsonl", traffic)  # no end mark (mosquitto_sub)
    run = run_lint(["--from", str(cut)], reports_dir / "cut")
    assert run.report["units"][unit]["rules"]["HB-012"]["verdict"] == "pass"


def test_a_commanders_rerun_line_lints_the_unit_it_commanded_and_finds_it_again(
        tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    # A commander's row ('commander alice') is no unit address: its rerun line names the
    # unit whose command topic the fault was on, and that line, run, shows the fault again.
    import shlex

    msgs = fleet_traffic(prefix, ["dji0", "dji1"], seconds=10)
    dji1 = f"{prefix}/unit/air/simulation/dji1"
    msgs.append(Message(T0 + 5.0, f"{dji1}/exec/command",
                        b'{"sender": "alice", "command": "ping", com-uuid}'))
    msgs.sort(key=lambda m: m.time)
    rec = write_recording(tmp_path / "rec.jsonl", msgs)
    run = run_lint(["--from", str(rec)], reports_dir)
    assert "MSG-002" in failed_rules(run.report, "commander alice")
    evidence = run.out[run.out.index("commander alice\nMSG-002 "):]
    rerun = f"waraps-conformance lint --from {rec} --unit {dji1}"
    assert f"rerun     {rerun}\n" in evidence + "\n"
    again = run_lint(shlex.split(rerun)[2:], reports_dir)
    assert "MSG-002" in failed_rules(again.report, "commander alice")
    assert set(again.report["units"]) == {dji1, "commander alice"}


def test_a_recorded_stall_of_the_broker_is_not_the_units(tmp_path: Path, reports_dir: Path,
                                                         prefix: str) -> None:
    """The broker froze 20 s, then delivered what it held within milliseconds.
    lint finds the stall in the traffic, says so, and judges no rate or silence over it (the
    burst fails HB-003 of every unit when taken for the units' own timing)."""
    msgs = fleet_traffic(prefix, ["dji0", "dji1"], seconds=60)
    burst = [m for m in msgs if T0 + 20.0 <= m.time < T0 + 40.0]
    held = [Message(T0 + 40.0 + k * 0.001, m.topic, m.payload) for k, m in enumerate(burst)]
    msgs = [m for m in msgs if not T0 + 20.0 <= m.time < T0 + 40.0] + held
    run = run_lint(["--from", str(write_recording(tmp_path / "stall.jsonl", msgs))],
                   reports_dir)
    unit = f"{prefix}/unit/air/simulation/dji0"
    assert run.code == 0, run.out
    assert "broker stalled:" in run.out and "rates, silences and deadlines over it not " \
        "judged" in run.out
    got = verdicts(run.report, unit)
    assert {r: got[r] for r in ("HB-003", "SI-002", "DEI-002", "HB-010")} == dict.fromkeys(
        ("HB-003", "SI-002", "DEI-002", "HB-010"), "pass")


def _pretty_pong(prefix: str, cut: bool) -> tuple[list[Message], str]:
    """A unit's traffic with a ping answered by a pretty-printed (multi-line) pong; ``cut``:
    as a tool that records line by line kept it, its first line '{' only."""
    msgs = unit_traffic(prefix, "dji0", seconds=20)
    base = msgs[0].topic.rsplit("/", 1)[0]
    agent = orjson.loads(next(m for m in msgs if m.topic.endswith("/heartbeat")).payload)[
        "agent-uuid"]
    ping = {"com-uuid": "7300d049-176f-4dcb-b0bf-151980d5611a", "command": "ping",
            "sender": "commander"}
    pong = {"agent-uuid": agent, "com-uuid": "8300d049-176f-4dcb-b0bf-151980d5611a",
            "response": "pong", "response-to": ping["com-uuid"]}
    text = orjson.dumps(pong, option=orjson.OPT_INDENT_2)
    return msgs + [Message(T0 + 5.0, f"{base}/exec/command", orjson.dumps(ping), 0, False),
                   Message(T0 + 5.1, f"{base}/exec/response",
                           text.split(b"\n")[0] if cut else text, 0, False)], base


def test_a_payload_the_capture_cut_to_its_first_line_is_the_captures_not_the_units(
        tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    """A tool that records line by line keeps a pretty-printed pong as '{' (its first line;
    mosquitto_sub -v prints the rest as lines of their own). The capture's fault, said once
    in a note: not the unit's invalid JSON (MSG-002), nor its ping unanswered (EXEC-PING-001);
    with -v, the rest of the payload is no malformed line either."""
    msgs, base = _pretty_pong(prefix, cut=True)
    unit = base
    run = run_lint(["--from", str(write_recording(tmp_path / "cut.jsonl", msgs))],
                   reports_dir)
    assert run.report is not None, run.out
    judged = verdicts(run.report, unit)
    assert judged["EXEC-PING-001"] != "fail" and judged["MSG-002"] != "fail", judged
    assert run.out.count("cut to their first line") == 1, run.out
    whole, _ = _pretty_pong(prefix, cut=False)  # the capture was whole: the pong answers
    verbose = b"".join(m.topic.encode() + b" " + m.payload + b"\n"
                       for m in sorted(whole, key=lambda m: m.time))
    run = run_lint(["--from", "-"], reports_dir / "v", stdin=verbose)
    assert run.report is not None and "malformed line" not in run.out, run.out
    assert verdicts(run.report, unit)["MSG-002"] != "fail"
    assert run.out.count("cut to their first line") == 1, run.out


def test_a_recording_whose_time_runs_backwards_is_refused_naming_the_line(
        tmp_path: Path, reports_dir: Path, prefix: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Two captures joined end to end (`cat a.jsonl b.jsonl | lint --from -`): the first
    one's death would read as a pass. Refused with an error naming the line where time runs
    back, nothing judged (exit 3: nothing could be linted, no report); a step back within
    BACKWARDS_SECONDS (a clock stepped by NTP) is read on."""
    from conformance.recording import BACKWARDS_SECONDS

    a = write_recording(tmp_path / "a.jsonl", unit_traffic(prefix, "dji0", seconds=20,
                                                           t0=T0 + 3600))
    b = write_recording(tmp_path / "b.jsonl", unit_traffic(prefix, "dji0", seconds=20))
    joined = a.read_bytes() + b.read_bytes()
    first_of_b = len(a.read_bytes().splitlines()) + 1
    run = run_lint(["--from", "-"], reports_dir, stdin=joined)
    assert run.code == 3 and run.report is None and not run.reports, run.out
    err = capsys.readouterr().err
    assert f"line {first_of_b}: time runs backwards" in err, err
    assert f"before line {first_of_b - 1}'s" in err and "Lint each on its own" in err
    stepped = unit_traffic(prefix, "dji0", seconds=20)
    back = [Message(m.time - BACKWARDS_SECONDS / 2 if i > 30 else m.time, *m[1:])
            for i, m in enumerate(stepped)]
    run = run_lint(["--from", str(write_recording(tmp_path / "c.jsonl", back))],
                   reports_dir / "c")
    assert run.report is not None, run.out


def test_a_failed_rule_shows_first_the_finding_it_fails_on_in_every_output(prefix: str
                                                                           ) -> None:
    """The public L1 agent lists only position and publishes only position: SI-004 fails on
    6.1's words (heading, course, speed unpublished) and warns on its decided 'listed'
    condition, found first. Lint's text, the HTML and the JSON report show the stated
    finding first, under its own basis, not the decided one over '[fail]'."""
    from conformance.checks import Monitor
    from conformance.lint.runner import failures
    from conformance.reporting import render_html
    from conformance.reporting.jsonreport import dumps

    m = Monitor()
    for msg in unit_traffic(prefix, "l1", seconds=10):
        if msg.topic.endswith(("/heading", "/course", "/speed")):
            continue
        if msg.topic.endswith("/sensor_info"):
            info = orjson.loads(msg.payload)
            info["sensor-data-provided"] = ["position"]
            msg = Message(msg.time, msg.topic, orjson.dumps(info))
        m.feed(msg)
    m.finish()
    report = m.report()
    unit = f"{prefix}/unit/air/simulation/l1"
    result = report.units[unit].rules["SI-004"]
    assert result.verdict.value == "fail"
    assert [v.condition for v in result.violations] == ["", "listed"]
    text = failures(report)
    block = text[text.index(f"{unit}\nSI-004 "):].split("\n\n")[0]
    assert "observed  nothing on heading, course, speed" in block
    assert 'basis     stated: "The following sensors are mandatory' in block
    assert "decided" not in block and "(and 1 more violations of SI-004)" in block
    page = render_html(report)
    evidence = page[page.index('-SI-004"'):]
    assert evidence.index("nothing on heading") < evidence.index("missing heading")
    stored = orjson.loads(dumps(report))["units"][unit]["rules"]["SI-004"]["violations"]
    assert [v.get("condition", "") for v in stored] == ["", "listed"]

"""The reference unit passes the certification, end to end, on both real brokers."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from certify_helpers import FAST, UNIT, Rebooter, certify, recorded

from conformance.rules import CATALOGUE, Level, Mode
from conformance.sim import SimUnit
from conformance.topics import UnitAddress

pytestmark = pytest.mark.slow


def test_reference_unit_passes_on_the_embedded_broker(pytester: pytest.Pytester) -> None:
    junit = pytester.path / "junit.xml"
    run = certify(pytester, "--unit", UNIT, "--broker", "embedded", "--sim-rate", "2",
                  "--sim-tst", f"--profile={FAST}", "--seed", "7", f"--junitxml={junit}")
    assert run.result.ret == 0, run.text
    assert not run.failed
    # Every rule has a test, and every active rule was really examined (not skipped); on
    # both levels, TST's conversation rules too.
    tst = {r for r in CATALOGUE if r.startswith("TST-") and CATALOGUE[r].side.value == "unit"}
    assert {r for r in tst if run.outcomes[r] != "passed"} == set(), run.text
    assert set(run.outcomes) == set(CATALOGUE)
    # (of the levels it declares: the bundled reference unit runs no TSTs by default)
    active = {r for r, rule in CATALOGUE.items() if rule.mode is Mode.ACTIVE
              and rule.level is not Level.TST_EXECUTION}
    assert {r for r in active if run.outcomes[r] != "passed"} == set(), run.text
    rules = run.unit_rules()
    assert all(rules[r]["verdict"] == "pass" for r in active)
    # The report tells what pytest tells: a pass for every test passed, a skip for every skip.
    as_pytest = {"pass": "passed", "warn": "passed", "skip": "skipped",
                 "could-not-test": "skipped", "fail": "failed"}
    assert {r: as_pytest[v["verdict"]] for r, v in rules.items()} == run.outcomes
    # The header makes the run repeatable and says what is being certified.
    header = run.text
    for needle in ("certifying waraps/unit/air/simulation/dji0", "agent-uuid ", "levels: sensor,"
                   " direct execution", "Using --seed=7", "profile:  fast-selftest"):
        assert needle in header
    # JUnit carries the run's identity as properties.
    props = {p.get("name"): p.get("value") for p in ET.parse(junit).iter("property")}
    assert props["unit"] == UNIT and props["seed"] == "7"
    assert len(props["agent-uuid"].split()) == 2  # before and after the reboot
    assert props["profile"].startswith("fast-selftest") and props["suite-version"]
    assert len(props["schemas-hash"]) >= 16
    # What was not applicable is said once a reason, with how many rules it covers.
    skipped = {reason: r["reason"] for reason, r in rules.items() if r["verdict"] == "skip"}
    for reason in set(skipped.values()):
        count = sum(1 for r in skipped.values() if r == reason)
        assert f"  skipped {count:>3}  {reason}" in run.text, reason
    # The JSON and HTML reports were written.
    assert len(list(run.reports_dir.glob("dji0-*.json"))) == 1
    assert len(list(run.reports_dir.glob("dji0-*.html"))) == 1


def test_one_rule_by_its_id(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  f"--profile={FAST}", "-k", "EXEC-PING-002")
    assert run.result.ret == 0, run.text
    assert run.outcomes == {"EXEC-PING-002": "passed"}


def test_warn_is_a_pass_with_a_warning_and_strict_makes_it_a_failure(
        pytester: pytest.Pytester) -> None:
    """An erratum reading (ERR-001: 'sensor.info') warns under the default profile: the test
    passes, a ConformanceWarning says why, the JUnit verdict property says 'warn'."""
    junit = pytester.path / "junit.xml"
    args = ("--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
            "--sim-fault=sensor-dot-info", "-k", "ERR-001")
    run = certify(pytester, *args, f"--junitxml={junit}")
    assert run.result.ret == 0, run.text
    assert run.outcomes == {"ERR-001": "passed"}
    assert "ConformanceWarning: ERR-001 sensor_info published on 'sensor.info'" in run.text
    verdicts = [p.get("value") for case in ET.parse(junit).iter("testcase")
                for p in case.iter("property") if p.get("name") == "verdict"]
    assert verdicts == ["warn"]
    strict = certify(pytester, *args, "--profile", "strict")
    assert strict.result.ret == pytest.ExitCode.TESTS_FAILED
    assert strict.outcomes == {"ERR-001": "failed"}


def test_reference_unit_passes_on_mosquitto_and_its_recording_lints_clean(
        pytester: pytest.Pytester, mosquitto: str, unit_address: UnitAddress,
        tmp_path) -> None:
    """The reference unit passes on Mosquitto, rebooted once through the hook. Lint judges
    conversations the way the suite does: a recording taken while the suite certifies it
    shows every command of the suite matched to its answer, and no failure of the unit (the
    suite's deliberately broken commands are its own probes: no commander's row)."""
    import io
    import json
    import time

    from conformance.cli.lint import main as lint_main

    recording = tmp_path / "certification.jsonl"
    # 2 Hz: the recorder, the suite and the unit share this process; at 3 Hz a loaded machine
    # stalled the unit past HB-010's three periods (1 s) once in a -n 4 run.
    with recorded(mosquitto, unit_address.prefix, recording), \
            SimUnit(unit_address, mosquitto, rate=2.0, seed=3) as sim:
        rebooter = Rebooter(sim)
        run = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                      f"--profile={FAST}", "--seed", "7", plugins=(rebooter,))
        # The run's end may probe a unit a period silent with a ping it does not wait to have
        # answered (its echo is what it asks for): the unit answers it before it stops.
        deadline = time.monotonic() + 5.0
        while _unanswered(recording) and time.monotonic() < deadline:
            time.sleep(0.05)  # polling a file the recorder flushes: bounded by the deadline
    assert run.result.ret == 0, run.text
    assert not run.failed
    assert rebooter.calls == 1
    assert run.outcomes["REBOOT-001"] == run.outcomes["REBOOT-002"] == "passed"
    out = io.StringIO()
    code = lint_main(["--from", str(recording), f"--profile={FAST}", "--plain", "--format",
                      "json", "--reports-dir", str(tmp_path / "lint")], stdout=out)
    report = json.loads(next((tmp_path / "lint").glob("*.json")).read_text())
    unit = report["units"][str(unit_address)]
    bad = {r: res["violations"][:1] for r, res in unit["rules"].items()
           if res["verdict"] == "fail"}
    assert bad == {}, out.getvalue()
    for rule in ("EXEC-PING-001", "EXEC-START-001", "EXEC-START-002", "EXEC-SIG-001",
                 "EXEC-RESEND-002", "EXEC-ROBUST-002", "EXEC-006", "EXEC-009"):
        assert unit["rules"][rule]["verdict"] == "pass", (rule, unit["rules"][rule])
    # Every command with a com-uuid got an answer with that response-to (12.3).
    sent, answered = _conversation(recording)
    assert len(sent) > 20 and sent <= answered, sorted(sent - answered)
    # The suite's deliberately broken commands are its own probes, no commander's fault
    # (5): the recording of a certification lints with the unit's findings only.
    commanders = [u for u in report["units"].values() if u["party"] == "commander"]
    assert commanders == [], commanders
    assert code == 0, out.getvalue()


def _conversation(recording) -> tuple[set[str], set[str]]:  # type: ignore[no-untyped-def]
    """The com-uuids of the commands in a recording so far, and the response-tos answered."""
    import orjson

    sent, answered = set(), set()
    for line in recording.read_bytes().splitlines() if recording.exists() else ():
        try:
            item = orjson.loads(line)
            payload = item.get("payload")
            body = orjson.loads(payload) if isinstance(payload, str) else None
        except (orjson.JSONDecodeError, AttributeError):
            continue  # a line being written
        topic = item.get("topic", "")
        if isinstance(body, dict) and isinstance(body.get("com-uuid"), str):
            if topic.endswith("/exec/command"):
                sent.add(body["com-uuid"])
            elif topic.endswith("/exec/response") and isinstance(body.get("response-to"), str):
                answered.add(body["response-to"])
    return sent, answered


def _unanswered(recording) -> set[str]:  # type: ignore[no-untyped-def]
    sent, answered = _conversation(recording)
    return sent - answered

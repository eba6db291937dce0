"""When things go wrong: a unit that answers nothing, a broker that is down or drops mid-run,
a unit that is not there, Ctrl-C in the middle. Each ends in one clear outcome."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import orjson
import pytest
from certify_helpers import (
    FAST,
    UNIT,
    PrivateMosquitto,
    Rebooter,
    SilentUnit,
    certify,
)

from conformance.broker import free_port
from conformance.client import BrokerURL, MqttClient
from conformance.plugin import NOT_CERTIFIED_EXIT
from conformance.sim import SimUnit
from conformance.topics import UnitAddress

pytestmark = pytest.mark.slow


def test_a_unit_that_answers_nothing(pytester: pytest.Pytester, mosquitto: str,
                                     unit_address: UnitAddress) -> None:
    with SilentUnit(str(unit_address), mosquitto):
        run = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                      f"--profile={FAST}")
    assert run.result.ret == pytest.ExitCode.TESTS_FAILED
    assert run.outcomes["EXEC-PING-001"] == "failed"
    # It never answered a ping, so it did not 'stop answering': that is
    # EXEC-PING-001's finding, and EXEC-ROBUST-001 says it could not tell.
    assert run.outcomes["EXEC-ROBUST-001"] == "skipped"
    rules = run.unit_rules()
    assert "answered no ping before" in rules["EXEC-ROBUST-001"]["reason"]
    # Each kind of command is probed once (one kind unanswered never implies another is):
    # each probe left unanswered fails its own rule (12.1), after its test ran.
    assert {"EXEC-START-001", "EXEC-QUERY-001"} <= run.failed
    # The other scenarios do not pile up failures: could-not-test, with the reason.
    for rule in ("EXEC-SIG-002", "EXEC-QUERY-002", "EXEC-RESEND-001"):
        assert rules[rule]["verdict"] == "could-not-test", rule
        assert "answers no command" in rules[rule]["reason"]
        assert run.outcomes[rule] == "skipped"


def test_a_broker_that_is_down_is_one_error(pytester: pytest.Pytester) -> None:
    port = free_port()
    run = certify(pytester, "--unit", UNIT, "--broker", f"mqtt://127.0.0.1:{port}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert run.outcomes == {}
    # Said once, in the summary, without pytest's wrapping.
    assert run.text.count(f"cannot reach the broker at mqtt://127.0.0.1:{port}") == 1
    assert "Exit" not in run.text and "_pytest" not in run.text
    assert f"not certified: cannot reach the broker at mqtt://127.0.0.1:{port}" in run.text
    assert run.report is not None and "cannot reach" in run.report["facts"]["error"]
    # The report never reads as a pass: its verdict says why, every rule is listed not run.
    assert run.report["verdict"] == "not certified"
    assert run.report["worst"] != "pass"
    rules = run.unit_rules()
    assert rules and all(r["reason"].startswith("not run: cannot reach") for r in rules.values())
    assert set(run.report["not_run"]) == set(rules)


def test_a_unit_that_is_not_there(pytester: pytest.Pytester, mosquitto: str,
                                  prefix: str) -> None:
    nobody = f"{prefix}/unit/air/simulation/dji0"
    run = certify(pytester, "--unit", nobody, "--broker", mosquitto, f"--profile={FAST}")
    assert run.result.ret == NOT_CERTIFIED_EXIT  # not a failed rule: nothing was judged
    assert run.outcomes == {}
    assert run.text.count(f"the unit {nobody} is not alive: no heartbeat") == 1
    assert "_pytest" not in run.text
    assert run.report is not None and run.report["verdict"] == "not certified"
    assert f"Nothing at all was published under {prefix}/" in run.text


class Position:
    """The unit's sensor/position, live every 0.5 s, and (``beat_after``) the reference unit
    started that many seconds later: a unit that is there, its first heartbeat slow."""

    def __init__(self, broker: str, unit: str, beat_after: float | None = None) -> None:
        import threading

        self.broker, self.unit, self.beat_after = broker, unit, beat_after
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        started = time.monotonic()
        sim = None
        position = f"{self.unit}/sensor/position"
        with MqttClient(BrokerURL.parse(self.broker), may_publish=lambda t: t == position
                        ) as client:
            while not self.stop.wait(0.5):  # the unit's pace: a schedule, not a wait
                client.publish(position, b'{"latitude": 57.76, "longitude": 16.68, "altitude": 10.0}')
                if (sim is None and self.beat_after is not None
                        and time.monotonic() - started >= self.beat_after):
                    sim = SimUnit(self.unit, self.broker, rate=3.0).start()
        if sim is not None:
            sim.stop()

    def __enter__(self) -> Position:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(10)


def test_a_unit_whose_other_topics_are_live_gets_longer_for_its_first_heartbeat(
        pytester: pytest.Pytester, mosquitto: str, prefix: str) -> None:
    """FAST's alive-timeout is 3 s: the unit's position is live, its heartbeat comes 4 s in
    (a slow heartbeat), and the run goes on, having said why it waited longer; one that never
    sends a heartbeat is not alive after the whole wait, 3 s and 6 s more, said as such."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    with Position(mosquitto, unit, beat_after=4.0):
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "-k", "HB-001")
    assert (f"{unit}: its other topics are live, but no heartbeat came within 3 s: waiting "
            f"up to 6 s more") in run.text, run.text
    assert "is not alive" not in run.text and run.outcomes.get("HB-001") == "passed", run.text
    with Position(mosquitto, unit):
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert "waiting up to 6 s more" in run.text
    assert f"the unit {unit} is not alive: no heartbeat on {unit}/heartbeat within 9.0 s" \
        in run.text, run.text


def test_a_unit_by_another_name_is_suggested(pytester: pytest.Pytester, mosquitto: str,
                                             prefix: str) -> None:
    with SimUnit(f"{prefix}/unit/air/simulation/dji1", mosquitto, rate=3.0):
        run = certify(pytester, "--unit", f"{prefix}/unit/air/simulation/dji0", "--broker",
                      mosquitto, f"--profile={FAST}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert f"did you mean --unit {prefix}/unit/air/simulation/dji1?" in run.text
    # our own line breaks are line breaks, not an escaped \x0a
    assert "\\x0a" not in run.text
    assert any(line.startswith(f"A unit publishes at {prefix}/unit/air/simulation/dji1")
               for line in run.result.outlines), run.text


def test_the_summary_names_what_could_not_be_tested_and_the_option(
        pytester: pytest.Pytester, mosquitto: str, prefix: str) -> None:
    """Without --reboot-cmd the summary names the REBOOT rules, why, and the
    option that would test them (not only '1 could not be tested')."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    with SimUnit(unit, mosquitto, rate=3.0):
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "-k", "REBOOT")
    summary = run.text[run.text.index("= waraps-conformance ="):]
    assert ("  could not test REBOOT-001, REBOOT-002: no way to reboot the unit: pass "
            "--reboot-cmd 'COMMAND'") in summary, summary
    assert summary.index("could not test REBOOT-001") < summary.index("json report:")


class DropBroker:
    """Kills the private broker before the signal scenario and starts it again once the
    certification has noticed (a broker that drops mid-run and comes back)."""

    def __init__(self, broker: PrivateMosquitto) -> None:
        self.broker = broker
        self.dropped = False

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if self.dropped or not item.name.startswith("test_signal_task"):
            return
        from conformance.suite.session import CERTIFICATION

        certification = item.config.stash[CERTIFICATION]
        client = certification.client
        self.dropped = True
        self.broker.stop()
        deadline = time.monotonic() + 10
        while client.is_connected and time.monotonic() < deadline:
            time.sleep(0.01)  # poll the flag until paho notices (bounded by the deadline)
        self.broker.start()
        # Go on once the unit is back too (its own client reconnects with its own backoff).
        mark = certification.traffic.mark()
        assert client.wait_connected(10)
        assert certification.traffic.wait_for(lambda e: True, 10, after=mark,
                                              subtopic="heartbeat")


def test_a_broker_that_drops_mid_run_and_comes_back(pytester: pytest.Pytester,
                                                    tmp_path: Path) -> None:
    broker = PrivateMosquitto(tmp_path).start()
    unit = "waraps/unit/air/simulation/dji0"
    try:
        with SimUnit(unit, broker.url, rate=3.0, seed=2) as sim:
            dropper = DropBroker(broker)
            run = certify(pytester, "--unit", unit, "--broker", broker.url,
                          f"--profile={FAST}", plugins=(Rebooter(sim), dropper))
    finally:
        broker.stop()
    assert dropper.dropped
    assert "broker connection lost" in run.text
    assert "broker connection back after" in run.text
    assert run.report is not None and len(run.report["gaps"]) >= 1
    assert run.result.ret == 0, run.text  # recovered, and finished with every rule judged
    assert run.outcomes["EXEC-SIG-002"] == "passed"


def _json(payload: bytes) -> dict:
    """A message's JSON object, or {}: the robustness scenario's malformed commands on
    exec/command (a truncated object among them) are no answer to read."""
    try:
        body = orjson.loads(payload)
    except orjson.JSONDecodeError:
        return {}
    return body if isinstance(body, dict) else {}


def test_ctrl_c_in_the_middle_writes_reports_and_aborts_tasks(tmp_path: Path, mosquitto: str,
                                                              unit_address: UnitAddress) -> None:
    """pytest in a subprocess; SIGINT once a task it started is running."""
    reports = tmp_path / "reports"
    unit = str(unit_address)
    seen: list[dict] = []
    with SimUnit(unit, mosquitto, rate=3.0, seed=4), \
            MqttClient(BrokerURL.parse(mosquitto)) as watcher:
        watcher.subscribe(unit + "/exec/#")
        cmd = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-o", "addopts=",
               "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
               f"--reports-dir={reports}", "-q"]
        proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
        running: set[str] = set()
        deadline = time.monotonic() + 60
        while not running and time.monotonic() < deadline:
            m = watcher.get(timeout=1)
            if m is None:
                continue
            body = _json(m.payload)
            seen.append(body)
            if m.topic.endswith("/feedback") and body.get("status") == "running":
                running.add(body["task-uuid"])
        assert running, "no task was started within 60 s"
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        for m in watcher.messages(timeout=0.5):  # what the teardown sent
            seen.append(_json(m.payload))
    assert proc.returncode == pytest.ExitCode.INTERRUPTED, out
    aborted = {b.get("task-uuid") for b in seen
               if b.get("command") == "signal-task" and b.get("signal") == "$abort"}
    ended = {b.get("task-uuid") for b in seen
             if b.get("status") in ("finished", "failed", "aborted")}
    assert running <= aborted | ended, out
    (report,) = reports.glob("*.json")
    data = json.loads(report.read_text())
    assert data["facts"]["interrupted"] is True
    assert "aborted" in out or running <= ended


def test_the_packaged_suite_runs_from_a_project_with_its_own_testpaths(tmp_path: Path) -> None:
    """--unit without paths runs exactly the packaged suite, even where an ini file points
    pytest at other tests (this repository's own pyproject does)."""
    (tmp_path / "pytest.ini").write_text("[pytest]\ntestpaths = mytests\n")
    (tmp_path / "mytests").mkdir()
    (tmp_path / "mytests" / "test_mine.py").write_text("def test_mine():\n    pass\n")
    out = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "--unit",
                          UNIT, "--broker", "embedded", "--sim-rate", "3", "--collect-only",
                          "-q"], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "test_mine" not in out.stdout
    assert "test_passive.py::test_rule[HB-003]" in out.stdout
    assert "test_execution.py::test_ping[EXEC-PING-001]" in out.stdout


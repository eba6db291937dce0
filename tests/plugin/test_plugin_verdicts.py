"""False greens (docs/ARCHITECTURE.md 'Verdicts': certified is earned only by a complete run that
judged every rule of the level on evidence): a unit that dies, a run of selected rules, a broker
lost for good. None of them shows a level certified or a ``pass`` verdict, in any output: the
terminal, the JSON and HTML reports, pytest's JUnit file."""

from __future__ import annotations

import shlex
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import orjson
import pytest
from certify_helpers import FAST, UNIT, Certified, PrivateMosquitto, Rebooter, certify

from conformance.client import BrokerURL, MqttClient
from conformance.plugin import NOT_CERTIFIED_EXIT
from conformance.sim import SimUnit

CERTIFICATION_META = [
    "agent_uuid", "allow_hostile", "allow_motion", "commands_sent", "dry_run", "exit_status",
    "explore", "explore_story", "profile_source", "reboot", "rerun", "safety", "seed",
    "timing_scale", "tst_command_topic", "unit"]
"""The keys of a certification's JSON ``meta`` (tests/reporting/test_run_meta.py's list)."""

pytestmark = pytest.mark.slow


def junit_properties(path: Path) -> dict[str, str]:
    """The test suite's own properties (each test case has its own 'verdict' too)."""
    suite = next(ET.parse(path).getroot().iter("testsuite"))
    found = suite.find("properties")
    assert found is not None
    return {p.get("name", ""): p.get("value", "") for p in found.iter("property")}


def assert_no_level_certified(run: Certified, junit: Path) -> None:
    """No output says 'certified' for a level, and none says the verdict is 'pass'."""
    assert run.report is not None, run.text
    summary = run.text[run.text.index("= waraps-conformance ="):]
    assert "— certified" not in summary and ": pass" not in summary, summary
    assert run.report["verdict"] != "pass" and run.report["conclusion"]["verdict"] != "pass"
    conclusion = run.report["conclusion"]
    assert conclusion["verdict"] == run.report["verdict"]
    (unit,) = conclusion["units"].values()
    assert unit["levels"] and not any(level["certified"] for level in unit["levels"])
    assert all(level["why"] for level in unit["levels"])
    (html,) = run.reports_dir.glob("*.html")
    head = html.read_text().split('<details class="fold">')[0]  # what opens the report
    assert "— certified" not in head and "not certified" in head
    assert ">pass<" not in head
    props = junit_properties(junit)
    assert props["verdict"] == run.report["verdict"]
    assert "— certified" not in props["levels"] and "not certified" in props["levels"]


def test_a_unit_that_dies_on_a_command_is_not_certified(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  "--sim-fault=dies-on-missing-task-uuid", f"--profile={FAST}",
                  "--junitxml=junit.xml")
    assert run.result.ret == pytest.ExitCode.TESTS_FAILED, run.text
    assert run.outcomes["HB-012"] == "failed"
    assert run.report is not None and run.report["verdict"] == "fail"
    assert_no_level_certified(run, pytester.path / "junit.xml")
    (unit,) = run.report["conclusion"]["units"].values()
    assert unit["died_at"] is not None
    assert all("the unit died at" in level["why"] for level in unit["levels"])
    # A level it never claimed stays not claimed when it dies (the public agents' TST rules
    # read 'fell silent ... no answer could come'): skipped, not could-not-test.
    tst = {r: v for r, v in run.unit_rules().items() if r.startswith("TST-")}
    assert tst and all(v["verdict"] == "skip" and v["reason"].startswith(
        ("not claimed", "commander-side")) for v in tst.values()), tst
    # The keys a certification's report has always written (RunMeta's, results.py), and the
    # command that reruns each failed or warned rule alone: none dropped.
    found = [r for r, v in run.unit_rules().items() if v["verdict"] in ("fail", "warn")]
    assert sorted(run.report["meta"]) == sorted([*CERTIFICATION_META, *(f"rerun {r}" for r in found)])
    assert run.report["meta"]["rerun HB-012"].endswith("-k HB-012")


def test_a_unit_whose_messages_could_not_be_examined_is_not_certified(
        pytester: pytest.Pytester) -> None:
    """Camera frames over the 1 MiB a message is examined up to (MSG-004, decided: a warn):
    what they held is no evidence, so the run is never a pass, a warn or a could-not-test
    with exit 0."""
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  "--sim-fault=camera-data-url", "--explore", "0", "--junitxml=junit.xml")
    assert run.result.ret == NOT_CERTIFIED_EXIT, run.text
    assert run.report is not None and run.report["verdict"] == "not certified"
    assert_no_level_certified(run, pytester.path / "junit.xml")
    (unit,) = run.report["conclusion"]["units"].values()
    assert all("could not be examined whole (MSG-004)" in level["why"]
               for level in unit["levels"])


def test_a_run_of_selected_rules_is_partial(pytester: pytest.Pytester) -> None:
    """-k HB-003 on a unit that never answers ping: the selected rule passes, the run does
    not (partial, no level certified), and its repeat line keeps the selection."""
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  "--sim-fault=pong-missing", f"--profile={FAST}", "-k", "HB-003 or HB-002",
                  "--junitxml=junit.xml")
    assert run.result.ret == pytest.ExitCode.OK, run.text  # no selected rule failed
    assert run.outcomes == {"HB-002": "passed", "HB-003": "passed"}
    assert run.report is not None
    assert run.report["verdict"] == "partial" and run.report["partial"] is True
    assert_no_level_certified(run, pytester.path / "junit.xml")
    assert junit_properties(pytester.path / "junit.xml")["partial"] == "true"
    # Rules left out are not run, not passed (the counts say so in every output).
    rules = run.unit_rules()
    assert rules["EXEC-PING-001"]["verdict"] == "could-not-test"
    assert rules["EXEC-PING-001"]["reason"].startswith("not run: not selected")
    assert run.report["conclusion"]["counts"]["not run"] == len(rules) - 2
    # The repeat line keeps the selection, shell-quoted: split as a shell would, it is -k's.
    line = next(ln for ln in run.text.splitlines() if ln.startswith("repeat this run: "))
    words = shlex.split(line.removeprefix("repeat this run: "))
    assert words[words.index("-k") + 1] == "HB-003 or HB-002"
    assert run.report["meta"]["rerun"] == line.removeprefix("repeat this run: ")


class LoseBroker:
    """Stops the private broker for good before the start-task scenario: a broker that dies a
    few seconds into the run and never returns."""

    def __init__(self, broker: PrivateMosquitto) -> None:
        self.broker = broker
        self.at: float | None = None

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if self.at is None and item.name.startswith("test_start_task"):
            self.at = time.time()
            self.broker.stop()


def test_a_broker_lost_for_good_ends_not_certified(pytester: pytest.Pytester,
                                                  tmp_path: Path) -> None:
    broker = PrivateMosquitto(tmp_path / "broker").start()
    unit = "waraps/unit/air/simulation/dji0"
    try:
        with SimUnit(unit, broker.url, rate=3.0, seed=2) as sim:
            lose = LoseBroker(broker)
            run = certify(pytester, "--unit", unit, "--broker", broker.url,
                          f"--profile={FAST}", "--junitxml=junit.xml",
                          plugins=(Rebooter(sim), lose))
    finally:
        broker.stop()
    assert lose.at is not None
    assert run.result.ret == NOT_CERTIFIED_EXIT, run.text
    assert "Traceback" not in run.text and "BrokerError" not in run.text, run.text
    assert "has not come back" in run.text
    assert run.report is not None and run.report["verdict"] == "not certified"
    assert any("the broker was lost at" in why for why in run.report["conclusion"]["why"])
    assert "Ctrl-C" not in run.text
    assert_no_level_certified(run, pytester.path / "junit.xml")
    # The outage is never the unit's: nothing failed, the rest is not run.
    assert not run.failed, run.failed
    rules = run.unit_rules()
    assert not [r for r, v in rules.items() if v["verdict"] == "fail"]
    assert rules["HB-012"]["verdict"] == "could-not-test"
    assert rules["EXEC-START-001"]["verdict"] == "could-not-test"


class LoseBrokerWithATaskRunning:
    """Stops the private broker once the suite has started a task, and starts it again only
    when the run has given the broker up (the teardown then aborts the task it started)."""

    def __init__(self, broker: PrivateMosquitto, unit: str) -> None:
        self.broker = broker
        self.unit = unit
        self.stopped = threading.Event()
        self.open_tasks: set[str] = set()
        self.watcher: MqttClient | None = None

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if self.stopped.is_set() or not item.name.startswith("test_start_task"):
            return
        from conformance.suite.session import CERTIFICATION

        certification = item.config.stash[CERTIFICATION]
        threading.Thread(target=self._run, args=(certification,), daemon=True).start()

    def _run(self, certification: Any) -> None:
        deadline = time.monotonic() + 30
        while not certification.commander.open_tasks and time.monotonic() < deadline:
            time.sleep(0.01)  # polling the suite's own state, bounded by the deadline
        self.open_tasks = set(certification.commander.open_tasks)
        self.broker.stop()
        self.stopped.set()
        while not any("has not come back" in e for e in certification.events) \
                and time.monotonic() < deadline + 60:
            time.sleep(0.05)
        self.broker.start()
        self.watcher = MqttClient(BrokerURL.parse(self.broker.url)).connect()
        self.watcher.subscribe(self.unit + "/exec/command")


def test_tasks_started_before_the_broker_was_lost_are_aborted_when_it_returns(
        pytester: pytest.Pytester, tmp_path: Path) -> None:
    broker = PrivateMosquitto(tmp_path / "broker").start()
    unit = "waraps/unit/air/simulation/dji0"
    try:
        with SimUnit(unit, broker.url, rate=3.0, seed=2) as sim:
            lose = LoseBrokerWithATaskRunning(broker, unit)
            run = certify(pytester, "--unit", unit, "--broker", broker.url,
                          f"--profile={FAST}", plugins=(Rebooter(sim), lose))
            assert lose.watcher is not None, run.text
            aborts = [orjson.loads(m.payload) for m in lose.watcher.messages(timeout=0.5)]
            lose.watcher.close()
    finally:
        broker.stop()
    assert run.result.ret == NOT_CERTIFIED_EXIT, run.text
    assert "Traceback" not in run.text and "BrokerError" not in run.text, run.text
    assert "broker connection back after" in run.text, run.text
    # The teardown sent $abort for the task it had started, once the broker was back (the unit's
    # own client may come back later: its answer is not waited for past the budget).
    assert lose.open_tasks, "no task was open when the broker was stopped"
    aborted = {a.get("task-uuid") for a in aborts
               if a.get("command") == "signal-task" and a.get("signal") == "$abort"}
    assert lose.open_tasks <= aborted, (lose.open_tasks, aborts)
    assert not [r for r, v in run.unit_rules().items() if v["verdict"] == "fail"]


def test_a_reports_folder_that_takes_no_file_is_a_usage_error(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--unit", UNIT,
                                           "--broker", "virtual", "--reports-dir", "/proc")
    out = result.stdout.str() + result.stderr.str()
    assert result.ret == pytest.ExitCode.USAGE_ERROR, out
    assert "--reports-dir '/proc': cannot write a report into it" in out
    assert "Traceback" not in out and "INTERNALERROR" not in out


def test_an_absent_unit_whose_reports_cannot_be_written_ends_not_certified(
        pytester: pytest.Pytester, mosquitto: str) -> None:
    """The folder replaced by a file while the suite waits for a heartbeat that never comes:
    once a bare traceback and exit 1; now said, and the run's own status (6)."""
    import subprocess
    import sys

    reports = pytester.path / "reports"
    proc = subprocess.Popen(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "--unit",
         "waraps/unit/air/real/absent9", "--broker", mosquitto, "--reports-dir", str(reports)],
        cwd=pytester.path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:  # the header is printed before the heartbeat is awaited
            lines.append(line)
            if "collected" in line or "waiting up to" in line:
                break
        reports.rmdir()
        reports.write_text("a file where the reports go\n")
        rest, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    out = "".join(lines) + rest
    assert proc.returncode == NOT_CERTIFIED_EXIT, out
    assert f"could not write the reports into {reports}" in out
    assert "Traceback" not in out


def test_a_unit_killed_by_a_probe_is_judged_on_the_scenarios_before_it_and_restarted(
        pytester: pytest.Pytester) -> None:
    """The public L2 agents died on the start-task with invalid parameters (EXEC-START-004's
    probe) in some runs: that probe runs after the scenarios whose evidence a death would
    destroy (signal, query, resend), so they are judged; where the run can reboot the unit
    it is restarted and the run carries on, saying so, and the death stays HB-012's."""
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  "--sim-fault=dies-on-invalid-params", f"--profile={FAST}")
    rules = run.unit_rules()
    assert rules["HB-012"]["verdict"] == "fail", rules["HB-012"]
    judged = ("EXEC-SIG-001", "EXEC-SIG-002", "EXEC-QUERY-001", "EXEC-RESEND-001",
              "EXEC-RESEND-002", "EXEC-ROBUST-001", "EXEC-ROBUST-002")
    assert {r: rules[r]["verdict"] for r in judged} == dict.fromkeys(judged, "pass"), \
        {r: rules[r] for r in judged}
    assert rules["EXEC-START-004"]["verdict"] == "could-not-test"  # it died on it
    assert "restarting it with the bundled reference unit's reboot and carrying on" in \
        run.text, run.text
    assert "the unit is back" in run.text and "after its restart" in run.text


def test_a_unit_restarted_under_another_name_is_named_not_followed(
        pytester: pytest.Pytester) -> None:
    """The public C++ agent adds a random suffix to its name at every start: restarted after
    its death it heartbeats under another address. The run says which name appeared, and
    still judges only the unit under test (it never publishes to the new name)."""
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  "--sim-fault=dies-on-invalid-params", "--sim-fault=reboot-renames",
                  f"--profile={FAST}")
    assert "restarting it with the bundled reference unit's reboot" in run.text, run.text
    said = run.text.split("restarting it with", 1)[1]
    assert "but no heartbeat within" in said, said
    assert "a unit of its type and role first heard since: 'dji0" in said, said
    assert run.unit_rules()["HB-012"]["verdict"] == "fail"

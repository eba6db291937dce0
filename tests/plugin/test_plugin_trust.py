"""Certification you can trust: bounded, visible, and never a false green.

- a unit with a stalling fault (statuses outside 12.4's list, no final feedback, its own
  task-uuids, feedback without task-uuid) is certified within a deadline, exactly its rule
  failing: the scenarios adapt to a deviation once seen (noted once) instead of waiting again;
- --max-duration stops a run cleanly: the waiting test fails saying for what, started tasks
  are aborted, the report says 'interrupted' and lists the rules not run;
- an interrupted run (Ctrl-C) is never a pass; --rule selects a rule and its evidence;
- progress: waits that last are shown (plain lines off a terminal), -v shows each step, -q
  shows nothing.
"""

from __future__ import annotations

import re

import pytest
from certify_helpers import (
    DEADLINE,
    MATRIX,
    REAL_STALL,
    STALL,
    UNIT,
    certify,
    certify_sim,
    certify_stalling,
    certify_virtual,
)

from conformance.plugin import INTERRUPTED_EXIT
from conformance.sim import FAULTS

STALLING = {"feedback-status-done": "EXEC-FB-002", "feedback-no-task-uuid": "EXEC-FB-001",
            "task-uuid-ignored": "EXEC-START-002", "no-final-feedback": "EXEC-START-003"}



@pytest.mark.slow
@pytest.mark.parametrize("fault", sorted(STALLING))
def test_a_stalling_fault_ends_within_the_deadline(pytester: pytest.Pytester,
                                                   request: pytest.FixtureRequest,
                                                   prefix: str, fault: str) -> None:
    # In virtual time (the deadline is the unit's time), but REAL_STALL end to end.
    broker = request.getfixturevalue("mosquitto") if fault == REAL_STALL else None
    run = certify_stalling(pytester, broker, prefix, fault)
    # The deviation is noted once, with its rule, and the run adapted to it.
    assert run.text.count(f"adapted to {STALLING[fault]}:") == 1, run.text[-3000:]
    assert "waiting for" not in run.text  # -q: no progress lines


@pytest.mark.slow
def test_max_duration_stops_cleanly_and_says_what_it_waited_for(
        pytester: pytest.Pytester, mosquitto: str, prefix: str) -> None:
    """$pause is acknowledged but never followed by 'paused' (pause-ignored; 30 s feedback
    deadline): the run stops at --max-duration, inside that wait."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    run = certify_sim(pytester, mosquitto, unit, f"--profile={STALL}", "--seed", "1", "-v",
                      "--max-duration", "25s", faults=("pause-ignored",))
    assert run.result.ret == INTERRUPTED_EXIT, run.text[-2000:]
    # The 'paused' wait starts a few seconds in: stopped at 25 s of the run's own clock, the
    # run ends before that 30 s wait (and the scenarios after it) would have, however loaded
    # the machine (the report's own times, not this test's).
    assert run.report is not None
    assert run.report["finished"] - run.report["started"] < 25 + 30
    assert "--max-duration 25 s reached while waiting for the 'paused' feedback of " \
        "look-at-bearing" in run.text
    assert run.failed == {"EXEC-SIG-001"}  # the test that was waiting; then it stops
    assert "aborted 1 task(s) or TST tree(s) the suite had started" in run.text
    # Progress (not a terminal: plain lines) and -v's steps.
    assert "waiting for the 'paused' feedback of look-at-bearing" in run.text
    assert " s of 30 s" in run.text
    assert "sent signal-task $pause" in run.text and "sent start-task look-at-bearing" in run.text
    report = run.report
    assert report is not None and report["verdict"] == "interrupted"
    not_run = report["not_run"]
    assert "EXEC-QUERY-001" in not_run and "HB-003" in not_run
    assert run.unit_rules()["HB-003"]["reason"].startswith("not run: --max-duration")
    assert "interrupted (" in run.text


class Interrupt:
    """Presses Ctrl-C when the signal scenario is about to run."""

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if item.name.startswith("test_signal_task"):
            raise KeyboardInterrupt


def test_an_interrupted_run_is_never_a_pass(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  f"--profile={MATRIX}", "--seed", "1", "-k", "test_ping or test_signal_task",
                  plugins=(Interrupt(),), no_reraise_ctrlc=True)
    assert run.result.ret == INTERRUPTED_EXIT
    assert run.outcomes and set(run.outcomes.values()) == {"passed"}  # ping passed
    report = run.report
    assert report is not None and report["verdict"] == "interrupted"
    assert report["verdict"] == "interrupted" and report["worst"] != "pass"
    signal = {"EXEC-SIG-001", "EXEC-SIG-002", "EXEC-SIG-003", "EXEC-SIG-004", "EXEC-SIG-005"}
    rules = run.unit_rules()
    # Selected and never run: interrupted; the rest was not selected (a partial run).
    assert set(report["not_run"]) == set(rules) - set(run.outcomes)
    for rule in signal:
        assert rules[rule]["reason"] == "not run: interrupted (Ctrl-C)", rules[rule]
    assert rules["HB-003"]["reason"].startswith("not run: not selected (-k ")
    assert "dji0: interrupted (" in run.text


def test_rule_option_runs_the_rule_and_the_scenarios_of_its_evidence(
        pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  f"--profile={MATRIX}", "--seed", "1", "--rule", "EXEC-FB-002",
                  "--sim-fault=feedback-status-typo")
    assert run.outcomes == {"EXEC-FB-002": "failed"}
    assert run.result.ret == pytest.ExitCode.TESTS_FAILED
    assert re.search(r"1 failed, \d+ deselected", run.text)


def test_rule_option_names_a_close_rule(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "--unit", UNIT, "--broker",
                                          "embedded", "--rule", "HB-03")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    err = result.stderr.str()
    assert "--rule 'HB-03' is not a rule of the catalogue (did you mean" in err
    assert "HB-003" in err


def test_help_documents_the_exit_statuses_and_the_guard(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest_inprocess("--help")
    text = result.stdout.str()
    words = " ".join(text.split())
    assert "0 certified (every claimed level; with -k/--rule: no selected rule failed), 1 a " \
           "rule failed, 2 interrupted" in words
    assert "6 not certified" in words and "7 not certified (no rule failed, but a rule a " \
           "claimed level needs could not be tested)" in words
    assert "--max-duration" in text and "--rule" in text


def test_a_slow_unit_without_final_statuses_is_certified_within_the_deadline(
        pytester: pytest.Pytester, prefix: str) -> None:
    """A 1 Hz unit whose tasks move at their real speeds (longer than the default profile's
    30 s feedback_timeout) and which sends no final status at all, certified with the default
    options (in virtual time: the deadline is the unit's time): the waits end on what the
    unit showed (a task leaving tasks-executing, the deviation once noted), not each on the
    full feedback deadline (133-136 s before), and exactly the fault's rules fail."""
    run = certify_virtual(pytester, f"{prefix}/unit/air/simulation/dji0", "--seed", "1", "-q",
                          faults=("no-final-status",), variants=("real-speed",), rate=1.0)
    assert run.report is not None, run.text[-3000:]
    assert run.report["finished"] - run.report["started"] < DEADLINE
    assert run.failed == set(FAULTS["no-final-status"].rules), run.text[-3000:]
    assert run.text.count("adapted to EXEC-START-003:") == 1, run.text[-3000:]

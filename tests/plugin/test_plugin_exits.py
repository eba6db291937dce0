"""Exit statuses that mean what a gate needs (README 'Exit status'): 0 only when the run
certified what it set out to (a complete run: every level the unit claims; a run narrowed
with -k/--rule: no selected rule failed); every other outcome its own status, and the
terminal's last line says the status and why."""

from __future__ import annotations

import socket

import pytest
from certify_helpers import FAST, MATRIX, UNIT, Certified, certify, certify_virtual

from conformance.plugin import (
    CERTIFIED_EXIT,
    FAILED_EXIT,
    INTERRUPTED_EXIT,
    NOT_CERTIFIED_EXIT,
    UNTESTED_EXIT,
)
from conformance.sim import SimUnit

pytestmark = pytest.mark.slow


def last_line(run: Certified) -> str:
    """The last line the terminal printed (after pytest's own counts)."""
    lines = [line for line in run.result.outlines if line.strip()]
    assert lines, run.text
    return lines[-1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_0_a_complete_run_that_certified_every_claimed_level(pytester: pytest.Pytester) -> None:
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", "--seed", "7", rate=3.0)
    assert run.result.ret == CERTIFIED_EXIT, run.text[-3000:]
    assert last_line(run) == "exit 0: certified: sensor, direct execution"


def test_0_a_narrowed_run_in_which_no_selected_rule_failed(pytester: pytest.Pytester) -> None:
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", "-k", "EXEC-PING-001", rate=3.0)
    assert run.result.ret == CERTIFIED_EXIT, run.text[-3000:]
    assert last_line(run).startswith("exit 0: partial (only the selected rules ran: -k "
                                     "EXEC-PING-001): no selected rule failed; no level is "
                                     "certified by a partial run"), last_line(run)


def test_1_a_rule_failed(pytester: pytest.Pytester) -> None:
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", "-k", "EXEC-PING-001",
                          faults=("pong-missing",), rate=3.0)
    assert run.result.ret == FAILED_EXIT, run.text[-3000:]
    assert last_line(run) == "exit 1: a rule failed: EXEC-PING-001"


class Interrupt:
    """Presses Ctrl-C when the signal scenario is about to run."""

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if item.name.startswith("test_signal_task"):
            raise KeyboardInterrupt


def test_2_interrupted(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "3",
                  f"--profile={MATRIX}", "-k", "test_ping or test_signal_task",
                  plugins=(Interrupt(),), no_reraise_ctrlc=True)
    assert run.result.ret == INTERRUPTED_EXIT, run.text[-3000:]
    assert last_line(run).startswith("exit 2: interrupted (Ctrl-C"), last_line(run)


def test_6_the_broker_cannot_be_reached(pytester: pytest.Pytester) -> None:
    port = free_port()  # nothing listens there
    run = certify(pytester, "--unit", UNIT, "--broker", f"mqtt://127.0.0.1:{port}")
    assert run.result.ret == NOT_CERTIFIED_EXIT, run.text[-3000:]
    assert f"not certified: cannot reach the broker at mqtt://127.0.0.1:{port}" in run.text
    assert last_line(run) == "exit 6: not certified: no rule was judged (the error above says " \
                             "why)"


def test_7_a_real_unit_without_opt_ins_is_not_certified(pytester: pytest.Pytester,
                                                        prefix: str) -> None:
    """A `real` unit: no hostile payloads without --allow-hostile, so EXEC-ROBUST-* could not
    be tested; no rule failed, and the run is no certificate."""
    unit = f"{prefix}/unit/air/real/dji0"
    run = certify_virtual(pytester, unit, f"--profile={FAST}", "--seed", "7", rate=3.0)
    assert run.result.ret == UNTESTED_EXIT, run.text[-3000:]
    assert run.report is not None and run.report["conclusion"]["exit_code"] == UNTESTED_EXIT
    line = last_line(run)
    assert line.startswith("exit 7: not certified: no rule failed, but "), line
    assert "--allow-hostile" in line, line


def test_7_without_reboot_cmd_no_level_is_certified(pytester: pytest.Pytester, mosquitto: str,
                                                    prefix: str) -> None:
    """A `simulation` unit on a real broker and no way to reboot it: REBOOT-001 holds for
    every level, so no level is certified, whatever else passed."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    with SimUnit(unit, mosquitto, rate=3.0, seed=1):
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "--seed", "7")
    assert run.result.ret == UNTESTED_EXIT, run.text[-3000:]
    line = last_line(run)
    assert line.startswith("exit 7: not certified: no rule failed, but sensor: "), line
    assert "could not test REBOOT-001, REBOOT-002: no way to reboot the unit: pass " \
           "--reboot-cmd" in line, line


def test_the_last_line_says_when_a_test_failed_that_the_whole_run_does_not_fail() -> None:
    """A rule whose test failed when it ran (pytest's 1) that the whole run's report does not
    fail: the last line says so, never 'the suite's own error'."""
    from conformance.conclusion import conclude
    from conformance.results import RunReport, UnitReport
    from conformance.suite.gate import last_line
    from conformance.violation import RuleResult, Verdict

    rules = {"HB-003": RuleResult("HB-003", Verdict.PASS, "")}
    report = RunReport("certification", 1.0, 2.0, units={UNIT: UnitReport(
        UNIT, "air", "simulation", "dji0", levels=["sensor"], rules=rules)})
    line = last_line(report, conclude(report), UNIT, FAILED_EXIT, failed_then=("HB-003",))
    assert line == ("exit 1: HB-003 failed when its test ran; the whole run's report does not "
                    "fail it (its verdict: pass): see the reports"), line
    assert "own error" in last_line(report, conclude(report), UNIT, FAILED_EXIT)

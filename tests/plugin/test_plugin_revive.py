"""A unit that is not alive when the run begins (an earlier run may have left it dead) is
restarted once with --reboot-cmd before it is judged not alive, and the run says so; without
--reboot-cmd the message suggests it."""

from __future__ import annotations

import os
import shlex
import signal
import sys
from pathlib import Path

import pytest
from certify_helpers import FAST, certify

NOT_CERTIFIED_EXIT = 6


def test_a_dead_unit_is_restarted_by_the_reboot_command_before_it_is_judged(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, tmp_path: Path) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    pidfile = tmp_path / "sim.pid"
    start = (f"timeout 60 {shlex.quote(sys.executable)} -m conformance.cli sim --unit {unit} "
             f"--broker {mosquitto} --rate 3 >/dev/null 2>&1 & echo $! > {pidfile}")
    try:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      f"--reboot-cmd={start}", "-k", "HB-001")
    finally:
        if pidfile.exists():
            os.kill(int(pidfile.read_text()), signal.SIGTERM)
    assert "restarting the unit before judging it" in run.text
    assert "reboot requested (--reboot-cmd" in run.text
    assert "the unit was not alive when the run began" in run.text
    assert run.outcomes == {"HB-001": "passed"}  # judged after the restart


def test_a_restart_that_brings_nothing_back_says_so(pytester: pytest.Pytester, mosquitto: str,
                                                    prefix: str, tmp_path: Path) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    quick = tmp_path / "quick.yaml"
    quick.write_text(f"extends: {FAST}\nreboot-timeout: 1\n")
    run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={quick}",
                  "--reboot-cmd=true")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert "It was restarted with --reboot-cmd true; still no heartbeat" in run.text
    failing = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={quick}",
                      "--reboot-cmd=echo no such unit >&2; exit 3")
    assert failing.result.ret == NOT_CERTIFIED_EXIT
    assert "which failed: exit status 3: no such unit" in failing.text


def test_without_a_reboot_command_the_message_suggests_one(pytester: pytest.Pytester,
                                                          mosquitto: str, prefix: str) -> None:
    run = certify(pytester, "--unit", f"{prefix}/unit/air/simulation/dji0", "--broker",
                  mosquitto, f"--profile={FAST}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert "pass --reboot-cmd 'COMMAND' and the suite restarts it before judging it" in run.text


def test_the_first_line_says_what_the_run_is_waiting_for(pytester: pytest.Pytester,
                                                         mosquitto: str, prefix: str) -> None:
    """Before the header (which needs the unit's first heartbeat), the run says what it
    connects to and what it awaits, so a person never looks at a silent terminal."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}")
    first = run.text.index(f"waraps-conformance: connecting to {mosquitto}, then waiting up "
                           f"to 3 s for a heartbeat of {unit}")
    assert first < run.text.index("test session starts")
    quiet = certify(pytester, "-q", "--unit", unit, "--broker", mosquitto, f"--profile={FAST}")
    assert "connecting to" not in quiet.text

"""`waraps-conformance demo`, and rebooting the unit with --reboot-cmd."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from certify_helpers import FAST, MATRIX, certify

from conformance.sim import SimUnit
from conformance.topics import UnitAddress

pytestmark = pytest.mark.slow


def test_demo_certifies_the_reference_unit_end_to_end(tmp_path: Path) -> None:
    # At 3 Hz for a quick test, with the self-test profile's jitter allowance (the demo's
    # own default is 1 Hz: bench/bench_certify.py measures that).
    done = subprocess.run([sys.executable, "-m", "conformance.cli", "demo", "--rate", "3",
                           "--profile", str(FAST), "--reports-dir", str(tmp_path / "reports"),
                           "-q"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    assert "the reference unit waraps/unit/air/simulation/dji0 passed" in out
    after = out[out.index("\nreports:"):]  # the demo's own last lines
    paths = [line.split()[-1] for line in after.splitlines()
             if line.strip().startswith(("html ", "json "))]
    assert len(paths) == 2 and all(Path(p).is_file() for p in paths)


def test_demo_with_a_fault_fails_and_says_which_rule(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "conformance.cli", "demo", "--rate", "3",
                           "--fault", "heartbeat-type-case", "--reports-dir",
                           str(tmp_path / "reports"), "-q", "--", "-k", "HB-002"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=180)
    assert done.returncode == 1
    assert "HB-002 heartbeat type is 'HeartBeat'" in done.stdout
    assert "did not pass" in done.stdout


# The reboot tests certify with the matrix profile: the reboot scenario runs start first
# (REBOOT-002 asks about the tasks that ended before it), and three tasks are enough for that.


def sim_process(unit: str, broker: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "conformance.cli", "sim", "--unit", unit,
                             "--broker", broker, "--rate", "3"], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None
    for _ in range(20):
        if proc.stdout.readline().startswith("ready "):
            return proc
    proc.kill()
    raise RuntimeError("the reference unit did not start")


def test_reboot_cmd_reboots_the_unit(pytester: pytest.Pytester, mosquitto: str,
                                     unit_address: UnitAddress) -> None:
    proc = sim_process(str(unit_address), mosquitto)
    try:
        run = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                      f"--profile={MATRIX}", "--reboot-cmd", f"kill -HUP {proc.pid}",
                      "-k", "test_start_task or test_reboot")
    finally:
        proc.terminate()
        proc.wait(10)
    assert run.result.ret == 0, run.text
    assert run.outcomes["REBOOT-001"] == run.outcomes["REBOOT-002"] == "passed"
    assert f"--reboot-cmd 'kill -HUP {proc.pid}'" in run.text


def test_a_failing_reboot_cmd_and_none_are_could_not_test(pytester: pytest.Pytester,
                                                          mosquitto: str,
                                                          unit_address: UnitAddress) -> None:
    with SimUnit(unit_address, mosquitto, rate=3.0):
        failing = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                          f"--profile={MATRIX}", "--reboot-cmd", "echo no such robot >&2; exit 3",
                          "-k", "test_reboot")
        without = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                          f"--profile={MATRIX}", "-k", "test_reboot", "-rs")
    assert failing.result.ret == 0 and without.result.ret == 0
    assert failing.outcomes == without.outcomes == {"REBOOT-001": "skipped",
                                                    "REBOOT-002": "skipped"}
    reason = failing.unit_rules()["REBOOT-001"]["reason"]
    assert "failed: exit status 3: no such robot" in reason
    assert "could not test: no way to reboot the unit: pass --reboot-cmd" in without.text

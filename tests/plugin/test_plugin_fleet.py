"""Two units served by one process on one MQTT connection (``conformance.sim.Fleet``), as a
unit written elsewhere may serve several vehicles through one client: each is certified on its
own while the other runs beside it (and reboots with it: the suite's reboot restarts the
process), and the lint of the recording of both certifications finds no fault in either. On
Mosquitto: what is tested is the shared connection, which the virtual double does not have.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from certify_helpers import Certified, certify, recorded, tell_holds
from test_plugin_variants import PROFILE, accusations, first_violations

from conformance.sim import Fleet
from conformance.topics import UnitAddress

pytestmark = pytest.mark.slow

RATE = 1.0
"""Hz of both units."""


class ProcessRebooter:
    """Reboots the process that serves the fleet (pytest_waraps_reboot), as a --reboot-cmd
    that restarts it would: every unit it serves reboots, not only the one certified."""

    def __init__(self, fleet: Fleet) -> None:
        self.fleet = fleet
        self.calls = 0

    def pytest_waraps_reboot(self, config: pytest.Config, unit: str) -> bool:
        self.calls += 1
        self.fleet.reboot()
        return True

    def pytest_sessionstart(self, session: pytest.Session) -> None:
        """The fleet shares this process: the certification is told when the host held it
        (as ``certify_helpers.Rebooter`` does; the lint of the recording cannot be)."""
        tell_holds(session, self.fleet.runtime)


def certify_both(pytester: pytest.Pytester, broker: str, base: UnitAddress,
                 recording: Path) -> tuple[list[UnitAddress], list[Certified]]:
    """Each unit of a fleet of two certified in turn, every message recorded. At 1 Hz (a
    second between heartbeats: a loaded host held the fleet's thread 1.1 s), and once more
    when it held the thread a heartbeat period or more (as ``certify_sim``)."""
    for _attempt in range(2):
        with recorded(broker, base.prefix, recording), \
                Fleet(base, broker, 2, rate=RATE, seed=1) as fleet:
            rebooter = ProcessRebooter(fleet)
            runs = [certify(pytester, "--unit", str(address), "--broker", broker,
                            f"--profile={PROFILE}", "--seed", "1", plugins=(rebooter,))
                    for address in fleet.addresses]
            assert rebooter.calls == len(runs)
            if fleet.runtime.held < 1.0 / RATE:
                return fleet.addresses, runs
        print(f"the host held the fleet {fleet.runtime.held:.2f} s past a step: again")
    return fleet.addresses, runs


def test_two_units_on_one_connection_are_each_certified_and_lint_clean(
        pytester: pytest.Pytester, mosquitto: str, unit_address: UnitAddress,
        tmp_path: Path) -> None:
    from conformance.cli.lint import main as lint_main

    addresses, runs = certify_both(pytester, mosquitto, unit_address, tmp_path / "fleet.jsonl")
    for address, run in zip(addresses, runs, strict=True):
        rules = run.unit_rules()
        assert not accusations(rules, set()), (address, first_violations(
            rules, accusations(rules, set())))
        assert run.result.ret == 0, run.text
        assert run.report is not None
        levels = run.report["conclusion"]["units"][str(address)]["levels"]
        assert levels and all(lv["certified"] for lv in levels), (address, levels)
        assert rules["REBOOT-001"]["verdict"] == "pass", address
    lint_main(["--from", str(tmp_path / "fleet.jsonl"), f"--profile={PROFILE}", "--plain",
               "--format", "json", "--reports-dir", str(tmp_path / "lint")], stdout=io.StringIO())
    report = json.loads(next((tmp_path / "lint").glob("*.json")).read_text())
    for address in addresses:
        linted = report["units"][str(address)]["rules"]
        assert not accusations(linted, set()), (address, first_violations(
            linted, accusations(linted, set())))

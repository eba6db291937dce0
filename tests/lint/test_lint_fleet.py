"""Lint over the simulator's fleet (``conformance.sim.Fleet``): exactly the faulty units fail."""

from __future__ import annotations

from pathlib import Path

import pytest
from lint_helpers import failed_rules, run_lint

pytestmark = pytest.mark.mosquitto

LENIENT = "extends: default\nname: lenient-timing\nmax_gap_periods: 5\n"
"""Which units fail is the point here, not single late messages on a loaded CI machine."""


def test_lint_over_a_simulated_fleet_fails_exactly_the_faulty_units(mosquitto: str, tmp_path: Path,
                                                                    prefix: str) -> None:
    from conformance.sim import Fleet

    profile = tmp_path / "lenient.yaml"
    profile.write_text(LENIENT)
    faulty = {1: ["heartbeat-type-case"], 3: ["speed-sentinel"]}
    with Fleet(f"{prefix}/unit/air/simulation/dji0", mosquitto, 5, rate=5.0, seed=1,
               faults_by_index=faulty) as fleet:
        # --strict: SENS-003 (speed a number of m/s >= 0) is a decided rule (rules.toml)
        run = run_lint(["--broker", mosquitto, "--topic", f"{prefix}/#", "--duration", "3s",
                        "--profile", str(profile), "--strict"], tmp_path / "reports")
        names = [a.base for a in fleet.addresses]
        assert fleet.errors == 0
    assert run.code == 1, run.out
    failing = {u for u, rep in run.report["units"].items()
               if any(r["verdict"] == "fail" for r in rep["rules"].values())}
    assert failing == {names[1], names[3]}, run.out
    assert "HB-002" in failed_rules(run.report, names[1])
    assert "SENS-003" in failed_rules(run.report, names[3])
    assert run.report["unexamined"] == 0

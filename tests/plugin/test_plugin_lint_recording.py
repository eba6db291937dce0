"""A recording made during a certification lints with the unit's findings only:
the suite's own commands (its sender) and deliberate probes (unreadable payloads, unknown and
malformed commands, invalid parameters, a start-task without task-uuid) are no commander's
fault, so lint exits 0 unless the unit itself fails."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from certify_helpers import FAST, Rebooter, certify, recorded

from conformance.sim import SimUnit
from conformance.topics import UnitAddress

pytestmark = [pytest.mark.slow, pytest.mark.mosquitto]

PROBES = ("EXEC-ROBUST-001 or EXEC-ROBUST-002 or EXEC-START-002 or EXEC-START-004 or "
          "EXEC-START-005")
"""The rules whose scenarios send the suite's deliberate probes."""


def _certify_and_lint(pytester: pytest.Pytester, broker: str, unit: UnitAddress,
                      tmp_path: Path, faults: tuple[str, ...] = ()) -> tuple[int, dict]:
    recording = tmp_path / "certification.jsonl"
    with recorded(broker, unit.prefix, recording), \
            SimUnit(unit, broker, faults=faults, rate=2.0, seed=1) as sim:
        run = certify(pytester, "--unit", str(unit), "--broker", broker, f"--profile={FAST}",
                      "-k", PROBES, plugins=(Rebooter(sim),))
    assert run.report is not None, run.text
    from conformance.cli.lint import main as lint_main

    reports = tmp_path / "lint"
    code = lint_main(["--from", str(recording), "--plain", "--format", "json",
                      "--reports-dir", str(reports)], stdout=io.StringIO())
    return code, json.loads(next(reports.glob("*.json")).read_text())


def test_a_certifications_recording_lints_with_the_units_findings_only(
        pytester: pytest.Pytester, mosquitto: str, unit_address: UnitAddress,
        tmp_path: Path) -> None:
    code, report = _certify_and_lint(pytester, mosquitto, unit_address, tmp_path)
    commanders = {name: [r for r, res in row["rules"].items() if res["verdict"] == "fail"]
                  for name, row in report["units"].items() if row.get("party") == "commander"}
    assert not any(commanders.values()), commanders
    unit = report["units"][str(unit_address)]["rules"]
    assert unit["EXEC-ROBUST-002"]["verdict"] == "pass"  # the probes reached the unit's row
    failing = {name: [r for r, res in row["rules"].items() if res["verdict"] == "fail"]
               for name, row in report["units"].items()}
    assert code == 0, failing


def test_a_faulty_units_recording_still_fails_on_the_unit(
        pytester: pytest.Pytester, mosquitto: str, unit_address: UnitAddress,
        tmp_path: Path) -> None:
    code, report = _certify_and_lint(pytester, mosquitto, unit_address, tmp_path,
                                     faults=("start-no-generated-task-uuid",))
    assert code == 1
    unit = report["units"][str(unit_address)]["rules"]
    assert unit["EXEC-START-002"]["verdict"] == "fail"

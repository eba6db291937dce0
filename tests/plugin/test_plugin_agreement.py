"""A certification and the lint of its own recording agree rule by rule: every answer a
scenario provokes is judged by the same passive checks lint runs (scenarios send and observe;
the Monitor judges), so where both judged a rule (pass, warn or fail in both) they gave the
same verdict. In virtual time: the reference unit and one fault of each kind of conversation
(a late pong, a start answered outside 12.1's words, feedback after the end)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from certify_helpers import MATRIX, certify_virtual, recorded_virtual

from conformance.cli.lint import main as lint_main
from conformance.rules import CATALOGUE, Mode

pytestmark = pytest.mark.slow

JUDGED = {"pass", "warn", "fail"}


def lint_of(recording: Path, reports: Path) -> dict:
    out = io.StringIO()
    lint_main(["--from", str(recording), f"--profile={MATRIX}", "--plain", "--format", "json",
               "--reports-dir", str(reports)], stdout=out)
    return json.loads(next(reports.glob("*.json")).read_text())


@pytest.mark.parametrize("faults", [(), ("pong-late",), ("start-answered-started",),
                                    ("feedback-after-final",)], ids=lambda f: "+".join(f) or
                         "conformant")
def test_a_certification_and_the_lint_of_its_recording_agree(
        pytester: pytest.Pytester, prefix: str, tmp_path: Path, faults: tuple[str, ...]) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    recording = tmp_path / "run.jsonl"
    with recorded_virtual(recording):
        run = certify_virtual(pytester, unit, f"--profile={MATRIX}", "--seed", "1",
                              faults=faults)
    suite = run.unit_rules()
    linted = lint_of(recording, tmp_path / "lint")["units"][unit]["rules"]
    differ = {}
    for rule, result in suite.items():
        if CATALOGUE[rule].mode is Mode.ACTIVE:
            continue  # only a stimulus the suite controls shows it (a reboot it asked for)
        theirs = linted.get(rule, {}).get("verdict")
        if result["verdict"] in JUDGED and theirs in JUDGED and theirs != result["verdict"]:
            differ[rule] = (result["verdict"], theirs, result.get("reason"),
                            linted[rule].get("reason"))
    assert not differ, json.dumps(differ, indent=1)
    assert sum(r["verdict"] in JUDGED for r in linted.values()) > 30

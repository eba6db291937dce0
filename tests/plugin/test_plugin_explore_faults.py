"""The sequence-fault matrix of the exploration, in virtual time: each sequence fault that a
unit written elsewhere showed in an order of commands no scripted scenario sends is found by
the exploration within its default budget (a 2 Hz unit: ``default_budget``) with a fixed
seed, told by the rule it breaks; the conformant reference unit explored as long answers as
the model says, and the summary says which of the model's transitions the steps reached
(``explore_cover.TRANSITIONS``: what was not reached is named, never a silent green)."""

from __future__ import annotations

import json

import pytest
from certify_helpers import FAST, UNIT, certify_virtual

from conformance.scenarios.explore_cover import TRANSITIONS
from conformance.sim import FAULTS
from conformance.suite.exploration import default_budget

pytestmark = pytest.mark.slow

RATE = 2.0
BUDGET = f"--explore={default_budget(RATE):g}s"
FOUND = {
    "query-paused-finished": "EXEC-QUERY-001",
    "paused-dropped-from-list": "EXEC-START-003",
    "resend-signal-reapplied": "EXEC-RESEND-001",
    "abort-aborts-all": "EXEC-SEQ-002",
    "resend-after-end-runs-again": "EXEC-RESEND-001",
}
"""Fault -> the rule the exploration's story shows it by (FAST adopts every decision: the
condition also-aborted of EXEC-SEQ-002 fails there, it warns by default)."""


def _summary(run) -> str:  # type: ignore[no-untyped-def]
    assert run.report is not None, run.text
    return str(run.report["meta"]["explore"])


@pytest.mark.parametrize("fault", sorted(FOUND))
def test_a_sequence_fault_is_found_within_the_default_budget(pytester: pytest.Pytester,
                                                             fault: str) -> None:
    assert FAULTS[fault].sequence and FOUND[fault] in FAULTS[fault].rules
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", BUDGET, "--seed", "1",
                          "-k", "test_explore", faults=(fault,), rate=RATE)
    assert run.result.ret == 1, run.text
    (stored,) = run.reports_dir.glob("*-explore.json")
    story = json.loads(stored.read_text())
    assert FOUND[fault] in story["rules"], story["rules"]
    assert "transitions covered" in _summary(run)


def test_the_conformant_unit_explored_reaches_every_transition(
        pytester: pytest.Pytester) -> None:
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", BUDGET, "--seed", "1",
                          "-k", "test_explore", rate=RATE)
    assert run.result.ret == 0, run.text
    summary = _summary(run)
    assert f"transitions covered {len(TRANSITIONS)}/{len(TRANSITIONS)}" in summary, summary
    assert "not reached" not in summary
    assert not list(run.reports_dir.glob("*-explore.json"))

"""The sequence-fault matrix of the exploration, in virtual time: each sequence fault that a
unit written elsewhere showed in an order of commands no scripted scenario sends is found by
the exploration within its default budget (a 2 Hz unit: ``default_budget``) with a fixed
seed, told by the rule it breaks; the conformant reference unit explored as long answers as
the model says, and the summary says which of the model's transitions the steps reached
(``explore_cover.TRANSITIONS``: what was not reached is named, never a silent green). A
story found is shrunk by replays to the steps the fault needs; a unit that dies on an order
of commands ends the exploration there. (On a real broker: ``test_plugin_explore.py``.)"""

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


def test_a_task_dropped_silently_is_shrunk_to_the_steps_that_drop_it(
        pytester: pytest.Pytester) -> None:
    """preempt-paused-silently: shrinking by replay leaves out what is not needed and ends
    at start, $pause, start another of its kind, then what shows the paused task gone: a
    query (EXEC-QUERY-001: the unit forgot it), or, where the paused task was held while
    tasks-executing listed it paused (the transition 'held-paused'), the second start itself
    or the teardown's $abort of the paused task right after it (EXEC-START-003: listed
    paused, it left the list with no final status). A paused task may be left out of
    tasks-executing (5.3 does not say), so its leaving the list is no end unless the unit
    listed it while paused (docs/MODEL.md). A budget long enough to finish shrinking (the
    replays cost virtual time only)."""
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", "--explore=150s", "--seed", "2",
                          "-k", "test_explore", faults=("preempt-paused-silently",), rate=RATE)
    assert run.result.ret == 1, run.text
    (stored,) = run.reports_dir.glob("*-explore.json")
    story = json.loads(stored.read_text())
    actions = [s["action"] for s in story["steps"] if not s["action"].get("teardown")]
    shapes = {"EXEC-QUERY-001": [("start", None), ("signal", "$pause"), ("start", None),
                                 ("query", None)],
              "EXEC-START-003": [("start", None), ("signal", "$pause"), ("wait", None),
                                 ("start", None)]}
    (rule,) = story["rules"]
    assert [(a["do"], a.get("signal")) for a in actions] == shapes[rule], story
    starts = [a for a in actions if a["do"] == "start"]
    assert starts[0]["task"] == starts[1]["task"]
    # The step that finds it gone: the last of the story, or the teardown's first right after.
    assert story["failing_step"] in (len(actions), len(actions) + 1)
    if story["failing_step"] > len(actions):
        assert story["steps"][len(actions)]["action"] == {
            "do": "signal", "signal": "$abort", "slot": starts[0]["slot"], "teardown": True}
    assert "story shrunk" in _summary(run) and "replays to shrink it" in _summary(run)


def test_a_unit_that_dies_on_an_order_of_commands_ends_the_exploration_with_its_steps(
        pytester: pytest.Pytester) -> None:
    """dies-on-missing-task-uuid: exploration sends a start-task without task-uuid and the
    unit stops heartbeating. No answer can come: the exploration ends there (not 'answered as
    the model says', not waiting out every step and teardown), telling the steps that led
    there; HB-012 fails on its own, naming the command."""
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", "--explore=40s", "--seed", "3",
                          "-k", "test_explore or HB-012", faults=("dies-on-missing-task-uuid",),
                          rate=RATE)
    assert run.result.ret == 1, run.text
    assert "exploration: the unit died during step" in run.text, run.text
    assert "no task-uuid (the unit makes one)" in run.text
    assert "answered as the model says" not in run.text
    assert "The above exception" not in run.text
    assert run.outcomes.get("HB-012") == "failed"
    assert "test_explore.py::test_explore - Failed: exploration: the unit died" in run.text
    (stored,) = run.reports_dir.glob("*-explore.json")
    assert json.loads(stored.read_text())["steps"][-1]["action"]["task_uuid"] is False

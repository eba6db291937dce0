"""The typed steps of an exploration (``conformance/scenarios/explore_action.py``): each kind's
JSON form is the one a stored story has always held, and reading it back gives the same step."""

from __future__ import annotations

import pytest

from conformance.scenarios.explore_action import (
    Action,
    Ping,
    Query,
    Resend,
    Signal,
    Start,
    Wait,
    from_json,
    is_teardown,
    slot_of,
    to_json,
)

STORED = [
    (Start("move-to", slot=0), {"do": "start", "task": "move-to", "task_uuid": True, "slot": 0}),
    (Start("move-to", False, 1), {"do": "start", "task": "move-to", "task_uuid": False,
                                  "slot": 1}),
    (Signal("$pause", 0), {"do": "signal", "signal": "$pause", "slot": 0}),
    (Signal("$enough", None), {"do": "signal", "signal": "$enough", "slot": None}),
    (Signal("$abort", 2, teardown=True), {"do": "signal", "signal": "$abort", "slot": 2,
                                          "teardown": True}),
    (Query(1), {"do": "query", "slot": 1}),
    (Resend(3), {"do": "resend", "step": 3}),
    (Ping(), {"do": "ping"}),
    (Wait(2), {"do": "wait", "periods": 2}),
]


@pytest.mark.parametrize(("action", "stored"), STORED, ids=[s["do"] for _, s in STORED])
def test_a_step_is_stored_as_it_always_was_and_read_back_the_same(
        action: Action, stored: dict[str, object]) -> None:
    assert to_json(action) == stored
    assert list(to_json(action)) == list(stored)  # the key order of the stored stories
    assert from_json(stored) == action


def test_a_stored_step_may_leave_out_what_has_a_default_and_hold_what_its_kind_ignores() -> None:
    assert from_json({"do": "start", "task": "move-to"}) == Start("move-to", True, None)
    assert to_json(Start("move-to")) == {"do": "start", "task": "move-to", "task_uuid": True}
    assert from_json({"do": "query", "task": "move-to"}) == Query(None)
    assert from_json({"do": "wait"}) == Wait(1)


def test_slots_and_the_teardown() -> None:
    assert [slot_of(a) for a, _ in STORED] == [0, 1, 0, None, 2, 1, None, None, None]
    assert [is_teardown(a) for a, _ in STORED] == [False] * 4 + [True] + [False] * 4

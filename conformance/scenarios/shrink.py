"""Shrinking a story by replaying it ('a failure is a minimal, replayable story').

Hypothesis shrinks the choices it drew, and after a removed step the same choice names another
command (the options depend on the unit's state): against a real unit that rarely gets a story
shorter. A story's steps are data that mean the same thing when run again (tasks by slot,
resends by step: ``explore_steps``), so a step can be left out and the rest replayed as it was:
greedy delta debugging (after Zeller's ddmin): what follows the disagreement at once, then each
task it is not about, then one step at a time, the least likely to matter first (``trials``).
A shorter story is kept when the unit still disagrees with the model on it, about any rule:
with a single bug that is the same bug, shown by its own rule once the steps that showed it
through another are gone (a dropped task queried 'unknown' is EXEC-QUERY-001; without the
query the task still vanishes, EXEC-START-003).

Every replay is a real example against the unit, with its teardown: one is begun only while
the budget has room for it (as long as the longest replay so far), so shrinking never runs past
the budget, and the shortest story so far is what is reported when it ends.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import Any

from conformance.scenarios.explore_action import Action, Ping, Query, Resend, Signal, Start, Wait

LEAST_TELLING = (Wait, Ping, Query, Resend, Signal, Start)
"""The order in which steps are tried out: those that change no task's state first."""


def without(actions: list[Action], drop: Iterable[int]) -> list[Action]:
    """``actions`` less the steps ``drop`` and what needs them: a signal or query to a task
    whose start is gone, a resend of a command that is gone. The rest are renumbered (slots:
    the n-th start of the story; resends: the index of the step resent)."""
    dropped = set(drop)
    gone_slots: set[int] = set()
    slot_of: dict[int, int] = {}  # old slot -> new slot
    step_of: dict[int, int] = {}  # old step -> new step
    kept: list[Action] = []
    slots = 0
    for i, a in enumerate(actions):
        if isinstance(a, Start):
            old = slots
            slots += 1
            if i in dropped:
                gone_slots.add(old)
                continue
            slot_of[old] = len(slot_of)
            a = replace(a, slot=slot_of[old])
        elif i in dropped:
            continue
        elif isinstance(a, (Signal, Query)) and a.slot is not None:
            if a.slot in gone_slots:
                continue
            if a.slot in slot_of:
                a = replace(a, slot=slot_of[a.slot])
        elif isinstance(a, Resend):
            if a.step not in step_of:
                continue
            a = replace(a, step=step_of[a.step])
        step_of[i] = len(kept)
        kept.append(a)
    return kept


def slots_of(actions: list[Action]) -> dict[int, int]:
    """Step index of each slot's start-task."""
    starts = [i for i, a in enumerate(actions) if isinstance(a, Start)]
    return dict(enumerate(starts))


def trials(actions: list[Action], failing: int, involved: set[int]) -> list[list[int]]:
    """The steps to try leaving out, in order: everything after the step where the unit
    first disagreed; each task the disagreement is not about (``involved``: slots), with
    what was sent to it; then one step at a time, those after the disagreement and the least
    telling kinds first, the latest first within a kind; the failing step last of all."""
    out: list[list[int]] = []
    if failing + 1 < len(actions):
        out.append(list(range(failing + 1, len(actions))))
    out += [[i] for slot, i in slots_of(actions).items() if slot not in involved]

    def key(i: int) -> tuple[bool, bool, int, int]:
        return (i == failing, i < failing, LEAST_TELLING.index(type(actions[i])), -i)
    return out + [[i] for i in sorted(range(len(actions)), key=key)]


Attempt = Callable[[list[Action]], "tuple[int, set[int], Any] | None"]


def shrink(actions: list[Action], failing: int, involved: set[int], attempt: Attempt,
           left: Callable[[], float], expected: float = 0.0,
           clock: Callable[[], float] = time.monotonic) -> tuple[list[Action], Any, bool]:
    """The shortest story found by leaving steps out of ``actions`` (disagreeing first at
    ``failing``, about the tasks of the slots ``involved``): ``attempt`` replays a candidate
    and gives the same three of it and its story, or None when the unit now answers as the
    model says. Returns the actions, their story (None when no shorter one was found) and
    whether shrinking finished (no single step can be left out) before the budget (``left``
    seconds) ran out. A replay begins only when the budget has room for the longest one so
    far (``expected`` before the first: the example that found the story), timed by ``clock``
    (the run's: virtual in the test suite's matrices)."""
    best, story = actions, None
    longest: float | None = None
    progress = True
    while progress:
        progress = False
        for drop in trials(best, failing, involved):
            candidate = without(best, drop)
            if not candidate or len(candidate) >= len(best):
                continue
            if left() <= (expected if longest is None else longest):
                return best, story, False
            began = clock()
            result = attempt(candidate)
            longest = max(longest or 0.0, clock() - began)
            if result is not None:
                failing, involved, story = result
                best, progress = candidate, True
                break  # the steps are renumbered: try again from the start
    return best, story, True

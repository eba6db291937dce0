"""Shrinking an exploration's story by replay (``conformance/scenarios/shrink.py``): leaving a
step out keeps what the others mean (tasks by slot, resends by step), and the greedy pass ends
at a story no single step of which can go, or when the budget has no room for a replay.

The unit here is a function of the steps (no broker): the real replays are exercised by
``test_plugin_explore.py`` and measured by ``bench/bench_explore.py``."""

from __future__ import annotations

from itertools import chain, repeat

from conformance.scenarios.explore_action import Action, Ping, Query, Resend, Signal, Start, Wait
from conformance.scenarios.shrink import shrink, trials, without


def start(slot: int, task: str = "look-at-bearing") -> Start:
    return Start(task, slot=slot)


def signal(name: str, slot: int | None) -> Signal:
    return Signal(name, slot)


STORY: list[Action] = [start(0), Ping(), start(1, "image-object-detection"),
                       signal("$pause", 0), Query(1), Wait(2), start(2), Resend(3),
                       signal("$abort", 1)]
"""Nine steps; the bug (a paused task dropped by a new one of its kind) needs steps 0, 3, 6."""


def drops_paused(actions: list[Action]) -> int | None:
    """The step where the faulty unit disagrees: a start of the kind of a task paused before
    it (what ``preempt-paused-silently`` does), or None."""
    paused: set[str] = set()
    slots: list[str] = []
    for i, a in enumerate(actions):
        if isinstance(a, Start):
            if a.task in paused:
                return i
            slots.append(a.task)
        elif isinstance(a, Signal) and a.signal == "$pause" and a.slot is not None:
            paused.add(slots[a.slot])
    return None


def test_leaving_out_a_start_takes_what_was_sent_to_its_task_and_renumbers_the_rest() -> None:
    shorter = without(STORY, [2])  # the start of T2 (slot 1): its query and abort go too
    assert shorter == [start(0), Ping(), signal("$pause", 0), Wait(2), start(1), Resend(2)]
    # a resend of a step left out goes with it; the later steps keep their meaning
    assert without(STORY, [3])[-2:] == [start(2), signal("$abort", 1)]
    # the first task gone: its pause, and the resend of that pause, go with it
    assert without(STORY, [0]) == [Ping(), start(0, "image-object-detection"), Query(0),
                                   Wait(2), start(1), signal("$abort", 0)]


def test_trials_put_what_follows_the_disagreement_and_other_tasks_first() -> None:
    order = trials(STORY, failing=6, involved={0, 2})
    assert order[0] == [7, 8]  # everything after the failing step, at once
    assert order[1] == [2]  # the task the disagreement is not about
    singles = [d[0] for d in order[2:]]
    assert singles[-1] == 6  # the failing step last
    assert singles.index(5) < singles.index(4) < singles.index(3) < singles.index(0)


def test_shrinks_to_the_steps_the_bug_needs_and_says_it_finished() -> None:
    replays: list[int] = []

    def attempt(actions: list[Action]) -> tuple[int, set[int], str] | None:
        replays.append(len(actions))
        failing = drops_paused(actions)
        return None if failing is None else (failing, {0}, f"{len(actions)} steps")

    assert drops_paused(STORY) == 6
    best, story, done = shrink(STORY, 6, {0, 2}, attempt, left=lambda: 60.0)
    assert best == [start(0), signal("$pause", 0), start(1)] and story == "3 steps"
    assert done
    assert len(replays) <= 12, replays


def test_shrinking_stops_when_the_budget_has_no_room_for_a_replay() -> None:
    clock = chain([30.0, 30.0], repeat(0.0))  # room for two replays, then none

    def attempt(actions: list[Action]) -> tuple[int, set[int], str] | None:
        failing = drops_paused(actions)
        return None if failing is None else (failing, {0}, "shorter")

    best, story, done = shrink(STORY, 6, {0, 2}, attempt, left=lambda: next(clock),
                               expected=5.0)
    assert not done and story == "shorter" and 3 < len(best) < len(STORY)


def test_a_story_that_no_longer_fails_without_any_step_stays_as_it_is() -> None:
    best, story, done = shrink(STORY, 6, {0, 2}, lambda actions: None, left=lambda: 60.0)
    assert best == STORY and story is None and done

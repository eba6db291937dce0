"""The model's transitions an exploration sets out to reach, which of them it reached, and the
commands that reach (or come closer to) one not reached yet.

Each transition is an order of commands that units get wrong (docs/MODEL.md 'The sequence
faults of the reference unit'): a paused task queried, held paused while tasks-executing is
followed, a signal resent after its effect was undone, one of two live tasks signalled, a
start-task resent after its task ended, ... ``reached`` says which transitions a step takes
in the model's view before it is sent (the teardown's aborts count: they are sent and
judged); ``toward`` offers, for each transition not reached yet in the run, the command that
takes it now or the step that leads there, and the exploration's choices favour those
(``explore.task_commands``): hypothesis stays the engine, it only finds them more often among
its options. The summary says what was not reached: never a green over an order not sent.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

from conformance.scenarios.explore_action import Action, Query, Resend, Signal, Start, Wait

if TYPE_CHECKING:
    from conformance.scenarios.explore_steps import Explorer

TRANSITIONS: dict[str, str] = {
    "pause": "a running task paused",
    "continue": "a paused task continued",
    "abort-paused": "a paused task aborted",
    "enough": "a task ended by $enough",
    "query-paused": "a paused task queried",
    "query-ended": "an ended task queried",
    "signal-ended": "a signal to an ended task",
    "held-paused": "a paused task held while tasks-executing is followed",
    "start-while-paused": "a task started while another is paused",
    "pause-one-of-two": "one of two live tasks paused",
    "abort-one-of-two": "one of two live tasks aborted",
    "signal-resent": "a signal resent after its effect was undone",
    "resend-after-end": "a start-task resent after its task ended",
}
"""Name -> what it is, in the order the summary tells them."""

EFFECT = {"$pause": "paused", "$continue": "running"}
"""The state a signal whose resend can be told to be applied again leads to."""


def hold(explorer: Explorer) -> float:
    """Seconds a paused task is held for ``held-paused``: listed once while paused, left out
    at the next direct_execution_info, and the response deadline of its final status."""
    ctx = explorer.ctx
    return ctx.timing.periods(2, ctx.rate_of("direct_execution_info"))


def _since_start(explorer: Explorer) -> float:
    """Seconds since the example's latest start-task (an 'aborted' soon after one is
    pre-emption, not another task's signal: EXEC-SEQ-002's decision)."""
    return explorer.now() - explorer.last_start


def reached(explorer: Explorer, action: Action) -> set[str]:
    """The transitions ``action`` takes now, in the model's view (and a task held paused)."""
    states = explorer.states()
    now = explorer.now()
    found = {"held-paused" for s, state in zip(explorer.slots, states, strict=True)
             if state == "paused" and now - s.since >= hold(explorer)}
    if isinstance(action, Start) and "paused" in states:
        found.add("start-while-paused")
    slot = getattr(action, "slot", None)
    state = states[slot] if isinstance(slot, int) and slot < len(states) else ""
    if action.do == "query" and state in ("paused", "ended"):
        found.add(f"query-{state}")
    if isinstance(action, Signal) and state:
        found |= _signalled(explorer, action.signal, state, states)
    if isinstance(action, Resend) and action.step < len(explorer.steps):
        first = explorer.steps[action.step].action
        if isinstance(first, Start) and isinstance(first.slot, int) \
                and first.slot < len(states) and states[first.slot] == "ended":
            found.add("resend-after-end")
        if isinstance(first, Signal) and isinstance(first.slot, int) \
                and first.slot < len(states) and _undone(first.signal, states[first.slot]):
            found.add("signal-resent")
    return found


def _signalled(explorer: Explorer, signal: str, state: str, states: list[str]) -> set[str]:
    found: set[str] = set()
    if state == "ended":
        return {"signal-ended"}
    if signal == "$pause" and state == "running":
        found.add("pause")
    if signal == "$continue" and state == "paused":
        found.add("continue")
    if signal == "$abort" and state == "paused":
        found.add("abort-paused")
    if signal == "$enough" and state in ("running", "paused"):
        found.add("enough")
    live = sum(s in ("running", "paused") for s in states)
    if live >= 2 and state in ("running", "paused") and signal in ("$pause", "$abort") \
            and _since_start(explorer) >= explorer.ctx.timing.response:
        found.add(f"{signal[1:]}-one-of-two")
    return found


def _undone(signal: str, state: str) -> bool:
    """Whether a task in ``state`` has left the state ``signal`` led it to (a $pause's task
    running again, a $continue's paused again): its resend would show a second effect."""
    return signal in EFFECT and state in ("running", "paused") and state != EFFECT[signal]


def toward(explorer: Explorer, missing: Iterable[str]) -> list[Action]:
    """For each transition in ``missing`` (in ``TRANSITIONS``' order), a command that takes
    it now or comes closer to it; none where the example cannot (no such task yet)."""
    states = explorer.states()
    live = [i for i, s in enumerate(states) if s in ("running", "paused")]
    paused = [i for i, s in enumerate(states) if s == "paused"]
    running = [i for i, s in enumerate(states) if s == "running"]
    ended = [i for i, s in enumerate(states) if s == "ended"]
    out: list[Action] = []
    for name in missing:
        out += _toward(explorer, name, states, live, paused, running, ended)
    return out


def _toward(explorer: Explorer, name: str, states: list[str], live: list[int],
            paused: list[int], running: list[int], ended: list[int]) -> list[Action]:
    simple: dict[str, list[Action]] = {
        "pause": [Signal("$pause", i) for i in running[:1]],
        "continue": [Signal("$continue", i) for i in paused[:1]],
        "abort-paused": [Signal("$abort", i) for i in paused[:1]]
        or [Signal("$pause", i) for i in running[:1]],
        "enough": [Signal("$enough", i) for i in live[:1]],
        "query-paused": [Query(i) for i in paused[:1]]
        or [Signal("$pause", i) for i in running[:1]],
        "query-ended": [Query(i) for i in ended[:1]] or [Signal("$enough", i) for i in live[:1]],
        "signal-ended": [Signal("$pause", i) for i in ended[:1]],
        "held-paused": [_wait(explorer)] if paused
        else [Signal("$pause", i) for i in running[:1]],
        "start-while-paused": [Start(explorer.slots[i].name, slot=len(explorer.slots))
                               for i in paused[:1]] if len(explorer.slots) < 3
        else [],
    }
    if name in simple:
        return simple[name]
    if name in ("pause-one-of-two", "abort-one-of-two"):
        if len(live) < 2:
            return []
        if _since_start(explorer) < explorer.ctx.timing.response:
            return [_wait(explorer, explorer.ctx.timing.response - _since_start(explorer))]
        return [Signal("$" + name.split("-")[0], live[-1])]
    if name == "resend-after-end":
        ends = [i for i, step in enumerate(explorer.steps) if i in explorer.commands
                and isinstance(step.action, Start) and step.action.slot in ended]
        return [Resend(i) for i in ends[-1:]] or [
            Signal("$enough", i) for i in live[:1]
            if any(isinstance(s.action, Start) and s.action.slot == i for s in explorer.steps)]
    if name == "signal-resent":
        return _toward_resent(explorer, states)
    return []


def _toward_resent(explorer: Explorer, states: list[str]) -> list[Action]:
    """A resend of a $pause (or $continue) whose effect its task has since left; else the
    $continue (or $pause) that leaves it; else a $pause to a running task."""
    signals = [(i, a) for i, step in enumerate(explorer.steps) for a in [step.action]
               if i in explorer.commands and isinstance(a, Signal) and a.signal in EFFECT
               and not a.teardown and isinstance(a.slot, int) and a.slot < len(states)]
    for i, a in reversed(signals):
        if _undone(a.signal, states[a.slot]):  # type: ignore[index]
            return [Resend(i)]
    for _, a in reversed(signals):
        if states[a.slot] == EFFECT[a.signal]:  # type: ignore[index]
            return [Signal("$continue" if a.signal == "$pause" else "$pause", a.slot)]
    pause: list[Action] = [Signal("$pause", i) for i, s in enumerate(states) if s == "running"]
    return pause[:1]


def _wait(explorer: Explorer, seconds: float | None = None) -> Wait:
    """Waiting ``seconds`` (``hold`` by default) in heartbeats, one more for the judging."""
    rate = explorer.ctx.rate_of("heartbeat") or 1.0
    return Wait(min(MAX_WAIT, 1 + math.ceil((hold(explorer) if seconds is None
                                             else seconds) * rate)))


MAX_WAIT = 10
"""Heartbeats a ``Wait`` step waits at most (``Explorer``)."""


def coverage(covered: Iterable[str]) -> str:
    """``transitions covered 11/13; not reached: ...``: what the exploration reached of
    ``TRANSITIONS``, and by name what it did not."""
    seen = set(covered)
    missing = [words for name, words in TRANSITIONS.items() if name not in seen]
    head = f"transitions covered {len(TRANSITIONS) - len(missing)}/{len(TRANSITIONS)}"
    return head + (f"; not reached: {', '.join(missing)}" if missing else "")

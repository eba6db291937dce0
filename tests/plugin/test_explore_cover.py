"""The exploration's transitions (``conformance/scenarios/explore_cover.py``): which a step
takes in the model's view, which command comes closer to one not reached yet, and the
coverage the summary says (what was not reached is named)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from types import SimpleNamespace

from conformance.scenarios.explore_action import Action, Query, Resend, Signal, Start, Wait
from conformance.scenarios.explore_cover import TRANSITIONS, coverage, reached, toward

RESPONSE = 1.5


@dataclass
class Slot:
    name: str
    state: str
    since: float = 0.0


@dataclass
class FakeExplorer:
    """What explore_cover reads of an ``Explorer``: slots and their states, the steps sent
    (and their commands), the clock, the timing."""

    slots: list[Slot] = field(default_factory=list)
    steps: list[SimpleNamespace] = field(default_factory=list)
    commands: dict[int, object] = field(default_factory=dict)
    covered: Counter[str] = field(default_factory=Counter)
    clock: float = 100.0
    last_start: float = 0.0
    ctx: SimpleNamespace = field(default_factory=lambda: SimpleNamespace(
        timing=SimpleNamespace(response=RESPONSE,
                               periods=lambda n, rate: n / (rate or 1.0) + RESPONSE),
        rate_of=lambda kind: 2.0))

    def states(self) -> list[str]:
        return [s.state for s in self.slots]

    def now(self) -> float:
        return self.clock

    def sent(self, action: Action) -> None:
        self.commands[len(self.steps)] = object()
        self.steps.append(SimpleNamespace(action=action))


def test_the_summary_names_what_was_not_reached() -> None:
    assert coverage(TRANSITIONS) == f"transitions covered {len(TRANSITIONS)}/{len(TRANSITIONS)}"
    told = coverage(set(TRANSITIONS) - {"signal-resent", "resend-after-end"})
    assert told.startswith(f"transitions covered {len(TRANSITIONS) - 2}/{len(TRANSITIONS)}; ")
    assert told.endswith("not reached: a signal resent after its effect was undone, "
                         "a start-task resent after its task ended")
    assert "not reached: " + ", ".join(TRANSITIONS.values()) in coverage(())


def test_a_step_takes_the_transitions_of_the_state_it_is_sent_in() -> None:
    e = FakeExplorer([Slot("look-at-bearing", "running")])
    assert reached(e, Signal("$pause", 0)) == {"pause"}
    e.slots[0].state, e.slots[0].since = "paused", e.clock  # paused just now
    assert reached(e, Query(0)) == {"query-paused"}
    assert reached(e, Signal("$abort", 0)) == {"abort-paused"}
    assert reached(e, Start("look-at-bearing", slot=1)) == {
        "start-while-paused"}
    e.slots[0].since = e.clock - 10  # held paused long enough: tasks-executing followed
    assert "held-paused" in reached(e, Query(0))


def test_one_of_two_live_tasks_signalled_counts_only_a_response_timeout_after_a_start() -> None:
    e = FakeExplorer([Slot("look-at-bearing", "running"), Slot("move-to", "running")])
    e.last_start = e.clock - RESPONSE / 2  # an 'aborted' now could be pre-emption
    assert reached(e, Signal("$abort", 1)) == set()
    assert toward(e, ["abort-one-of-two"]) == [Wait(3)]
    e.last_start = e.clock - RESPONSE
    assert reached(e, Signal("$abort", 1)) == {"abort-one-of-two"}
    assert toward(e, ["pause-one-of-two"]) == [Signal("$pause", 1)]


def test_toward_a_resent_signal_pauses_continues_then_resends_the_pause() -> None:
    e = FakeExplorer([Slot("look-at-bearing", "running")])
    e.sent(Start("look-at-bearing", slot=0))
    assert toward(e, ["signal-resent"]) == [Signal("$pause", 0)]
    e.sent(Signal("$pause", 0))
    e.slots[0].state = "paused"
    assert toward(e, ["signal-resent"]) == [Signal("$continue", 0)]
    e.sent(Signal("$continue", 0))
    e.slots[0].state = "running"
    assert toward(e, ["signal-resent"]) == [Resend(1)]
    assert reached(e, Resend(1)) == {"signal-resent"}
    assert reached(e, Resend(2)) == set()  # $continue: not undone


def test_toward_a_resend_after_the_end_ends_the_task_then_resends_its_start() -> None:
    e = FakeExplorer([Slot("look-at-bearing", "running")])
    e.sent(Start("look-at-bearing", slot=0))
    assert toward(e, ["resend-after-end"]) == [Signal("$enough", 0)]
    e.slots[0].state = "ended"
    assert toward(e, ["resend-after-end"]) == [Resend(0)]
    assert reached(e, Resend(0)) == {"resend-after-end"}

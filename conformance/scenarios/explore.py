"""Exploration: a hypothesis state machine sends spec-12 commands in orders no script has,
and the Monitor judges every answer (docs/MODEL.md).

Its rules are the commands: start-task (with or without task-uuid, of the tasks the unit lists
and the suite may start, parameters drawn from the task's schema inside the safe radius),
every built-in signal to any task (running, paused, ended, or never seen), query-status of any
task, a resend of any earlier command, ping, and waiting. ``Explorer`` (explore_steps.py) runs
each step and judges it; a disagreement is told as a ``Story`` (story.py). The choice of a
command about the tasks favours those toward the model's transitions the run has not reached
yet (explore_cover.py); the summary says which were reached, and names the others.

Against a slow, real system
(docs/FIELD-NOTES.md 'Stateful exploration against a slow, real system'): no
per-step deadline, a bounded step count, health checks off, and the wall-clock budget is ours:
past it no example starts and no step runs (``OutOfBudget`` is not an ``Exception``, so
hypothesis lets it through). The first disagreement ends the generation (``Found``); it is
printed at once, then shrunk by replaying it with steps left out (``shrink.py``) in what is
left of the budget, and the shortest story so far is the one reported, shrunk or not.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

from conformance.protocol import BUILTIN_SIGNALS
from conformance.scenarios.context import RUNS_UNTIL_ENOUGH
from conformance.scenarios.explore_action import Action, Ping, Query, Resend, Signal, Start, Wait
from conformance.scenarios.explore_cover import TRANSITIONS, toward
from conformance.scenarios.explore_steps import UNCHANGED, Disagreement, Explorer, Step
from conformance.scenarios.shrink import shrink
from conformance.scenarios.story import Story, describe

STEPS = 10
"""Steps per example at most (hypothesis' stateful_step_count)."""
PICK = 63
"""Range of every draw that picks among what the unit's state offers."""
TASKS = 3
"""Start-tasks per example at most."""
EXAMPLES = 10_000
"""Examples at most: the budget ends the exploration long before."""
# Generation favours, and shrinking goes towards, the first: the signal that changes most.
SIGNALS = ("$pause", "$abort", "$continue", "$enough")


class OutOfBudget(BaseException):
    """The exploration's time is up (a BaseException: hypothesis must not take it for a
    failure of the unit and shrink it)."""


class Found(BaseException):
    """The unit disagreed with the model: hypothesis stops at once (it would shrink by its
    own choices, and replay the example to report it); the story is shrunk by replay
    (``shrink.py``)."""


class Stopped(BaseException):
    """Something that is not the unit's disagreement ended a step (the run's --max-duration,
    --dry-run, a broken connection): it ends the exploration, carried out of hypothesis."""

    def __init__(self, cause: BaseException) -> None:
        super().__init__(str(cause))
        self.cause = cause


@dataclass
class Outcome:
    """What an exploration did and found."""

    examples: int = 0
    steps: int = 0
    elapsed: float = 0.0
    story: Story | None = None
    ended: str = ""
    """Why it ended: 'budget', 'shrunk', 'exhausted' (hypothesis had nothing more to try)."""
    last_error: str = ""
    """What hypothesis ended with (its own complaint, if any)."""
    replays: int = 0
    """Replays of shorter stories while shrinking."""
    covered: frozenset[str] = frozenset()
    """The model's transitions its steps took (``explore_cover.TRANSITIONS``)."""


class Search:
    """One exploration: the budget, the counters, and the shortest story found so far."""

    def __init__(self, explorer: Explorer, budget: float, seed: int,
                 on_story: Callable[[Story], None] = lambda story: None,
                 guided: bool = True) -> None:
        self.explorer = explorer
        self.guided = guided
        """Whether each choice offers the most telling options first (the model's view),
        or in a random order (--explore-order random: what the guidance adds, measured)."""
        self.budget = budget
        self.seed = seed
        self.on_story = on_story
        self.clock = explorer.ctx.traffic.clock
        """The budget is spent in the run's time (virtual in the test suite's matrices)."""
        self.started = self.clock.monotonic()
        self.outcome = Outcome()
        self.spent = False
        self.failed = False
        """This example disagreed: its teardown ends the exploration (``Found``)."""
        self.example_began = self.started
        self.on_step: Callable[[str], None] = lambda doing: None
        """Told what the exploration does next (a step, a replay while shrinking): the
        terminal shows it with the counts (``suite/exploration.py``)."""

    def left(self) -> float:
        return self.budget - (self.clock.monotonic() - self.started)

    def check(self) -> None:
        if self.spent or self.left() <= 0:
            self.spent = True
            raise OutOfBudget()

    def begin_example(self) -> None:
        self.check()
        self.outcome.examples += 1
        self.example_began = self.clock.monotonic()
        self.explorer.begin()

    def run_step(self, action: Action) -> None:
        self.check()
        self.on_step(describe(action))
        try:
            self.explorer.do(action)
        except Disagreement:
            self.failed = True
            raise Found() from None
        except Exception as e:  # not the unit's disagreement: end the exploration with it
            raise Stopped(e) from e
        finally:
            self.outcome.steps = self.explorer.total_steps
            self.outcome.covered = frozenset(self.explorer.covered)

    def end_example(self) -> None:
        """The example's teardown (every task aborted, what the unit owes awaited): what it
        finds belongs to the story too; a disagreement ends the exploration here."""
        try:
            self.explorer.end()
        except Disagreement:
            self.failed = True
        except Exception as e:
            raise Stopped(e) from e
        finally:
            self.outcome.steps = self.explorer.total_steps
            self.outcome.covered = frozenset(self.explorer.covered)
        if self.failed:
            raise Found()

    def run(self) -> Outcome:
        """Explore until a disagreement or the budget's end; shrink the story in what is
        left of the budget."""
        from hypothesis import HealthCheck, Phase, Verbosity, settings
        from hypothesis import seed as hseed
        from hypothesis.stateful import run_state_machine_as_test

        machine = hseed(self.seed)(machine_for(self))
        how = settings(max_examples=EXAMPLES, stateful_step_count=STEPS, deadline=None,
                       database=None, derandomize=False, phases=[Phase.generate],
                       suppress_health_check=list(HealthCheck), verbosity=Verbosity.quiet,
                       report_multiple_bugs=False, print_blob=False)
        try:
            run_state_machine_as_test(machine, settings=how)
            self.outcome.ended = "exhausted"
        except Found:
            self._shrink()
        except (Stopped, KeyboardInterrupt):
            raise
        except BaseException as e:
            if not self.spent:
                raise
            # Out of budget (hypothesis may complain on its way out that the example
            # stopped early).
            self.outcome.ended = "budget"
            if not isinstance(e, OutOfBudget):
                self.outcome.last_error = f"{type(e).__name__}: {str(e)[:200]}"
        self.outcome.elapsed = self.clock.monotonic() - self.started
        return self.outcome

    def _shrink(self) -> None:
        """Tell the story found at once, then leave out steps while the unit still
        disagrees (``shrink.py``), within the budget."""
        story = Story.of(self.explorer.steps, self.seed)
        story.found_after = self.clock.monotonic() - self.started
        story.found_steps = self.explorer.total_steps
        story.first_length = story.length
        self.outcome.story = story
        self.on_story(story)

        def attempt(actions: list[Action]) -> tuple[int, set[int], Story] | None:
            self.outcome.replays += 1
            self.on_step(f"shrinking the story: replay {self.outcome.replays}, "
                         f"{len(actions)} steps")
            found = run_example(self.explorer, actions, self.seed)
            self.outcome.steps = self.explorer.total_steps
            return None if found is None else (found.failing, self.explorer.involved(), found)

        _, shorter, done = shrink(story.actions(), story.failing, self.explorer.involved(),
                                  attempt, self.left, clock=self.clock.monotonic,
                                  expected=self.clock.monotonic() - self.example_began)
        if shorter is not None:
            shorter.found_after, shorter.found_steps = story.found_after, story.found_steps
            shorter.first_length = story.first_length
            self.outcome.story = story = shorter
        story.shrunk = done
        self.outcome.ended = "shrunk" if done else "budget"


def machine_for(search: Search) -> type:
    """The state machine of one exploration: its rules are the commands of 12.1."""
    from hypothesis import strategies as st
    from hypothesis.stateful import RuleBasedStateMachine, precondition, rule

    explorer = search.explorer
    tasks = explorer.tasks or ["-"]
    lasting = [t for t in tasks if t in RUNS_UNTIL_ENOUGH] or tasks

    def pick(data: Any, label: str, options: list[Any]) -> Any:
        return _pick(data, label, options, search.guided)

    # Hypothesis draws rules by their place in a list sorted by number of arguments (all have
    # one), then name, and early examples favour the first places: the names put the
    # commands that change a task's state first, ping and waiting last.
    class Exploration(RuleBasedStateMachine):
        def __init__(self) -> None:
            super().__init__()
            search.begin_example()

        # Two starts an example (a third while a task is paused: ``task_commands``): the
        # steps go to what is done with the tasks.
        @precondition(lambda self: bool(explorer.tasks) and len(explorer.slots) < TASKS - 1)
        @rule(data=st.data())
        def a_start_task(self, data: Any) -> None:
            task = pick(data, "task", start_order(explorer, tasks, lasting))
            task_uuid = not data.draw(st.booleans(), label="without task-uuid")
            search.run_step(Start(task, task_uuid, slot=len(explorer.slots)))

        @precondition(lambda self: bool(explorer.slots))
        @rule(data=st.data())
        def b_task_command(self, data: Any) -> None:
            search.run_step(pick(data, "command", task_commands(
                explorer, alternate=search.outcome.examples % 2 == 0, bias=search.guided)))

        @rule(data=st.data())
        def c_query_status(self, data: Any) -> None:
            search.run_step(Query(pick(data, "task", query_order(explorer))))

        @precondition(lambda self: bool(explorer.commands))
        @rule(data=st.data())
        def d_resend(self, data: Any) -> None:
            step = pick(data, "command", resend_order(explorer))
            search.run_step(Resend(step))

        @rule(data=st.data())
        def e_ping(self, data: Any) -> None:
            search.run_step(Ping())

        @rule(periods=st.integers(1, 3))
        def f_wait(self, periods: int) -> None:
            search.run_step(Wait(periods))

        def teardown(self) -> None:
            search.end_example()

    assert set(SIGNALS) == set(BUILTIN_SIGNALS)
    return Exploration


def _pick(data: Any, label: str, options: list[Any], guided: bool) -> Any:
    """One of ``options``, ordered by the model's view of the tasks (the most telling first:
    early examples and shrinking favour it; shuffled unless ``guided``). Drawn as a number of
    fixed range and mapped onto the options there are, so that the draw does not depend on
    the unit (hypothesis replays a choice only where its range is the same)."""
    from hypothesis import strategies as st

    if not guided:
        options = list(options)
        random.Random(data.draw(st.integers(0, 2**32 - 1), label=f"{label} order")
                      ).shuffle(options)
    return options[data.draw(st.integers(0, PICK), label=label) % len(options)]


def start_order(explorer: Explorer, tasks: list[str], lasting: list[str]) -> list[str]:
    """Tasks to start: while one is paused, the same task again (what a second task does to
    a paused one); then tasks that run until ended and are not running yet, of a family not
    started yet first (two that run side by side), then every task."""
    states = explorer.states()
    paused = [s.name for s, state in zip(explorer.slots, states, strict=True)
              if state == "paused"]
    started = {s.name for s in explorer.slots}
    families = {name.split("-")[0] for name in started}
    fresh = sorted((t for t in lasting if t not in started),
                   key=lambda t: (t.split("-")[0] in families, lasting.index(t)))
    return paused[:1] + fresh + tasks


class Priority(NamedTuple):
    """How telling a command about the tasks is in the model's view: the options sort by it,
    smallest first (ties keep the order they were offered in)."""

    unchanged: bool
    """The model expects it to change nothing: a signal to a task not live, or one that
    leaves the task's state as it is (``UNCHANGED``); a query of a task neither paused nor
    ended; a resend of a start-task whose task has not ended."""
    times_done: int
    """How often this kind of command was sent in this example (the least done first)."""
    slot: int
    """The task it is about (``BEFORE_EVERY_TASK`` for a resend)."""
    place: float
    """Its place among the commands to one task: ``QUERY_PLACE``, each signal in the order of
    ``SIGNALS``, a new start of the task's kind before or after the signals."""


BEFORE_EVERY_TASK = -1
QUERY_PLACE = 0


def signal_place(n: int) -> int:
    """The place of the n-th of ``SIGNALS`` among the commands to one task."""
    return 1 + n


START_BEFORE_SIGNALS = 0.5
START_AFTER_SIGNALS = signal_place(len(SIGNALS))


class Option(NamedTuple):
    """A command the exploration may choose next, and how telling it is."""

    priority: Priority
    action: Action


def task_commands(explorer: Explorer, alternate: bool = False, bias: bool = False
                  ) -> list[Action]:
    """Commands about the tasks started, the most telling in the model's view first: a
    signal that changes a live task's state, a query of a paused or ended task, a resend of
    a start-task whose task has ended; among those, the kind done least in this example
    first. Then the rest; then signals to a task the unit never saw. ``bias``: first, and
    as many times over as the rest, the commands toward the transitions the run has not
    reached yet (``explore_cover.toward``), so that about half the draws pick one."""
    states = explorer.states()
    done = Counter(_kind(s.action) for s in explorer.steps)
    options: list[Option] = []
    for i, state in enumerate(states):
        live = state in ("running", "paused")
        options.append(Option(Priority(state not in ("paused", "ended"), done["query", None], i,
                                       QUERY_PLACE), Query(i)))
        for n, signal in enumerate(SIGNALS):
            options.append(Option(Priority(not live or (signal, state) in UNCHANGED,
                                           done["signal", signal], i, signal_place(n)),
                                  Signal(signal, i)))
    paused = [i for i, state in enumerate(states) if state == "paused"]
    if paused and len(explorer.slots) < TASKS:  # what a new task does to a paused one
        # before or after the signals, every other example: both orders get their turn
        place = START_BEFORE_SIGNALS if len(explorer.slots) % 2 or alternate \
            else START_AFTER_SIGNALS
        options.append(Option(Priority(False, 0, paused[0], place),
                              Start(explorer.slots[paused[0]].name, slot=len(explorer.slots))))
    for step in resend_order(explorer)[:1]:
        options.append(Option(Priority(not _ended_start(explorer, states, step),
                                       done["resend", None], BEFORE_EVERY_TASK, 0),
                              Resend(step)))
    options.sort(key=lambda o: o.priority)
    rest = [o.action for o in options] + [Signal(signal, None) for signal in SIGNALS]
    wanted = toward(explorer, [n for n in TRANSITIONS if not explorer.covered[n]]) \
        if bias else []
    return wanted * max(1, len(rest) // len(wanted)) + rest if wanted else rest


def _kind(action: Action) -> tuple[str, str | None]:
    """What counts as the same kind of command: its ``do``, and a signal's name."""
    return action.do, action.signal if isinstance(action, Signal) else None


QUERY_FIRST = {"paused": 0, "ended": 1, "running": 2}


def query_order(explorer: Explorer) -> list[int | None]:
    """Tasks to ask about: paused, then ended, then running ones, the rest; then a task
    never seen (12.1: 'unknown')."""
    states = explorer.states()
    order = sorted(range(len(states)), key=lambda i: (QUERY_FIRST.get(states[i], 3), i))
    return [*order, None]


def _ended_start(explorer: Explorer, states: list[str], i: int) -> bool:
    a = explorer.steps[i].action if i < len(explorer.steps) else None
    return isinstance(a, Start) and a.slot is not None and a.slot < len(states) \
        and states[a.slot] == "ended"


def resend_order(explorer: Explorer) -> list[int]:
    """Commands to resend: a start-task whose task has ended first (it must not run
    again), then the others, the latest first."""
    states = explorer.states()
    return sorted(explorer.commands, key=lambda i: (not _ended_start(explorer, states, i), -i))


def run_example(explorer: Explorer, actions: list[Action],
                seed: int = 0) -> Story | None:
    """Run steps once, in order, and the teardown whatever happens (every task aborted):
    the story of the disagreement they show, or None when the unit answers as the model
    says."""
    explorer.begin()
    failed = False
    try:
        for action in actions:
            explorer.do(action)
    except Disagreement:
        failed = True
    finally:
        try:
            explorer.end()
        except Disagreement:
            failed = True
    return Story.of(explorer.steps, seed) if failed else None


def replay(explorer: Explorer, actions: list[Action], seed: int = 0) -> Story | None:
    """Run a stored story's steps once (its teardown as well): the story of the
    disagreement it shows again, or None when the unit now answers as the model says."""
    story = run_example(explorer, actions, seed)
    if story is not None:
        story.shrunk = True
    return story


__all__ = ["Disagreement", "Explorer", "Found", "OutOfBudget", "Outcome", "Search", "Step",
           "Stopped", "Story", "replay", "run_example"]

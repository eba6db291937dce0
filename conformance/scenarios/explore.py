"""Exploration: a hypothesis state machine sends spec-12 commands in orders no script has,
and the Monitor judges every answer (issue 17; DESIGN 'One model of the protocol's states').

Its rules are the commands: start-task (with or without task-uuid, of the tasks the unit lists
and the suite may start, parameters drawn from the task's schema inside the safe radius),
every built-in signal to any task (running, paused, ended, or never seen), query-status of any
task, a resend of any earlier command, ping, and waiting. ``Explorer`` (explore_steps.py) runs
each step and judges it; a disagreement is told as a ``Story`` (story.py).

Against a slow, real system (FIELD-NOTES 'hypothesis against a slow, real system'): no
per-step deadline, a bounded step count, health checks off, and the wall-clock budget is ours:
past it no example starts and no step runs (``OutOfBudget`` is not an ``Exception``, so
hypothesis lets it through), and the shortest failing story seen so far is the one reported,
printed the moment the first is found, shrunk or not.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from conformance.scenarios.context import BUILTIN_SIGNALS, RUNS_UNTIL_ENOUGH
from conformance.scenarios.explore_steps import Disagreement, Explorer, Step
from conformance.scenarios.story import Story

STEPS = 10
"""Steps per example at most (hypothesis' stateful_step_count)."""
TASKS = 3
"""Start-tasks per example at most."""
EXAMPLES = 10_000
"""Examples at most: the budget ends the exploration long before."""
# Generation favours, and shrinking goes towards, the first: the signal that changes most.
SIGNALS = ("$pause", "$abort", "$continue", "$enough")


class OutOfBudget(BaseException):
    """The exploration's time is up (a BaseException: hypothesis must not take it for a
    failure of the unit and shrink it)."""


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
    """What hypothesis ended with (the failure it re-raised, or its own complaint)."""


class Search:
    """One exploration: the budget, the counters, and the shortest story found so far."""

    def __init__(self, explorer: Explorer, budget: float, seed: int,
                 on_story: Callable[[Story], None] = lambda story: None) -> None:
        self.explorer = explorer
        self.budget = budget
        self.seed = seed
        self.on_story = on_story
        self.started = time.monotonic()
        self.outcome = Outcome()
        self.spent = False

    def left(self) -> float:
        return self.budget - (time.monotonic() - self.started)

    def check(self) -> None:
        if self.spent or self.left() <= 0:
            self.spent = True
            raise OutOfBudget()

    def run_step(self, action: dict[str, Any]) -> None:
        self.check()
        try:
            self.explorer.do(action)
        except Disagreement as d:
            self.found(d)
            raise
        except Exception as e:  # not the unit's disagreement: end the exploration with it
            raise Stopped(e) from e
        finally:
            self.outcome.steps = self.explorer.total_steps

    def end_example(self) -> None:
        try:
            self.explorer.end()
        except Disagreement as d:
            self.found(d)
            raise
        except Exception as e:
            raise Stopped(e) from e
        finally:
            self.outcome.steps = self.explorer.total_steps

    def found(self, d: Disagreement) -> None:
        """Keep the story if it is the first or shorter than the one kept; tell the first."""
        story = Story(list(d.steps), d.step, self.seed)
        best = self.outcome.story
        if best is None:
            story.found_after = time.monotonic() - self.started
            story.found_steps = self.explorer.total_steps
            story.first_length = story.length
            self.outcome.story = story
            self.on_story(story)
        elif (story.length, story.failing) < (best.length, best.failing):
            story.found_after, story.found_steps = best.found_after, best.found_steps
            story.first_length = best.first_length
            self.outcome.story = story

    def run(self) -> Outcome:
        """Explore until the budget is spent or a story is shrunk (or hypothesis gives up)."""
        from hypothesis import HealthCheck, Phase, Verbosity, settings
        from hypothesis import seed as hseed
        from hypothesis.stateful import run_state_machine_as_test

        machine = hseed(self.seed)(machine_for(self))
        how = settings(max_examples=EXAMPLES, stateful_step_count=STEPS, deadline=None,
                       database=None, derandomize=False, phases=[Phase.generate, Phase.shrink],
                       suppress_health_check=list(HealthCheck), verbosity=Verbosity.quiet,
                       report_multiple_bugs=False, print_blob=False)
        try:
            run_state_machine_as_test(machine, settings=how)
            self.outcome.ended = "exhausted"
        except (Stopped, KeyboardInterrupt):
            raise
        except BaseException as e:
            self.outcome.last_error = f"{type(e).__name__}: {str(e)[:200]}"
            # Out of budget (hypothesis may complain on its way out that the example stopped
            # early), or hypothesis re-raised the (shrunk) failure: the story is kept.
            if self.spent:
                self.outcome.ended = "budget"
            elif self.outcome.story is not None:
                self.outcome.ended = "shrunk"
            else:
                raise
        self.outcome.elapsed = time.monotonic() - self.started
        if self.outcome.story is not None:
            self.outcome.story.shrunk = self.outcome.ended == "shrunk"
        return self.outcome


def machine_for(search: Search) -> type:
    """The state machine of one exploration: its rules are the commands of 12.1."""
    from hypothesis import strategies as st
    from hypothesis.stateful import RuleBasedStateMachine, precondition, rule

    explorer = search.explorer
    tasks = explorer.tasks or ["-"]
    # Half the starts are of tasks that run until they are ended (9: look-at-*, detection):
    # the states where signals and queries matter last; the other half of any task.
    lasting = [t for t in tasks if t in RUNS_UNTIL_ENOUGH] or tasks
    task_choice = st.one_of(st.sampled_from(lasting), st.sampled_from(tasks))

    def slot_choice(data: Any, signal: str | None) -> int | None:
        """A task by the model's view of it: those the command acts on first (a paused one
        for $continue, a running one for the other signals), then the rest, then a task the
        unit never saw (shrinking goes to the first). Drawn as a number of fixed range and
        mapped onto the tasks there are, so that the draw does not depend on the unit
        (hypothesis replays a choice only where its range is the same)."""
        states = explorer.states()
        live = {"$continue": ("paused",)}.get(signal or "", ("running", "paused"))
        order: list[int | None] = sorted(range(len(states)),
                                         key=lambda i: (states[i] not in live, i))
        order.append(None)
        return order[data.draw(st.integers(0, STEPS), label="task") % len(order)]

    # Hypothesis draws rules by their place in a list sorted by number of arguments (all have
    # one), then name, and early examples favour the first places: the names put the
    # commands that change a task's state first, ping and waiting last.
    class Exploration(RuleBasedStateMachine):
        def __init__(self) -> None:
            super().__init__()
            search.check()
            search.outcome.examples += 1
            explorer.begin()

        # At most TASKS starts an example: the steps go to what is done with them (and the
        # unit's preemption rules are reached with two or three).
        @precondition(lambda self: bool(explorer.tasks) and len(explorer.slots) < TASKS)
        @rule(how=st.tuples(task_choice, st.booleans().map(lambda b: not b),
                            st.integers(0, 3)))
        def a_start_task(self, how: tuple[str, bool, int]) -> None:
            task, task_uuid, params = how
            search.run_step({"do": "start", "task": task, "task_uuid": task_uuid,
                             "params": params, "slot": len(explorer.slots)})

        @precondition(lambda self: bool(explorer.slots))  # a task never seen: one choice of it
        @rule(data=st.data())
        def b_signal_task(self, data: Any) -> None:
            signal = data.draw(st.sampled_from(SIGNALS), label="signal")
            search.run_step({"do": "signal", "signal": signal,
                             "slot": slot_choice(data, signal)})

        @rule(data=st.data())
        def c_query_status(self, data: Any) -> None:
            search.run_step({"do": "query", "slot": slot_choice(data, None)})

        @precondition(lambda self: bool(explorer.commands))
        @rule(data=st.data())
        def d_resend(self, data: Any) -> None:
            steps = sorted(explorer.commands)
            step = steps[data.draw(st.integers(0, STEPS), label="command") % len(steps)]
            search.run_step({"do": "resend", "step": step})

        @rule(data=st.data())
        def e_ping(self, data: Any) -> None:
            search.run_step({"do": "ping"})

        @rule(periods=st.integers(1, 3))
        def f_wait(self, periods: int) -> None:
            search.run_step({"do": "wait", "periods": periods})

        def teardown(self) -> None:
            search.end_example()

    assert set(SIGNALS) == set(BUILTIN_SIGNALS)
    return Exploration


def replay(explorer: Explorer, actions: list[dict[str, Any]], seed: int = 0) -> Story | None:
    """Run a stored story's steps once, in order (its teardown as well): the story of the
    disagreement it shows again, or None when the unit now answers as the model says."""
    explorer.begin()
    try:
        for action in actions:
            explorer.do(action)
        explorer.end()
    except Disagreement as d:
        return Story(list(d.steps), d.step, seed, shrunk=True)
    return None


__all__ = ["Disagreement", "Explorer", "OutOfBudget", "Outcome", "Search", "Step", "Stopped",
           "Story", "replay"]

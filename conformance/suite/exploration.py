"""The certification's exploration: after the scripted scenarios, command orders
drawn by hypothesis (``scenarios/explore.py``) within a budget, the Monitor judging every
answer; a disagreement is printed as a story the moment it is found, stored under the reports
folder, and its rerun line replays exactly that story (``--explore-replay``).
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

import pytest

from conformance.reporting.text import printable
from conformance.scenarios.deviation import Kind
from conformance.scenarios.explore import Outcome, Search, Stopped, replay
from conformance.scenarios.explore_action import Action
from conformance.scenarios.explore_cover import coverage
from conformance.scenarios.explore_steps import Collector, Explorer, UnitDied, judged
from conformance.scenarios.sender import NotSent
from conformance.scenarios.story import Story, StoryError, load
from conformance.scenarios.traffic import OutOfTime
from conformance.suite.session import Certification
from conformance.topics import DIRECT_EXECUTION

PERIODS = 50
"""The default budget in heartbeat periods of the unit: 50 s at 1 Hz (with the scripted
scenarios, a 1 Hz unit is certified within 90 s) ..."""
LEAST, MOST = 20.0, 50.0
"""... and never less or more than these seconds."""
RESERVE = 10.0
"""Seconds of --max-duration left to the tests after the exploration (the passive rules)."""
RUN_BUDGET = 80.0
"""Seconds a run with the default options aims to end within (a 1 Hz unit is certified within
90 s whatever single fault it has): the default exploration takes what the
scripted scenarios left of it, after ``RESERVE`` for the passive rules; ``--explore`` asks for
an exact budget instead."""
ANSWER_PACE = 1.0
"""Seconds: the answer time ``RUN_BUDGET`` is made for (the reference unit answers at once;
a unit whose median answer takes longer gets a run budget that much longer: ``pace``)."""
LEAST_WORTH = 5.0
"""Seconds below which the default exploration is not begun (it would not finish an example)."""


def default_budget(rate: float | None) -> float:
    """Seconds of exploration when --explore is not given: ``PERIODS`` heartbeat periods."""
    return min(MOST, max(LEAST, PERIODS / (rate if rate and rate > 0 else 1.0)))


def budget(c: Certification) -> float:
    """The exploration's budget: --explore, or the default within what the scripted scenarios
    left of ``RUN_BUDGET`` (``run_budget_left``); within what --max-duration has left once the
    tests after it have their share."""
    wanted = c.settings.explore
    if wanted is None:
        wanted = min(default_budget(c.context.rate_of("heartbeat")), run_budget_left(c))
        if wanted < LEAST_WORTH:
            return 0.0
    deadline = c.traffic.waits.deadline
    if deadline is not None:
        wanted = min(wanted, deadline - c.traffic.clock.monotonic() - RESERVE)
    return max(0.0, wanted)


def pace(c: Certification) -> float:
    """How much slower than ``RUN_BUDGET`` is made for the unit goes, at least 1: its
    heartbeat period in seconds (the scripted waits for info messages and feedback go by
    it) plus its median answer time over ``ANSWER_PACE`` (every command waits for it): 1 for
    a 1 Hz unit that answers at once, 4 for a 0.5 Hz unit answering after 1-3 s. Only
    answers that came count: a unit that answers nothing is no slower, nor its run longer."""
    rate = c.context.rate_of("heartbeat")
    answers = c.commander.answer_time()
    return max(1.0, (1.0 / rate if rate and rate > 0 else 1.0)
               + (answers or 0.0) / ANSWER_PACE)


def run_budget(c: Certification) -> float:
    """Seconds a default run aims to end within: ``RUN_BUDGET`` times --timing-scale, times
    the unit's ``pace``."""
    return RUN_BUDGET * c.settings.timing_scale * pace(c)


def run_budget_left(c: Certification) -> float:
    """Seconds of ``run_budget`` the scripted scenarios left to the exploration, the passive
    rules' ``RESERVE`` kept."""
    spent = c.traffic.clock.now() - c.started
    return run_budget(c) - spent - RESERVE


def story_path(c: Certification) -> Path:
    return c.settings.reports_dir / f"{c.reports.stem}-explore.json"


def rerun(c: Certification, path: Path) -> str:
    """The line that replays ``path``'s story (and nothing else) against the same unit."""
    base = c.settings.rerun_command()
    if c.settings.explore_replay is None:
        base += f" --explore-replay={shlex.quote(str(path))}"
    words = shlex.split(base)
    selected = any(a == "-k" and b == "test_explore" for a, b in zip(words, words[1:], strict=False))
    return base if selected else base + " -k test_explore"


def _save(c: Certification, story: Story, path: Path) -> Path:
    """Store ``story`` with the deviations the run had adapted to (a replay adapts alike)."""
    return story.save(path, str(c.unit), [d.kind.rule for d in c.deviations.all()])


def remember(c: Certification, story: Story, path: Path, began: float) -> None:
    """Each rule ``story`` broke is repeated by replaying it (``Certification.rerun_command``),
    unless the rule was also found before exploration ``began`` (Unix seconds)."""
    for rule in story.rules:
        c.evidence.replays.setdefault(rule, (began, rerun(c, path)))


def run(c: Certification, node: pytest.Item) -> None:
    """Explore (or replay a stored story) and turn what was found into this test's outcome."""
    s = c.settings
    if s.explore == 0 and s.explore_replay is None:
        pytest.skip("could not test: exploration is off (--explore 0): command orders beyond "
                    "the scripted scenarios were not explored")
    if not c.claims(DIRECT_EXECUTION):
        pytest.skip(f"the unit does not declare '{DIRECT_EXECUTION}': nothing to explore")
    dead = c.unit_died()
    if dead:
        pytest.skip(f"could not test: {dead}")
    actions: list[Action] | None = None
    stored: dict[str, Any] = {}
    if s.explore_replay is not None:
        try:
            actions, stored = load(s.explore_replay)
        except StoryError as e:
            pytest.fail(str(e), pytrace=False)
        for rule in stored["adapted"]:  # replayed as the run that stored it ran it
            c.deviations.note(Kind(rule), "seen in the run that stored this story",
                              "the replay adapts to it as that run did")
    try:
        c.observation.wait_execution_info()
    except OutOfTime as e:
        c.out_of_time_reached(e)
        c.fail_if_out_of_time()
    collector = Collector(str(c.unit), lambda v: judged(v, c.profile))
    explorer = Explorer(c.context, collector, lambda task_uuid: _model_state(c, task_uuid),
                        dead=c.unit_died)
    c.connection.listeners.append(collector)
    died, began = "", c.traffic.clock.now()
    try:
        if actions is not None:
            _replay(c, explorer, actions, stored, node, began)
        else:
            _explore(c, explorer, node, began)
    except UnitDied as e:  # in a replay (of a stored story, or while shrinking)
        died = str(e)
    except Stopped as e:
        if isinstance(e.cause, UnitDied):
            died = str(e.cause)
        elif isinstance(e.cause, NotSent):  # --dry-run, or the publish policy refused it
            pytest.skip(f"could not test: {e.cause}")
        elif isinstance(e.cause, OutOfTime):
            c.out_of_time_reached(e.cause)
            c.fail_if_out_of_time()
        else:
            raise e.cause from None
    finally:
        c.connection.listeners.remove(collector)
        if not s.dry_run:
            c.commander.abort_all(c.timing.response)
        c.reports.write()
    if died:
        _died(c, explorer, died, node, began)


def _died(c: Certification, explorer: Explorer, why: str, node: pytest.Item,
          began: float) -> None:
    """The unit died on what the exploration sent (HB-012 fails too, naming the command):
    the steps that led there, stored and replayable; nothing more could be explored."""
    story = Story.of(explorer.steps, c.settings.seed)
    path = _save(c, story, story_path(c))
    remember(c, story, path, began)
    c.explored = f"the unit died at step {len(explorer.steps)} of an example"
    c.explore_story = _told(story, f"the unit died during step {len(explorer.steps)} of "
                                   f"these: {why}")
    node.user_properties.append(("explore", c.explored))
    pytest.fail(story.render(str(c.unit), "", brief=True, heading=(
        f"exploration: the unit died during step {len(explorer.steps)} of these (not shrunk: "
        f"a dead unit answers no replay): {why}. It must survive any order of commands "
        f"(12.1); HB-012 names the command it received last:")) + f"\n\nstory stored: {printable(str(path))}\n  rerun     "
        f"{rerun(c, path)}", pytrace=False)


def _model_state(c: Certification, task_uuid: str) -> str | None:
    """The protocol model's view of a task (the one the Monitor judges with: lint and the
    suite cannot disagree about a sequence), None when it holds nothing of it."""
    state = c.model_state(task_uuid)
    return state.value if state is not None else None


def _say(c: Certification, text: str) -> None:
    """Print ``text`` a line at a time (a story's wire text is escaped where it is rendered;
    the progress line escapes whatever a line holds, its line breaks too)."""
    if c.progress.verbosity >= 0:
        for line in text.splitlines():
            c.progress.line(line)


def _skip_without_time(c: Certification, seconds: float) -> None:
    """No time left to explore: could not test, said beside the verdict too (the run's facts:
    ``RunFacts.unexplored``), never a silent skip."""
    if seconds > 0:
        return
    if c.settings.explore is None:
        spent = c.traffic.clock.now() - c.started
        c.unexplored = (f"the scripted scenarios took {spent:.0f} s; a default run aims for "
                        f"{run_budget(c):.0f} s at this unit's pace, so no time was left to "
                        f"explore command orders (--explore 50s explores anyway)")
    else:
        c.unexplored = ("no time left for exploration within --max-duration "
                        f"{c.settings.max_duration:g} s")
    c.explored = f"not run: {c.unexplored}"
    pytest.skip(f"could not test: {c.unexplored}")


def _explore(c: Certification, explorer: Explorer, node: pytest.Item, began: float) -> None:
    seconds = budget(c)
    _skip_without_time(c, seconds)
    path = story_path(c)

    def tell(story: Story) -> None:  # at once: shrinking may take the rest of the budget
        _save(c, story, path)
        remember(c, story, path, began)
        _say(c, story.render(str(c.unit), rerun(c, path), brief=True, heading=(
            f"exploration found a disagreement after {story.found_after:.0f} s "
            f"({steps(story.found_steps)}); shrinking it within the {seconds:.0f} s budget "
            f"(stored: {path}):")))

    order = "" if c.settings.explore_order == "model" else ", in random order"
    share = (f", what the scripted scenarios left of the {run_budget(c):.0f}"
             f" s a default run aims for" if c.settings.explore is None
             and seconds < default_budget(c.context.rate_of("heartbeat")) - 0.5 else "")
    _say(c, f"exploring command orders for {seconds:.0f} s{share} (hypothesis, seed "
            f"{c.settings.seed}{order})")
    search = Search(explorer, seconds, c.settings.seed, tell,
                    guided=c.settings.explore_order == "model")

    def doing(what: str) -> None:  # the terminal shows where it stands
        o = search.outcome
        c.progress.show_status(
            f"exploring: {search.clock.monotonic() - search.started:.0f} s of {seconds:.0f} s, "
            f"{o.examples} example{'s' * (o.examples != 1)}, {steps(o.steps)}; {what}")
    search.on_step = doing
    try:
        outcome = search.run()
    finally:
        c.progress.show_status("")
    summary = _summary(outcome)
    if outcome.last_error and c.progress.verbosity > 0:
        _say(c, f"exploration ended with {printable(outcome.last_error)}")
    node.user_properties.append(("explore", summary))
    c.explored = summary
    story = outcome.story
    if story is None and not outcome.covered:
        # Nothing sent, or no transition of the model reached (a slow unit's one start-task
        # in 11 s), is nothing explored: could not test (the run's facts say so), never a
        # pass of a search that did not happen.
        c.unexplored = (f"no command order was explored ({summary}); --explore 120s gives "
                        f"it longer")
        c.explored = f"not run: {c.unexplored}"
        pytest.skip(f"could not test: {c.unexplored}")
    if story is None:
        _say(c, f"exploration: {summary}: the unit answered as the model says")
        return
    _save(c, story, path)
    remember(c, story, path, began)
    state = "shrunk" if story.shrunk else "not fully shrunk (the budget ran out)"
    heading = (f"exploration: the unit and the model disagree at step {story.failing + 1} of "
               f"this story ({state}, {steps(story.length)}; first found after "
               f"{story.found_after:.0f} s and {steps(story.found_steps)}, in "
               f"{steps(story.first_length)}; {summary})")
    c.explore_story = _told(story, f"{heading}; stored: {path}")
    pytest.fail(story.render(str(c.unit), rerun(c, path), heading=heading)
                + f"\n\nstory stored: {printable(str(path))}", pytrace=False)


def _replay(c: Certification, explorer: Explorer, actions: list[Action],
            stored: dict[str, Any], node: pytest.Item, began: float) -> None:
    path = c.settings.explore_replay
    assert path is not None
    _say(c, f"replaying the {steps(len(actions))} of {printable(str(path))}")
    story = replay(explorer, actions, c.settings.seed)
    c.explored = f"replayed {steps(len(actions))} of {path}"
    if story is None:
        node.user_properties.append(("explore", "replay: no disagreement"))
        _say(c, f"replay of {printable(str(path))}: no longer fails: the unit answered every "
                "step as the model says")
        return
    remember(c, story, path, began)
    heading = f"replay of {printable(str(path))}: the unit and the model disagree"
    was, rules = stored.get("failing_step"), stored.get("rules")
    rules = [str(r) for r in rules] if isinstance(rules, list) else []
    told = f"step {printable(str(was))[:20]}: {printable(', '.join(rules))[:200] or '?'}"
    if set(rules) & set(story.rules):
        heading += f" again, at step {story.failing + 1}"
        if was != story.failing + 1 or set(rules) != set(story.rules):
            # a warning the unit gave then, not now; or the finding's message came a step
            # later or earlier (the unit's messages arrive at its own pace, not the steps')
            heading += f" ({', '.join(story.rules)}; the stored story's {told})"
    else:  # the unit answers otherwise now: never told as the stored story's repeat
        heading += (f" at step {story.failing + 1} ({', '.join(story.rules)}), unlike the "
                    f"stored story ({told})")
    c.explore_story = _told(story, heading)
    pytest.fail(story.render(str(c.unit), rerun(c, path), heading=heading), pytrace=False)


def _told(story: Story, heading: str) -> str:
    """The story for the reports: its steps and the rules broken at each (its messages are
    in the evidence and in the stored story file)."""
    return story.render("", "", heading=heading, brief=True)


def steps(count: int) -> str:
    return f"{count} step{'s' * (count != 1)}"


def _summary(outcome: Outcome) -> str:
    why = {"budget": "budget spent", "shrunk": "story shrunk", "exhausted": "nothing left to "
           "try"}.get(outcome.ended, outcome.ended)
    replays = f", {outcome.replays} replays to shrink it" if outcome.replays else ""
    return (f"{outcome.examples} example{'s' * (outcome.examples != 1)}, {steps(outcome.steps)} "
            f"in {outcome.elapsed:.0f} s ({why}{replays}); {coverage(outcome.covered)}")

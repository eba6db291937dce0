"""Exploration: the conformant reference unit still certifies with it on (with and
without TST); a sequence fault no scripted scenario reaches is found by it, told as a story
whose rerun line replays it, and a replay against a unit without the fault says it no longer
fails; ``--explore 0`` and ``--dry-run`` say why nothing was explored (never a pass)."""

from __future__ import annotations

import json
import shlex

import pytest
from certify_helpers import FAST, UNIT, certify

pytestmark = pytest.mark.slow

EMBEDDED = ("--unit", UNIT, "--broker", "embedded", "--sim-rate", "2", f"--profile={FAST}")
FAULT, RULE = "pause-pauses-all", "EXEC-SEQ-002"
"""A sequence fault (two tasks, $pause to one) and the rule it breaks."""


def explore_outcome(run) -> str:  # type: ignore[no-untyped-def]
    reprec = run.result.reprec
    (rep,) = [r for r in reprec.getreports("pytest_runtest_logreport")
              if r.nodeid.endswith("test_explore") and r.when == "call"
              or r.nodeid.endswith("test_explore") and r.skipped]
    return str(rep.outcome)


@pytest.mark.parametrize("tst", [False, True], ids=["direct", "tst"])
def test_conformant_unit_certifies_with_exploration(pytester: pytest.Pytester,
                                                    tst: bool) -> None:
    run = certify(pytester, *EMBEDDED, "--explore=12s", "--seed", "3",
                  *(["--sim-tst"] if tst else []))
    assert run.result.ret == 0, run.text
    assert explore_outcome(run) == "passed", run.text
    assert run.report is not None
    assert "examples" in run.report["meta"]["explore"], run.report["meta"]
    # after the scripted scenarios, before the passive rules
    names = [line for line in run.result.outlines if "::" in line or ".py " in line]
    assert "--explore 12" in run.report["meta"]["rerun"]
    assert not list(run.reports_dir.glob("*-explore.json")), names


def test_sequence_fault_found_told_and_replayed(pytester: pytest.Pytester) -> None:
    run = certify(pytester, *EMBEDDED, f"--sim-fault={FAULT}", "--explore=60s", "--seed", "1",
                  "-k", "test_explore")
    assert run.result.ret == 1, run.text
    assert explore_outcome(run) == "failed", run.text
    text = run.text
    assert "exploration found a disagreement" in text  # told at once, before shrinking
    told = text.split("exploration found a disagreement", 1)[1].split(
        "exploration: the unit and the model disagree")[0]
    assert "\\x0a" not in told and "\n   1. start-task" in told  # a line a step, as printed
    assert f"disagree here: {RULE}" in told and "sent  {" not in told  # brief: the steps
    assert "<-- the model and the unit disagree here" in text and RULE in text
    assert "sent  {" in text and "came  exec/response:" in text
    # the reports tell the story step by step too
    assert run.report is not None and RULE in run.report["meta"]["explore_story"]
    (html,) = run.reports_dir.glob("*.html")
    page = html.read_text()
    assert "The exploration's story, step by step" in page
    assert page.index("story, step by step") < page.index('<details class="fold">')
    assert "disagree here" in page[page.index("story, step by step"):]
    (stored,) = run.reports_dir.glob("*-explore.json")
    story = json.loads(stored.read_text())
    # shrunk to the end by replay: two tasks and the $pause (3 steps; 4 with a wait between)
    assert RULE in story["rules"] and story["shrunk"] and story["length"] <= 4, story
    assert story["adapted"] == [], story  # the conformant unit showed no deviation
    rerun = [line.split("rerun", 1)[1].strip() for line in run.result.outlines
             if line.strip().startswith("rerun") and "--explore-replay=" in line][-1]
    args = shlex.split(rerun)
    assert args[0] == "pytest" and f"--explore-replay={stored}" in args
    again = certify(pytester, *args[1:])
    assert again.result.ret == 1, again.text
    assert "disagree again" in again.text and RULE in again.text
    # the same story against the unit without the fault: it says it no longer fails
    fixed = [a for a in args[1:] if not a.startswith("--sim-fault")]
    clean = certify(pytester, *fixed)
    assert clean.result.ret == 0, clean.text
    assert "no longer fails" in clean.text


def test_random_order_explores_without_the_models_guidance_and_its_rerun_keeps_it(
        pytester: pytest.Pytester) -> None:
    """--explore-order random (what bench_explore --order random measures): the conformant
    unit still answers as the model says, the run says how it explored, and its rerun line
    repeats the order (a story found so is replayed under the same settings)."""
    run = certify(pytester, *EMBEDDED, "--explore=8s", "--explore-order=random", "--seed", "5",
                  "-k", "test_explore", "-v")
    assert explore_outcome(run) == "passed", run.text
    assert "in random order" in run.text
    assert run.report is not None and "--explore-order random" in run.report["meta"]["rerun"]
    assert "examples" in run.report["meta"]["explore"]


def test_explore_off_and_dry_run_say_why(pytester: pytest.Pytester) -> None:
    off = certify(pytester, *EMBEDDED, "--explore=0", "-k", "test_explore", "-rs")
    assert explore_outcome(off) == "skipped"
    assert "exploration is off (--explore 0)" in off.text
    assert off.report is not None and off.report["meta"]["explore"] == "off"
    dry = certify(pytester, *EMBEDDED, "--explore=10s", "--dry-run", "-k", "test_explore",
                  "-rs")
    assert explore_outcome(dry) == "skipped"
    assert "could not test: dry run: would publish" in dry.text


def test_replay_of_a_file_that_is_no_story(pytester: pytest.Pytester) -> None:
    missing = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-o", "addopts=",
                                           *EMBEDDED, "--explore-replay=nowhere.json")
    assert missing.ret == pytest.ExitCode.USAGE_ERROR
    assert "--explore-replay nowhere.json: no such file" in "\n".join(missing.errlines)
    start = {"do": "start", "task": "move-to", "slot": 0}
    for name, steps, says in (  # Each one line, a usage error, before any test
            ("other-format", None, "not a story written by --explore"),
            ("slot-string", [start, {"do": "query", "slot": "0"}],
             "step 2 (query): 'slot' is '0', not a slot"),
            ("slot-negative", [start, {"do": "signal", "signal": "$pause", "slot": -1}],
             "step 2 (signal): 'slot' is -1, not a slot"),
            ("start-without-task", [{"do": "start", "slot": 0}],
             "step 1 (start): 'task' is missing (a name)"),
            ("periods-float", [{"do": "wait", "periods": 1.5}],
             "step 1 (wait): 'periods' is 1.5, not a whole number from 0"),
            # A lone surrogate is no name a command can carry (once a TypeError, exit 1).
            ("lone-surrogate", [start, {"do": "signal", "signal": "\ud800", "slot": 0}],
             "not a readable story (no low surrogate in string"),
            ("steps-60000", [{"do": "ping"}] * 60_000,
             "60000 steps; a story holds at most 200, the steps an example keeps")):
        bad = pytester.path / f"{name}.json"
        bad.write_text(json.dumps({"format": "something else", "steps": []} if steps is None
                                  else {"format": "waraps-conformance explore story 1",
                                        "steps": [{"action": a} for a in steps]}))
        run = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-o", "addopts=",
                                           *EMBEDDED, f"--explore-replay={bad}")
        errors = "\n".join(run.errlines)
        assert run.ret == pytest.ExitCode.USAGE_ERROR, (name, errors)
        assert f"--explore-replay: {bad}: {says}" in errors, (name, errors)
        assert "Traceback" not in errors + "\n".join(run.outlines), name
    bad = pytester.path / "adapted-unknown.json"  # only the deviations the suite adapts to
    bad.write_text(json.dumps({"format": "waraps-conformance explore story 1", "steps": [],
                               "adapted": ["HB-003", ["nested"]]}))
    run = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-o", "addopts=",
                                       *EMBEDDED, f"--explore-replay={bad}")
    errors = "\n".join(run.errlines)
    assert run.ret == pytest.ExitCode.USAGE_ERROR, errors
    assert f"--explore-replay: {bad}: 'adapted' lists the rules of the deviations" in errors
    assert "Traceback" not in errors


def test_a_replay_adapts_as_the_stored_run_did_and_says_where_it_disagrees_now(
        pytester: pytest.Pytester) -> None:
    """The public L2 agent's replay said 'disagree again' at step 4 (EXEC-QUERY-001) of a
    story stored disagreeing at step 6 (EXEC-RESEND-001): the full run had adapted to its
    unanswered query-status, and the scripted scenarios had judged it. A replay adapts as
    the stored run did, and a disagreement elsewhere is never told as the story's own."""
    story = pytester.path / "story.json"
    story.write_text(json.dumps({
        "format": "waraps-conformance explore story 1", "failing_step": 3,
        "rules": ["EXEC-SEQ-002"], "adapted": ["EXEC-QUERY-001"], "steps": [
            {"action": {"do": "start", "task": "look-at-bearing", "task_uuid": True,
                        "slot": 0}},
            {"action": {"do": "query", "slot": 0}},
            {"action": {"do": "wait", "periods": 2}}]}))
    run = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "1",
                  "--sim-fault=query-unanswered", f"--profile={FAST}", "--seed", "1",
                  f"--explore-replay={story}", "-k", "test_explore")
    assert run.result.ret == 1, run.text
    assert ("adapted to EXEC-QUERY-001: seen in the run that stored this story; the replay "
            "adapts to it as that run did") in run.text, run.text
    assert "the unit answered no query-status" not in run.text  # not found again: restored
    assert "disagree again" not in run.text, run.text
    assert ("the unit and the model disagree at step 2 (EXEC-QUERY-001), unlike the stored "
            "story (step 3: EXEC-SEQ-002)") in run.text, run.text
    # The same step, a rule in common, a warning the unit gave then and not now (the public
    # L2 agent's EXEC-FB-004): the story's repeat, told with what differs.
    data = json.loads(story.read_text())
    story.write_text(json.dumps({**data, "failing_step": 2,
                                 "rules": ["EXEC-FB-004", "EXEC-QUERY-001"]}))
    again = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "1",
                    "--sim-fault=query-unanswered", f"--profile={FAST}", "--seed", "1",
                    f"--explore-replay={story}", "-k", "test_explore")
    assert ("disagree again, at step 2 (EXEC-QUERY-001; the stored story's step 2: "
            "EXEC-FB-004, EXEC-QUERY-001)") in again.text, again.text
    # The same rule a step off (its message came at the unit's pace, after the next step
    # began: a loaded machine's replay of a $pause that paused both tasks): the repeat.
    story.write_text(json.dumps({**data, "failing_step": 3, "rules": ["EXEC-QUERY-001"]}))
    later = certify(pytester, "--unit", UNIT, "--broker", "virtual", "--sim-rate", "1",
                    "--sim-fault=query-unanswered", f"--profile={FAST}", "--seed", "1",
                    f"--explore-replay={story}", "-k", "test_explore")
    assert ("disagree again, at step 2 (EXEC-QUERY-001; the stored story's step 3: "
            "EXEC-QUERY-001)") in later.text, later.text


def test_replay_never_moves_a_real_unit_without_allow_motion(pytester: pytest.Pytester) -> None:
    story = pytester.path / "story.json"
    story.write_text(json.dumps({"format": "waraps-conformance explore story 1", "steps": [
        {"action": {"do": "start", "task": "move-to", "task_uuid": True, "slot": 0}},
        {"action": {"do": "query", "slot": 0}}]}))
    run = certify(pytester, "--unit", "waraps/unit/air/real/dji0", "--broker", "embedded",
                  "--sim-rate", "2", f"--profile={FAST}", f"--explore-replay={story}",
                  "-k", "test_explore", "-v")
    assert run.result.ret == 0, run.text
    assert "sent start-task move-to" not in run.text
    assert "sent query-status" in run.text and "no longer fails" in run.text


def test_a_unit_silent_on_start_is_explored_as_briskly_as_one_that_reports_it(
        pytester: pytest.Pytester) -> None:
    """A unit that sends no feedback for a start it answered 'running' (12.4's feedback read
    as an update of the status; an independent unit) is waited for once: later
    starts go on at once (measured, default profile, 30 s: 22 steps before, 109 after)."""
    import re

    from certify_helpers import certify_virtual

    steps = {}
    for variants in ((), ("silent-start",)):
        run = certify_virtual(pytester, UNIT, "--seed", "1", "--explore=30s",
                              variants=variants)
        assert run.result.ret == 0, run.text
        found = re.search(r"exploration: \d+ examples?, (\d+) steps", run.text)
        assert found is not None, run.text
        steps[variants] = int(found.group(1))
    assert steps[("silent-start",)] >= 0.8 * steps[()], steps


def test_an_exploration_left_no_time_is_said_beside_the_verdict(
        pytester: pytest.Pytester) -> None:
    """Never a silent skip: the scripted scenarios leave --max-duration no time to explore,
    and the unit's verdict (every report's) says the exploration was not run, and why."""
    from certify_helpers import MATRIX, certify_virtual

    run = certify_virtual(pytester, UNIT, f"--profile={MATRIX}", "--seed", "1",
                          "--explore=10s", "--max-duration", "12s")
    assert run.report is not None, run.text
    why = "no time left for exploration within --max-duration 12 s"
    assert f"exploration: could-not-test ({why})" in run.text
    summary = run.report["conclusion"]["units"][UNIT]["summary"]
    assert summary.endswith(f"; exploration not run: {why}"), summary
    assert run.report["facts"]["unexplored"] == why


def test_an_exploration_that_sent_nothing_is_no_pass(pytester: pytest.Pytester) -> None:
    """A budget spent before the first example (a loaded machine once spent 21 s of 10
    starting it; here 1 ms of the real clock) explored nothing: could not test, said beside
    the verdict, never 'the unit answered as the model says'."""
    run = certify(pytester, *EMBEDDED, "--explore=0.001s", "-k", "test_explore")
    assert run.report is not None, run.text
    assert "answered as the model says" not in run.text, run.text
    assert "exploration: could-not-test (no command order was explored (0 examples, 0 steps" \
        in run.text, run.text
    assert run.report["facts"]["unexplored"].startswith("no command order was explored")


def test_an_exploration_that_reached_no_transition_is_no_pass(
        pytester: pytest.Pytester) -> None:
    """A step or two that reached none of the model's transitions (the public Workshop agent:
    one start-task in the 11 s its pace left) explored no command order: could not test."""
    from certify_helpers import MATRIX, certify_virtual

    run = certify_virtual(pytester, UNIT, f"--profile={MATRIX}", "--seed", "1",
                          "--explore=0.001s", "-k", "test_explore")
    assert run.report is not None, run.text
    assert "steps in" in run.report["facts"]["unexplored"], run.report["facts"]
    assert "transitions covered 0/" in run.report["facts"]["unexplored"]
    assert "exploration: could-not-test (no command order was explored" in run.text, run.text

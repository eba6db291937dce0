"""start-task (12.2.3, 12.3.3, 12.4, 5.3): every task the profile lets the suite run.

For each task in tasks-available that may be started (docs/ARCHITECTURE.md 'Safety'), with
parameters generated from its schema near the unit's own position: the answer is one of 12.1's
values (EXEC-START-001, judged by the Monitor) and carries the task-uuid sent (EXEC-START-002); a
running task sends feedback until a final status (EXEC-START-003) and appears in, then leaves,
``tasks-executing`` (DEI-004). One start-task goes without a task-uuid: the unit must generate
one (12.1); when no task ran yet and that one is not answered, it is asked again with a
task-uuid, as in every spec example, so that a unit deaf to the first (public agents are) still
has its tasks followed. Then a start-task with invalid parameters is refused with a reason
(EXEC-START-004), and so is a task the unit does not list (EXEC-START-005).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from conformance.protocol import NO_SUCH_TASK
from conformance.scenarios.context import Context
from conformance.scenarios.deviation import meaning
from conformance.scenarios.params import invalid_params, valid_params
from conformance.scenarios.sender import Refused, Sent
from conformance.scenarios.traffic import Entry
from conformance.violation import Observed, Violation

RULES = ("EXEC-START-001", "EXEC-START-002", "EXEC-START-003", "DEI-004")
LINK_LOST = ("the broker connection was lost while waiting for tasks-executing (an outage of "
             "the observer, not the unit's)")
FINAL_LOST = ("the broker connection was lost while the task ran: its final status may have "
              "been published meanwhile (an outage of the observer, not the unit's)")
REFUSAL_RULES = ("EXEC-START-004", "EXEC-START-005")
# Tasks that end on their own (9.6, 9.7, 9.15, 9.13): the first one available is let run to
# its end. move-to first: a target near the unit is reached in seconds.
NATURAL_END = ("move-to", "take-off", "move-path", "land")
NATURAL_RADIUS = 3.0  # metres


def _check_answer(ctx: Context, task: str, answer: Entry | None, com_uuid: str = ""
                  ) -> str | None:
    """The response value of one answer to a start-task, when usable. What the answer says is
    judged by the Monitor's conversation checks, as lint judges it (EXEC-START-001: one of
    12.1's values; EXEC-007: a failed answer's fail-reason); only no answer at all is this
    scenario's observation."""
    if answer is None:
        ctx.record("EXEC-START-001", violation=ctx.violation(
            "EXEC-START-001", expected=f"a response to start-task '{task}' within "
            f"{ctx.timing.response:.1f} s", observed="no response", command=com_uuid))
        return None
    response = answer.get("response")
    return response if isinstance(response, str) else None


def run(ctx: Context) -> None:
    """Start, watch and end every startable task; then the generated task-uuid."""
    available = ctx.tasks_available()
    origin = ctx.position()
    startable = [n for n in available if ctx.safety.may_start(n, "start")[0]]
    if _cannot_start(ctx, available, startable, origin):
        return
    assert origin is not None
    ended: list[tuple[str, int]] = []  # (task-uuid, mark of its final status)
    ran = False  # whether a task of this scenario ran
    # 12.4: one task is left to end on its own (a move ends when it arrives), so feedback is
    # seen for a natural end too, not only after signals; the others are ended by a signal.
    natural = next((t for t in NATURAL_END if t in startable), None)
    for index, task in enumerate(startable):
        # The task left to end on its own goes only a few metres: it arrives in seconds.
        params = valid_params(task, origin, ctx.safety, ctx.seed + index,
                              radius=NATURAL_RADIUS if task == natural else None)
        generate = index == len(startable) - 1  # the last one without a task-uuid (12.1)
        sent, answer, generate = _start(ctx, task, params, generate, retry=not ran)
        if answer is None:
            continue
        response = _check_answer(ctx, task, answer)
        task_uuid = _task_uuid(ctx, task, sent, answer, generate)
        if response != "running" or task_uuid is None:
            continue
        ran = True
        seen, unlisted = _listed(ctx, task, task_uuid, sent)
        final = _ended(ctx, task, task_uuid, sent, available.get(task, []),
                       natural=task == natural, listed=seen, ended=ended)
        if unlisted is not None:
            # Without a final status the task may have ended before the next info: then not
            # being listed is no violation (EXEC-START-003 or EXEC-FB-001 says what is).
            unknown = ctx.untestable(ctx.final_known()) if final is None else None
            if unknown:
                ctx.record("DEI-004", seen=Observed.UNTESTABLE,
                           reason=f"whether the task was listed before it ended: {unknown}")
            else:
                ctx.record("DEI-004", violation=unlisted)
    _check_left(ctx, ended)


def _start(ctx: Context, task: str, params: dict[str, Any], generate: bool, *,
           retry: bool) -> tuple[Sent, Entry | None, bool]:
    """Send the start-task (without a task-uuid when ``generate``, 12.1); an unanswered one
    fails EXEC-START-001. When the one without a task-uuid is not answered and no task ran
    yet (``retry``), ask again as every start-task example of the spec does, with a
    task-uuid, so that what follows a start (EXEC-START-003, DEI-004) is still judged.
    Returns the start to follow, its answer, and whether it was sent without a task-uuid."""
    def send(task_uuid: str | None) -> tuple[Sent, Entry | None]:
        sent, answer = ctx.commander.start_task(task, params, ctx.timing.response,
                                                task_uuid=task_uuid)
        if answer is None:
            _check_answer(ctx, task, None, sent.com_uuid)  # EXEC-START-001: not answered
        return sent, answer

    sent, answer = send(None if generate else "new")
    if answer is not None or not generate:
        return sent, answer, generate
    # 12.1 'a generated task-uuid will be returned in the response message': no response, so
    # no task-uuid was seen either way. Not a pass (the answers to start-tasks that named one
    # say nothing of this), and not a second failure of the one unanswered command
    # (EXEC-START-001's).
    ctx.record("EXEC-START-002", seen=Observed.UNTESTABLE, reason=(
        f"the start-task '{task}' sent without a task-uuid was not answered "
        f"(EXEC-START-001): whether the unit generates one was not seen"))
    if not retry:
        return sent, None, True
    return (*send("new"), False)


def _cannot_start(ctx: Context, available: dict[str, list[str]], startable: list[str],
                  origin: object) -> bool:
    """Whether no task can be started (no task the suite may start, or no position to place
    its parameters near): then every rule of the scenario could not be tested."""
    if not startable:
        refused = {n: ctx.safety.may_start(n, "start")[1] for n in available}
        why = "; ".join(refused.values()) or "tasks-available is empty"
        reason = f"no task the suite may start: {why}"
    elif origin is None:
        reason = ("the unit reports no sensor/position: task positions are generated near it "
                  "(docs/ARCHITECTURE.md 'Safety')")
    else:
        return False
    for rule in RULES:
        ctx.record(rule, seen=Observed.UNTESTABLE, reason=reason)
    return True


def _task_uuid(ctx: Context, task: str, sent: Sent, answer: Entry,
               generate: bool) -> str | None:
    """EXEC-START-002 judged on the answer: one generated when none was sent (12.1), not
    another than the one sent. The task-uuid the unit runs the task under, None when it has
    none."""
    task_uuid = answer.get("task-uuid")
    wanted = sent.body.get("task-uuid")
    if generate:
        # A task-uuid that is not in UUID form is ERR-014's; here: is there one at all.
        if isinstance(task_uuid, str) and task_uuid.strip():
            ctx.record("EXEC-START-002", seen=Observed.EXAMINED)
        else:
            ctx.record("EXEC-START-002", violation=ctx.violation(
                "EXEC-START-002", expected="a generated task-uuid (start-task sent "
                "without one, 12.1)", observed=f"task-uuid {task_uuid!r}", entry=answer))
            return None
    elif task_uuid == wanted:
        pass  # no pass: only the answer to a start-task without one examines 12.1's words
    else:
        ctx.record("EXEC-START-002", violation=ctx.violation(
            "EXEC-START-002", expected=f"task-uuid {wanted}", observed=f"{task_uuid!r}",
            entry=answer, detail=f"task '{task}'"))
        # Follow the task-uuid the unit runs the task under (the commander does, too).
        task_uuid = ctx.commander.unit_task_uuid(str(wanted))  # sent: not generate
    return task_uuid if isinstance(task_uuid, str) else None


def _listed(ctx: Context, task: str, task_uuid: str,
            sent: Sent) -> tuple[Entry | None, Violation | None]:
    """5.3: a running task is listed in tasks-executing (unless it ended before the next
    direct_execution_info: then it cannot be judged here). The listing seen (its
    direct_execution_info, None if not seen) and, when not listed, the violation to judge
    once its end is known (it may have ended unannounced)."""
    gaps = ctx.commander.gaps()
    seen = ctx.wait_listed(task_uuid, after=sent.mark)
    listed = seen if seen is not None and seen.subtopic == "direct_execution_info" else None
    if listed is not None:
        ctx.record("DEI-004", seen=Observed.EXAMINED)
    elif seen is None and ctx.commander.gaps() != gaps:
        ctx.record("DEI-004", seen=Observed.UNTESTABLE, reason=LINK_LOST)
    elif seen is None and not _has_tasks_executing(ctx.traffic.latest("direct_execution_info")):
        # No list to be in (DEI-001's finding): one fault, one rule.
        ctx.record("DEI-004", seen=Observed.UNTESTABLE, reason="direct_execution_info "
                   "has no tasks-executing list (DEI-001)")
    elif seen is None:
        return None, ctx.violation(
            "DEI-004", expected=f"task {task_uuid} ('{task}') in tasks-executing while "
            "it runs", observed=f"not listed within {ctx.info_deadline():.1f} s of "
            "'running'", subtopic="direct_execution_info",
            entry=ctx.traffic.latest("direct_execution_info"))
    return listed, None


def _has_tasks_executing(info: Entry | None) -> bool:
    """Whether a direct_execution_info has a tasks-executing list (5.3): without one, DEI-001
    is the finding and DEI-004 cannot be told."""
    return info is not None and isinstance(info.get("tasks-executing"), list)


def _ended(ctx: Context, task: str, task_uuid: str, sent: Sent, signals: list[str], *,
           natural: bool, listed: Entry | None, ended: list[tuple[str, int]]) -> Entry | None:
    """EXEC-START-003: the task ends with a final status (12.4), on its own when it is the
    ``natural`` one, else (and also then, if it did not) after the signals that end it. Its
    final status, None if none came; an ended task is added to ``ended``."""
    judged = False
    if natural:
        noted = ctx.final_known()
        final = ctx.wait_final(task_uuid, after=sent.mark, why=f"('{task}', ending on its "
                               "own)", listed=listed, gaps_before=sent.gaps_before)
        if final is None:
            judged = True
            _no_final(ctx, ctx.untestable(noted), sent, violation=dataclasses.replace(ctx.violation(
                "EXEC-START-003", expected=f"'{task}' ends on its own with a final status "
                f"(finished or failed) within {ctx.timing.feedback_for(task):.1f} s",
                observed=f"statuses {ctx.commander.statuses(task_uuid, sent.mark) or 'none'}",
                subtopic="exec/feedback", detail=f"task-uuid {task_uuid}; params "
                f"{sent.body.get('task', {}).get('params')}"), condition="own-end"))
    noted = ctx.final_known()
    final = ctx.end_task(task_uuid, signals, after=sent.mark, gaps_before=sent.gaps_before)
    statuses = ctx.commander.statuses(task_uuid, sent.mark)
    if final is not None:
        ctx.record("EXEC-START-003", seen=Observed.EXAMINED)
        ended.append((ctx.commander.unit_task_uuid(task_uuid), ctx.traffic.mark()))
        ctx.notes.setdefault("ended", []).append(
            (task_uuid, task, meaning(final.get("status")) or final.get("status")))
    elif not judged:
        _no_final(ctx, ctx.untestable(noted), sent, violation=ctx.violation(
            "EXEC-START-003", expected=f"feedback for task '{task}' until finished, "
            "failed or aborted (12.4)", observed=f"statuses {statuses or 'none'} within "
            f"{ctx.timing.feedback_for(task):.1f} s", subtopic="exec/feedback",
            detail=f"task-uuid {task_uuid}"))
    return final


def _no_final(ctx: Context, untestable: str | None, sent: Sent, *,
              violation: Violation) -> None:
    """EXEC-START-003 without a final status: the unit's failure, unless a deviation seen
    earlier explains it, or the suite's link to the broker was lost since the task's
    start-task ``sent`` (a broker's fault is the broker's; what the unit published
    meanwhile is unknown): then could-not-test, with that reason."""
    if not untestable and ctx.commander.gaps() != sent.gaps_before:
        untestable = FINAL_LOST
    if untestable:
        ctx.record("EXEC-START-003", seen=Observed.UNTESTABLE, reason=untestable)
    else:
        ctx.record("EXEC-START-003", violation=violation)


def _check_left(ctx: Context, ended: list[tuple[str, int]]) -> None:
    """DEI-004, the other half: a task that ended leaves tasks-executing (one wait for all)."""
    if not ended:
        return
    last = max(mark for _, mark in ended)
    gaps = ctx.commander.gaps()
    info = ctx.traffic.wait_for(lambda e: True, ctx.info_deadline(1.0), after=last,
                                subtopic="direct_execution_info")
    if info is None:
        return  # no direct_execution_info at all: DEI-002/HB-008 say so
    if not _has_tasks_executing(info):
        return  # no list to leave: DEI-004 could-not-test (_listed)
    still = [u for u, _ in ended if u in ctx.executing(info)]
    if still:
        # Give it one more period: the info may have been composed before the final status.
        info = ctx.traffic.wait_for(lambda e: True, ctx.info_deadline(1.0), after=info.seq,
                                    subtopic="direct_execution_info") or info
        still = [u for u, _ in ended if u in ctx.executing(info)]
    if still and ctx.commander.gaps() != gaps:
        ctx.record("DEI-004", seen=Observed.UNTESTABLE, reason=LINK_LOST)
    elif still:
        ctx.record("DEI-004", violation=ctx.violation(
            "DEI-004", expected="tasks that ended are no longer in tasks-executing",
            observed=f"{len(still)} ended task(s) still listed: {', '.join(still[:3])}",
            subtopic="direct_execution_info", entry=info))
    else:
        ctx.record("DEI-004", seen=Observed.EXAMINED)


def run_refusals(ctx: Context) -> None:
    """EXEC-START-004 (invalid parameters) and EXEC-START-005 (task not available)."""
    available = ctx.tasks_available()
    origin = ctx.position()
    # 004: a task the suite may start, preferably one that does not move the unit, in case
    # the unit wrongly accepts the parameters.
    chosen = None
    for task in ctx.startable("refuse"):
        if origin is not None and (bad := invalid_params(task, origin, ctx.safety, ctx.seed)):
            chosen = (task, *bad)
            break
    if chosen is None:
        reason = ("the unit reports no sensor/position" if origin is None else
                  "no startable task has a parameter schema to break")
        ctx.record("EXEC-START-004", seen=Observed.UNTESTABLE, reason=reason)
    else:
        task, params, what = chosen
        try:
            sent, answer = ctx.commander.start_task(task, params, ctx.timing.response,
                                                    invalid=True)
        except Refused as e:  # malformed on purpose: a real unit gets it only by opt-in
            ctx.record("EXEC-START-004", seen=Observed.UNTESTABLE, reason=str(e))
        else:
            _expect_refusal(ctx, "EXEC-START-004", answer, f"start-task '{task}' whose {what}",
                            with_reason=True)
    # 005: a name that is certainly not in tasks-available; it cannot move anything.
    name = NO_SUCH_TASK if NO_SUCH_TASK not in available else NO_SUCH_TASK + "-2"
    sent, answer = ctx.commander.start_task(name, {}, ctx.timing.response, invalid=True)
    _expect_refusal(ctx, "EXEC-START-005", answer, f"start-task '{name}' (not in "
                    "tasks-available)", with_reason=False)
    _await_listings(ctx, sent.mark)


def _await_listings(ctx: Context, after: int, count: int = 3) -> None:
    """A refused task never runs (5.3): the Monitor fails DEI-004 for one listed in
    tasks-executing past two info periods after its refusal (the public agents keep it for
    good), so ``count`` direct_execution_info messages are awaited before the next scenario
    (a reboot would end the evidence)."""
    seen: set[int] = set()

    def enough(e: Entry) -> bool:
        seen.add(e.seq)
        return len(seen) >= count

    ctx.traffic.wait_for(enough, ctx.info_deadline(count + 0.5), after=after,
                         subtopic="direct_execution_info",
                         what="tasks-executing after the refused start-tasks")


def _expect_refusal(ctx: Context, rule: str, answer: Entry | None, what: str, *,
                    with_reason: bool) -> None:
    """``rule`` holds when the answer is 'failed' (with a non-empty fail-reason when
    ``with_reason``; otherwise an empty one is EXEC-007's alone)."""
    wanted = "'failed' with a fail-reason" if with_reason else "'failed'"
    if answer is None:
        ctx.record(rule, violation=ctx.violation(
            rule, expected=f"{wanted} for {what}",
            observed=f"no response within {ctx.timing.response:.1f} s"))
        return
    reason = answer.get("fail-reason")
    if answer.get("response") == "failed" and (
            not with_reason or isinstance(reason, str) and reason.strip()):
        ctx.record(rule, seen=Observed.EXAMINED)
        return
    if answer.get("response") == "running" and isinstance(answer.get("task-uuid"), str):
        # Accepted what it should have refused: end it at once (docs/ARCHITECTURE.md 'Safety').
        ctx.commander.signal(answer.get("task-uuid"), "$abort", ctx.timing.response)
    ctx.record(rule, violation=ctx.violation(
        rule, expected=f"{wanted} for {what}",
        observed=f"response {answer.get('response')!r}, fail-reason {reason!r}", entry=answer))

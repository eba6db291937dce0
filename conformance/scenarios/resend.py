"""Resend (2, 12.1): a command resent with the same com-uuid is answered again
(EXEC-RESEND-002, a 'should') and not executed twice (EXEC-RESEND-001).

The subject is a start-task sent without a task-uuid: a unit that executes the resend again
generates a second task-uuid, or lists the task twice in tasks-executing. A unit that answers
no start-task without a task-uuid is asked with one (as the spec's examples are).
"""

from __future__ import annotations

from typing import Any

from conformance.scenarios.context import Context, describe
from conformance.scenarios.params import valid_params
from conformance.scenarios.sender import Sent
from conformance.scenarios.traffic import Entry
from conformance.violation import Observed

RULES = ("EXEC-RESEND-001", "EXEC-RESEND-002")


def _start(ctx: Context, task: str, params: dict[str, Any]) -> tuple[Sent, Entry | None]:
    """The start-task to resend: without a task-uuid; if that is not answered (EXEC-START-001
    and -002's finding), as every start-task example of the spec is, with one. A unit that
    runs the resend again then reports the task 'running' anew or lists it twice."""
    first, answer = ctx.commander.start_task(task, params, ctx.timing.response, task_uuid=None)
    if answer is None:
        first, answer = ctx.commander.start_task(task, params, ctx.timing.response)
    return first, answer


def _listed_twice_after(ctx: Context, info: Entry | None, task_uuid: str, resent: int) -> bool:
    """``info`` lists the task twice after its resend, and the unit listed no task twice
    before it (that is its way of listing, DEI-004's finding, and no sign of a second run)."""
    if info is None or ctx.executing(info).count(task_uuid) < 2:
        return False
    return not any(e.seq < resent and len(ids) != len(set(ids))
                   for e in ctx.traffic.since(0, "direct_execution_info")
                   for ids in (ctx.executing(e),))


def run(ctx: Context) -> None:
    available = ctx.tasks_available()
    origin = ctx.position()
    task = next(iter(ctx.startable("resend")), None)
    if task is None or origin is None:
        reason = ("the unit reports no sensor/position" if origin is None
                  else ctx.none_startable("resend"))
        for rule in RULES:
            ctx.record(rule, seen=Observed.UNTESTABLE, reason=reason)
        return
    first, answer1 = _start(ctx, task, valid_params(task, origin, ctx.safety, ctx.seed))
    if answer1 is None:
        for rule in RULES:
            ctx.record(rule, seen=Observed.UNTESTABLE,
                       reason=f"start-task '{task}' was not answered, with a task-uuid or "
                              f"without (EXEC-START-001)")
        return
    again = ctx.commander.resend(first)
    answer2 = ctx.commander.response(first, ctx.timing.response, after=again.mark)
    if answer2 is not None and answer2.get("com-uuid") == answer1.get("com-uuid"):
        # The first answer again (its own com-uuid), arriving after the resend: a copy the
        # unit published twice (EXEC-009's), or its stored answer sent again for the resend
        # (2: resend 'until a response has arrived'; nothing asks for a new message). Another
        # answer that still comes is the resend's; if none does, the copy answered it.
        copy = answer2
        answer2 = ctx.commander.response(first, ctx.timing.response, after=copy.seq) or copy
    ctx.commander.track_response(again, answer2)
    if answer2 is not None:
        ctx.record("EXEC-RESEND-002", seen=Observed.EXAMINED)
    else:
        ctx.record("EXEC-RESEND-002", violation=ctx.violation(
            "EXEC-RESEND-002", expected=f"a second response to com-uuid {first.com_uuid}",
            observed=f"none within {ctx.timing.response:.1f} s of the resend",
            detail=f"first answer: {describe(answer1)}"))
    uuids = {a.get("task-uuid") for a in (answer1, answer2) if a is not None} - {None}
    # Only a 'running' answer starts a task: a resend refused ('failed', 'A task is already
    # running', perhaps naming another task-uuid) was not executed again (12.1).
    started = {a.get("task-uuid") for a in (answer1, answer2)
               if a is not None and a.get("response") == "running"} - {None}
    twice = len(started) > 1
    evidence = answer2
    if not twice and answer1.get("response") == "running" and started:
        # The same task-uuid: a unit that ran it again lists it twice, or restarts it.
        (task_uuid,) = started
        info = ctx.traffic.wait_for(lambda e: task_uuid in ctx.executing(e),
                                    ctx.info_deadline(), after=again.mark,
                                    subtopic="direct_execution_info")
        if _listed_twice_after(ctx, info, task_uuid, again.mark):
            twice, evidence = True, info
    if twice:
        ctx.record("EXEC-RESEND-001", violation=ctx.violation(
            "EXEC-RESEND-001", expected=f"start-task '{task}' executed once for com-uuid "
            f"{first.com_uuid}", observed=f"executed twice: task-uuids {sorted(started)}",
            entry=evidence,
            subtopic="exec/response" if evidence is answer2 else "direct_execution_info"))
    else:
        ctx.record("EXEC-RESEND-001", seen=Observed.EXAMINED)
    for task_uuid in uuids:
        ctx.end_task(str(task_uuid), available.get(task, []), after=first.mark,
                     gaps_before=first.gaps_before)

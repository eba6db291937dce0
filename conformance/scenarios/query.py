"""query-status (12.1): the status of a running task, of ended ones over the whole history,
and 'unknown' for a task the unit never saw."""

from __future__ import annotations

from conformance.protocol import QUERY_ANSWERS, State
from conformance.scenarios.context import Context, describe
from conformance.scenarios.deviation import FINAL_STATUSES, meaning
from conformance.scenarios.params import valid_params
from conformance.scenarios.sender import new_uuid
from conformance.scenarios.traffic import Entry
from conformance.violation import Observed

RULES = ("EXEC-QUERY-001", "EXEC-QUERY-002")
# What query-status may answer for a task whose last feedback was this status (12.1, the
# model's table; ERR-006: 12.1 says 'success' where responses say 'finished').
ACCEPTED = {state.value: set(answers) for state, answers in QUERY_ANSWERS.items()
            if state is not State.UNKNOWN}


def status_answer(answer: Entry | None) -> object:
    """The status in a query-status response: its ``status`` field, else its ``response``."""
    return answer.get("status", answer.get("response")) if answer is not None else None


def ask(ctx: Context, task_uuid: str, expected: set[str], what: str) -> None:
    sent, answer = ctx.commander.query(task_uuid, ctx.timing.response)
    got = status_answer(answer)
    if got in expected:
        ctx.record("EXEC-QUERY-001", seen=Observed.EXAMINED)
        return
    ctx.record("EXEC-QUERY-001", violation=ctx.violation(
        "EXEC-QUERY-001", expected=f"{' or '.join(sorted(expected))} for {what}",
        observed=repr(got) if answer is not None else
        f"no response within {ctx.timing.response:.1f} s", entry=answer,
        detail=f"task-uuid {task_uuid}; answer: {describe(answer)}", command=sent.com_uuid))


def run(ctx: Context) -> None:
    # A running task (one that runs until $enough, if the unit has one the suite may start).
    available = ctx.tasks_available()
    origin = ctx.position()
    task = next(iter(ctx.startable("query")), None)
    if task is not None and origin is not None:
        params = valid_params(task, origin, ctx.safety, ctx.seed)
        sent, answer = ctx.commander.start_task(task, params, ctx.timing.response)
        if answer is not None and answer.get("response") == "running":
            task_uuid = sent.body["task-uuid"]
            first = ctx.commander.first_feedback(task_uuid, ctx.timing.response,
                                                 after=sent.mark)
            if first is not None and meaning(first.get("status")) not in FINAL_STATUSES:
                ask(ctx, task_uuid, {"running", str(first.get("status"))},
                    f"running task '{task}'")
            elif first is None and ctx.commander.silent_starts:  # its answer said 'running'
                ask(ctx, task_uuid, {"running"}, f"running task '{task}'")
            final = ctx.end_task(task_uuid, available.get(task, []), after=sent.mark,
                                 gaps_before=sent.gaps_before)
            if final is not None:
                ctx.notes.setdefault("ended", []).append(
                    (task_uuid, task, meaning(final.get("status")) or final.get("status")))
    # Ended tasks, the oldest first: the history is kept for the unit's whole life (12.1).
    for task_uuid, name, status in ctx.notes.get("ended", [])[:3]:
        ask(ctx, task_uuid, ACCEPTED.get(str(status), {str(status)}),
            f"task '{name}' that ended '{status}'")
    if not ctx.notes.get("ended"):
        ctx.record("EXEC-QUERY-001", seen=Observed.UNTESTABLE,
                   reason="no task could be started and ended to ask about" + (
                       f" ({ctx.none_startable('query')})" if task is None else ""))
    ghost = new_uuid()
    sent, answer = ctx.commander.query(ghost, ctx.timing.response)
    if status_answer(answer) == "unknown":
        ctx.record("EXEC-QUERY-002", seen=Observed.EXAMINED)
    else:
        ctx.record("EXEC-QUERY-002", violation=ctx.violation(
            "EXEC-QUERY-002", expected=f"'unknown' for task-uuid {ghost} (never sent)",
            observed=repr(status_answer(answer)) if answer is not None else
            f"no response within {ctx.timing.response:.1f} s", entry=answer))

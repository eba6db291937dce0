"""signal-task (12.2.2): every signal the unit lists is answered, with the feedback it implies.

Each distinct signal in tasks-available is sent once, to a running task that lists it:
``$pause`` then ``$continue`` (feedback 'paused', then 'running': EXEC-SIG-003), ``$enough``
(ends 'finished': EXEC-SIG-004), ``$abort`` (ends 'aborted': EXEC-SIG-002), and each
task-specific signal (answered: EXEC-SIG-001). A signal for a task-uuid the unit never saw is
answered 'failed' (EXEC-SIG-005).
"""

from __future__ import annotations

from conformance.protocol import BUILTIN_SIGNALS, SIGNAL_EFFECT, SIGNAL_RULE
from conformance.scenarios.context import Context, describe
from conformance.scenarios.deviation import FINAL_STATUSES
from conformance.scenarios.params import valid_params
from conformance.scenarios.sender import new_uuid
from conformance.scenarios.traffic import Entry
from conformance.violation import Observed

RULES = ("EXEC-SIG-001", "EXEC-SIG-002", "EXEC-SIG-003", "EXEC-SIG-004", "EXEC-SIG-005")
# The feedback status each built-in signal implies and the rule it proves (12.2.2, the model's).
IMPLIED = {signal: status for signal, (status, _) in SIGNAL_EFFECT.items()}
RULE_OF = SIGNAL_RULE


def _answered(ctx: Context, signal: str, task: str, answer: Entry | None,
              com_uuid: str = "") -> bool:
    """EXEC-SIG-001 on one answer (ERR-013: shaped like a start-task response)."""
    if answer is None:
        ctx.record("EXEC-SIG-001", violation=ctx.violation(
            "EXEC-SIG-001", expected=f"a response to signal-task {signal} within "
            f"{ctx.timing.response:.1f} s", observed="no response", detail=f"task '{task}'",
            command=com_uuid))
        return False
    ctx.record("EXEC-SIG-001", seen=Observed.EXAMINED)
    return True


def _start(ctx: Context, task: str) -> tuple[str, int] | None:
    """Start ``task`` and return (task-uuid, mark) once it runs, or None."""
    origin = ctx.position()
    if origin is None:
        return None
    params = valid_params(task, origin, ctx.safety, ctx.seed)
    sent, answer = ctx.commander.start_task(task, params, ctx.timing.response)
    if answer is None or answer.get("response") != "running":
        return None
    task_uuid = ctx.commander.unit_task_uuid(sent.body["task-uuid"])
    # Signals are judged on a task that has started: wait for its first feedback (12.4),
    # unless the unit sends none for a start (its 'running' answer says it runs).
    ctx.commander.first_feedback(task_uuid, ctx.timing.response, after=sent.mark)
    return task_uuid, sent.mark


def _signal(ctx: Context, task: str, task_uuid: str, signal: str, mark: int) -> bool:
    """Send one signal and judge its answer and the feedback it implies; False when that
    feedback did not come."""
    if IMPLIED.get(signal) in FINAL_STATUSES and ctx.final_known() \
            and ctx.listing(task_uuid) is None:
        # A unit known to end tasks unsaid: see the task listed first, so that its leaving
        # tasks-executing shows the end the signal asks for (5.3).
        ctx.wait_listed(task_uuid, after=mark)
    after = ctx.traffic.mark()
    sent, answer = ctx.commander.signal(task_uuid, signal, ctx.timing.response)
    if not _answered(ctx, signal, task, answer, sent.com_uuid) or signal not in IMPLIED:
        return answer is not None
    rule, status = RULE_OF[signal], IMPLIED[signal]
    deadline = timeout = ctx.timing.feedback_for(task)
    known, ended = None, False
    if status in FINAL_STATUSES:
        # What the unit showed shortens the wait (the Monitor judges the whole deadline from
        # the traffic): once it is known to end tasks unsaid, the response deadline; its
        # leaving tasks-executing (5.3: it ended) ends the wait early, its final status then
        # getting the response deadline more, or none once that is known.
        known = ctx.final_known()
        timeout = ctx.timing.response if known else timeout
        ended, left = ctx.wait_ended(task_uuid, timeout, after=after,
                                     listed=ctx.listing(task_uuid))
        timeout = min(0.0 if known else ctx.timing.response, left) if ended else 0.0
    got = ctx.commander.feedback(task_uuid, {status}, timeout, after=after)
    if got is not None:
        ctx.record(rule, seen=Observed.EXAMINED)
        return True
    blind = ctx.commander.blind() or (None if ended else ctx.untestable(known))
    if blind:  # the known deviation, held against it once: the Monitor judges the deadline
        ctx.record(rule, seen=Observed.UNTESTABLE, reason=blind)
        return False
    statuses = ctx.commander.statuses(task_uuid, after)
    ctx.record(rule, violation=ctx.violation(
        rule, expected=f"feedback '{status}' after {signal}", observed=f"statuses "
        f"{statuses or 'none'} " + ("until it left tasks-executing" if ended else
                                    f"within {deadline:.1f} s"),
        subtopic="exec/feedback",
        entry=answer, detail=f"task '{task}' {task_uuid}; answer: {describe(answer)}"))
    return False


def run(ctx: Context) -> None:
    available = ctx.tasks_available()
    startable = ctx.startable("signal")
    todo: list[str] = []  # each distinct signal once, built-ins in a sensible order
    for signals in available.values():
        todo += [s for s in signals if s not in todo]
    order = {"$pause": 0, "$continue": 1}
    todo.sort(key=lambda s: (order.get(s, 2), s in ("$enough", "$abort"), s))
    if "$continue" in todo and "$pause" not in todo:
        todo.remove("$continue")  # nothing to continue from
    done: set[str] = set()
    for signal in todo:
        if signal in done or signal == "$continue":  # $continue only right after $pause
            continue
        task = next((t for t in startable if signal in available[t]), None)
        if task is None:
            continue
        started = _start(ctx, task)
        if started is None:
            continue
        task_uuid, mark = started
        batch = [signal]
        if signal == "$pause" and "$continue" in available[task]:
            batch.append("$continue")
        for s in batch:
            done.add(s)
            if not _signal(ctx, task, task_uuid, s, mark):
                break  # 'paused' never came: nothing to continue from (no second timeout)
        if signal not in ("$enough", "$abort"):
            ctx.end_task(task_uuid, available[task], after=mark)
    _unexamined(ctx, todo, done, available, startable)
    # EXEC-SIG-005: a task-uuid this unit has never seen.
    ghost = new_uuid()
    sent, answer = ctx.commander.signal(ghost, "$abort", ctx.timing.response)
    if answer is not None and answer.get("response") == "failed":
        ctx.record("EXEC-SIG-005", seen=Observed.EXAMINED)
    else:
        ctx.record("EXEC-SIG-005", violation=ctx.violation(
            "EXEC-SIG-005", expected=f"'failed' for a signal to unknown task-uuid {ghost}",
            observed=describe(answer) if answer else
            f"no response within {ctx.timing.response:.1f} s", entry=answer))


def _unexamined(ctx: Context, todo: list[str], done: set[str], available: dict[str, list[str]],
                startable: list[str]) -> None:
    """Why the rules of signals never sent were not examined: no task lists the signal
    (inapplicable, 5.3), or none that lists it could be started (could not test)."""
    for rule in RULES[:-1]:
        wanted = [s for s, r in RULE_OF.items() if r == rule]
        if not any(s in done for s in wanted) and rule != "EXEC-SIG-001":
            listed = [s for s in wanted if s in todo]
            blocked = [ctx.safety.may_start(t, "signal")[1] for t in available
                       if t not in startable and any(s in available[t] for s in listed)]
            reason = (f"no task in tasks-available lists {' or '.join(wanted)} (5.3)"
                      if not listed
                      else f"no task listing {' or '.join(listed)} could be started"
                      + (f" ({'; '.join(blocked)})" if blocked and not any(
                          any(s in available[t] for s in listed) for t in startable) else ""))
            ctx.record(rule, seen=Observed.UNTESTABLE if listed else Observed.NOT_APPLICABLE,
                       reason=reason)
    # What an accepted $abort (EXEC-SEQ-001) or any built-in signal (EXEC-SEQ-002) does:
    # inapplicable where no task lists one (the Monitor's examination, if any, passes).
    for rule, signals in (("EXEC-SEQ-001", ("$abort",)), ("EXEC-SEQ-002", BUILTIN_SIGNALS)):
        if not any(s in todo for s in signals):
            ctx.record(rule, seen=Observed.NOT_APPLICABLE, reason=f"no task in tasks-available "
                       f"lists {' or '.join(signals)} (5.3)")
    if not todo:
        ctx.record("EXEC-SIG-001", seen=Observed.NOT_APPLICABLE,
                   reason="no task in tasks-available lists a signal (5.3)")
    elif not done:
        ctx.record("EXEC-SIG-001", seen=Observed.UNTESTABLE,
                   reason="no task with signals could be started" + (
                       f" ({ctx.none_startable('signal')})" if not startable else ""))


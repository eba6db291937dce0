"""A task's lifecycle as its feedback and tasks-executing show it (12.4, 5.3).

Feedback follows a task to one final status (finished, failed, aborted) and nothing follows it;
an accepted signal implies the feedback it asks for (12.2.2); a task that leaves
tasks-executing has ended, and its final feedback is due (judged by ``exec_deadline``). Feedback
after the end that a resend caused is EXEC-RESEND-001's, not EXEC-FB-004's.
"""

from __future__ import annotations

from collections.abc import Iterator

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import response_timeout, str_of, violation
from conformance.checks.conversation import (
    CONVERSATIONS,
    FEEDBACK_WITHOUT_TASK_UUID,
    LISTED_KEPT,
    Conversations,
    conversations,
    said,
    state_of,
    task_uuid_sent,
)
from conformance.checks.registry import check, reinterprets
from conformance.checks.stash import StashKey
from conformance.message import Message
from conformance.status import FINAL_STATUSES, meaning
from conformance.taskrecord import State, TaskRecord
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

REPEATS_STATUS: StashKey[bool] = StashKey("repeats-status")
"""The unit said a task's 'running' again with nothing between and no
resend to answer (12.4's 'Update of the status' read as a periodic report): a 'running' after
a resend is then no sign that it started the task again (EXEC-RESEND-001)."""


@check("EXEC-FB-004", "EXEC-START-003", "EXEC-SIG-002", "EXEC-SIG-003", "EXEC-SIG-004",
       "EXEC-RESEND-001", "EXEC-RESEND-003", on=(TopicKind.EXEC_FEEDBACK,),
       reads=(CONVERSATIONS, FEEDBACK_WITHOUT_TASK_UUID, REPEATS_STATUS))
def feedback_follows_task(ctx: CheckContext, unit: UnitState, msg: Message,
                          v: Validation) -> Iterator[Violation]:
    """12.4: feedback follows a task to one final status (finished, failed, aborted), and
    nothing follows that (a repeated delivery of the final message, same com-uuid, is no new
    feedback)."""
    m = v.message
    task_uuid, status = task_uuid_sent(m), str_of(m, "status")
    status = meaning(status) or status  # 'done' ends a task as 'finished' (EXEC-FB-002's word)
    if not task_uuid or status is None:
        # Missing or empty ("" names no task): which task it concerns cannot be told. Its own
        # finding per message (EXEC-FB-001), never one pseudo-task '' whose feedback follows
        # its own final status (docs/FIELD-NOTES.md 'Precision': empty task-uuid).
        if status is not None:
            unit.stash[FEEDBACK_WITHOUT_TASK_UUID] = True
            unit.note("EXEC-FB-004", "feedback without a task-uuid: its tasks could not be "
                                     "tracked")
        return
    c = conversations(unit, ctx)
    t = msg.time
    unit.examine("EXEC-FB-004")
    task = c.followed(task_uuid) or c.task(task_uuid, t)
    if str_of(m, "task-uuid") != task_uuid:
        c.model.hear(task, status, t)  # by another key: the model did not (exec_sequence)
    if task.said_failed and status != "failed" and not _runs_again(task, status) and (
            task.final is None or task.final[0] == "failed"):
        yield from _failed_but_runs_on(c, task, msg, status)
    if task.final is not None:
        yield from _after_final(c, task, task_uuid, msg, m, status)
        return
    if status == "running":
        before = said(task, 2)[1:]  # this one is the model's latest already
        if task.running_feedback and before and before[0][1] == "running":
            if task.resent is None:
                unit.stash[REPEATS_STATUS] = True
            elif not unit.stash.get(REPEATS_STATUS):
                yield violation("EXEC-RESEND-001", msg, expected=f"task {task_uuid} started "
                                "once", observed="a new 'running' after its start-task was "
                                "resent", path="$.status", detail="12.1: a resend is answered "
                                "from memory, not executed again")
        task.running_feedback += 1
    yield from _judge_signalled(unit, c, task_uuid, msg, status)
    if status == "failed":  # the finding if the task runs on after it (EXEC-FB-004's note)
        rule = "EXEC-RESEND-003" if task.resent is not None else "EXEC-FB-004"
        unit.examine(rule)
        task.said_failed = (*task.said_failed, (rule, msg))[-2:]
    if status in FINAL_STATUSES:
        c.ended(task, (status, str_of(m, "com-uuid"), t))
        if task.command is not None:
            unit.examine("EXEC-START-003")


def _runs_again(task: TaskRecord, status: str) -> bool:
    """The task, ended, runs again after its start-task was resent (EXEC-RESEND-001)."""
    return (task.final is not None and task.resent is not None
            and task.resent > task.final[2] and status not in FINAL_STATUSES)


def _failed_but_runs_on(c: Conversations, task: TaskRecord, msg: Message,
                        status: str) -> Iterator[Violation]:
    """A task said 'failed' (by its feedback, or by the answer to its resent start-task) and
    runs on: the 'failed' was false, and is the finding, once (EXEC-RESEND-003, EXEC-FB-004's
    decision), not the later, true status. The task is followed on to its true end."""
    for rule, failed in task.said_failed:
        yield violation(rule, failed, expected=f"'failed' only for a task that failed: task "
                        f"{task.task_uuid} did not", observed=f"'failed', then '{status}' "
                        f"{msg.time - failed.time:.2f} s later: the task ran on", path=(
                            "$.status" if failed.topic == msg.topic else "$.response"),
                        detail="12.1: answer a resend as the first time (from memory); "
                        "say 'failed' only when the task has ended so")
    task.said_failed = ()
    if task.final is not None:
        task.final = None
        c.started(task)


def _after_final(c: Conversations, task: TaskRecord, task_uuid: str, msg: Message, m: object,
                 status: str) -> Iterator[Violation]:
    """12.4: nothing follows a task's final status (EXEC-FB-004), but the same final message
    delivered again. Executed again (EXEC-RESEND-001) only when the task runs again after its
    start-task was resent: a resend refused ('failed', 'A task is already running') ran
    nothing twice, and a 'failed' feedback answering it (or another task's signal) is feedback
    after the final status, EXEC-FB-004's decision (12.4 says neither which statuses end a
    task nor that feedback stops)."""
    assert task.final is not None
    end_status, end_com_uuid, end_time = task.final
    if str_of(m, "com-uuid") == end_com_uuid:
        return
    again = (task.resent is not None and task.resent > end_time
             and status not in FINAL_STATUSES)
    rule = "EXEC-RESEND-001" if again else "EXEC-FB-004"
    yield violation(rule, msg, expected=f"no feedback for task {task_uuid} after its final "
                    f"status '{end_status}'", observed=f"status '{status}' "
                    f"{msg.time - end_time:.2f} s later" + (" (after its start-task was "
                                                            "resent: executed again)"
                                                            if again else ""),
                    path="$.status", detail="stop sending feedback once a task is "
                    "finished, failed or aborted")
    if again:  # it runs again: its later feedback is that run's, judged as a live task's
        task.final, task.resent = None, None  # in the state it says (``state_of``)
        task.said_failed = ()  # its 'failed' was true: that run ended so
        c.started(task)


def _judge_signalled(unit: UnitState, c: Conversations, task_uuid: str, msg: Message,
                     status: str) -> Iterator[Violation]:
    """12.2.2: an accepted signal is followed by the feedback it asks for: that status
    proves its rule, a final status other than it breaks it."""
    for e in [e for e in c.expects if e.task_uuid == task_uuid]:
        if status in e.wanted:
            unit.examine(e.rule)
            c.expects.remove(e)
        elif status in FINAL_STATUSES:
            c.expects.remove(e)
            unit.examine(e.rule)
            yield violation(e.rule, msg, expected=f"{' or '.join(sorted(e.wanted))} after "
                            f"{e.command.describe()} was accepted",
                            observed=f"status '{status}'", path="$.status")


@check("EXEC-START-003", "EXEC-RESEND-001", on=(TopicKind.DIRECT_EXECUTION_INFO,),
       reads=(CONVERSATIONS,))
def tasks_executing_follow_tasks(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> list[Violation] | None:
    """5.3: tasks-executing lists the running tasks: a started task that leaves it has ended,
    and its final feedback is due (not while it is paused, unless it was listed paused); one
    listed twice after a resend was executed twice.
    (Runs on every direct_execution_info: a list or None; nothing to do without open tasks.)"""
    c = unit.stash.get(CONVERSATIONS)
    if c is None or not c.running:
        return None
    m = v.message
    executing = m.get("tasks-executing") if type(m) is dict else None
    if type(executing) is not list:
        return None
    open_tasks = c.open()
    listed = [e.get("task-uuid") for e in executing if isinstance(e, dict)]
    found = None
    for task in open_tasks:
        n = listed.count(task.task_uuid)
        paused = state_of(task) is State.PAUSED
        if n > 1 and task.resent is None:
            c.lists_twice = True  # its way of listing (DEI-004's), not a resend run twice
        if n:
            task.listed, task.listed_at, task.left_at = True, msg.time, None
            task.listed_paused = task.listed_paused or paused
            if n > 1 and task.resent is not None and not c.lists_twice:
                unit.examine("EXEC-RESEND-001")
                task.resent = None  # said once
                found = [violation("EXEC-RESEND-001", msg, expected=f"task {task.task_uuid} "
                                   f"once in tasks-executing", observed=f"listed {n} times "
                                   f"after its start-task was resent",
                                   path="$.tasks-executing")]
        elif paused and not task.listed_paused:
            # 5.3 lists the tasks 'currently executing': a unit may leave a paused one out
            # while it is paused, so its leaving is no end (listed again, or ended, once
            # continued); a unit seen listing it paused has no such reading.
            task.left_at = None
        elif task.listed and task.left_at is None:
            task.left_at = msg.time
    return found


ENDED_FOR_GOOD = ("finished", "aborted")
"""Final statuses after which a task cannot be executing (DEI-004 from traffic). Not 'failed':
the public agents also answer a refused command (a resend, another task's signal) with a
'failed' feedback naming a task that runs on, so which of the two messages is false cannot be
told (EXEC-FB-004's, decided)."""
NO_LIST = ("direct_execution_info has no tasks-executing list (DEI-001): whether an ended task "
           "leaves it cannot be told")
LISTED_GRACE_PERIODS = 2.0
"""An info message composed before the final feedback may still list the task: two declared
periods of direct_execution_info (or the response timeout, if longer) pass first."""


@check("DEI-004", on=(TopicKind.DIRECT_EXECUTION_INFO,), reads=(CONVERSATIONS,))
def ended_tasks_leave_tasks_executing(ctx: CheckContext, unit: UnitState, msg: Message,
                                      v: Validation) -> list[Violation] | None:
    """5.3 'List of tasks currently executing.': a task whose feedback said 'finished' or
    'aborted' and is listed long after is an entry that never ends. Found wherever
    the traffic shows it, whichever command ended the task. (Runs on every
    direct_execution_info: a list or None.)"""
    c = unit.stash.get(CONVERSATIONS)
    m = v.message
    executing = m.get("tasks-executing") if type(m) is dict else None
    if type(m) is dict and type(executing) is not list:
        # The public L2 agents' info: no list to leave (DEI-001's finding), said as the skip
        unit.note("DEI-004", NO_LIST)
    elif unit.notes.get("DEI-004") == NO_LIST:
        del unit.notes["DEI-004"]
    if c is None or not executing or type(executing) is not list:
        return None
    period = unit.period(TopicKind.DIRECT_EXECUTION_INFO) or 0.0
    grace = max(LISTED_GRACE_PERIODS * period, response_timeout(ctx))
    listed = [task_uuid_sent(e) if isinstance(e, dict) else None for e in executing[:64]]
    found = list(_listed_wrongly(unit, c, msg, listed, grace))
    for uuid in listed:
        task = c.followed(uuid)
        if task is None or task.final is None or task.life != c.life:
            continue
        status, _, when = task.final
        if status not in ENDED_FOR_GOOD or msg.time - when <= grace:
            continue
        unit.examine("DEI-004")
        found = found or []
        found.append(violation("DEI-004", msg, expected=f"task {task.task_uuid} no longer in "
                               f"tasks-executing once it said '{status}'", observed=f"still "
                               f"listed {msg.time - when:.1f} s after its '{status}' feedback",
                               path="$.tasks-executing", detail="5.3: list only the tasks "
                               "currently executing; remove a task when it ends"))
    return found


def _listed_wrongly(unit: UnitState, c: Conversations, msg: Message, listed: list[str | None],
                    grace: float) -> Iterator[Violation]:
    """5.3 'List of tasks currently executing.': one task listed twice (after a resend of
    its start-task, EXEC-RESEND-001's), or a task whose start-task was refused ('failed':
    it never ran) listed from after the refusal on, past the grace. Once per task."""
    first = c.first_listed
    for uuid in dict.fromkeys(u for u in listed if u):
        if uuid not in first:
            first[uuid] = msg.time
            while len(first) > LISTED_KEPT:
                first.popitem(last=False)
        if first[uuid] < 0:
            continue  # named already
        task = c.followed(uuid)
        refused = c.model.tasks.get(uuid) if task is None else None
        if listed.count(uuid) > 1 and (task is None or task.resent is None):
            observed = f"listed {listed.count(uuid)} times"
        elif (refused is not None and refused.refused and not refused.lost
              and refused.ended_at is not None and first[uuid] > refused.ended_at
              and msg.time - refused.ended_at > grace):
            observed = (f"listed {msg.time - refused.ended_at:.1f} s after its start-task "
                        f"was refused ('failed'): it never ran")
        else:
            continue
        unit.examine("DEI-004")
        first[uuid] = -1.0
        yield violation("DEI-004", msg, expected=f"task {uuid} listed once, and only while "
                        f"it runs", observed=observed, path="$.tasks-executing",
                        detail="5.3: list each task currently executing once; a refused "
                        "task never runs")


@reinterprets("EXEC-FB-001", on=(TopicKind.EXEC_FEEDBACK,))
def empty_task_uuid_names_no_task(ctx: CheckContext, unit: UnitState, msg: Message,
                                  v: Validation, found: list[Violation]) -> list[Violation]:
    """12.4: feedback names its task by task-uuid; an empty one names none. It is judged as
    missing (EXEC-FB-001), once per message, rather than as an id that is not a UUID
    (ERR-014, a warning) or as a task of its own."""
    if str_of(v.message, "task-uuid") != "":
        return found
    unit.examine("EXEC-FB-001")
    kept = [f for f in found if not (f.rule == "ERR-014" and f.path == "$.task-uuid")]
    return [*kept, Violation.of(
        "EXEC-FB-001", expected="task-uuid: the task this feedback is about (12.4)",
        observed='task-uuid ""', topic=msg.topic, path="$.task-uuid", time=msg.time,
        payload=msg.payload, detail="send the task-uuid of the task, as in its start-task "
                                    "response")]


@reinterprets("ERR-006", on=(TopicKind.EXEC_FEEDBACK,))
def success_in_feedback(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                        found: list[Violation]) -> list[Violation]:
    """12.1 calls a completed task 'success' (query-status) where 12.4's feedback says
    'finished': feedback 'success' follows 12.1's word in 12.4's place. Read as finished and
    warned (ERR-006), not failed as an unknown status (EXEC-FB-002)."""
    if not found or str_of(v.message, "status") != "success":
        return found
    out = []
    for f in found:
        if f.rule == "EXEC-FB-002" and f.path == "$.status":
            unit.examine("ERR-006")
            f = Violation.of("ERR-006", expected="'finished' (12.4) for a completed task",
                             observed="status 'success' (12.1's query-status word)",
                             topic=msg.topic, path="$.status", time=msg.time,
                             payload=msg.payload, detail="12.4's feedback says 'finished'; "
                             "'success' is what query-status answers (12.1)")
        out.append(f)
    return out

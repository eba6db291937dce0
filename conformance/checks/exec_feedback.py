"""A task's lifecycle as its feedback and tasks-executing show it (12.4, 5.3).

Feedback follows a task to one final status (finished, failed, aborted) and nothing follows it;
a signal answered 'ok' implies the feedback it asks for (12.2.2); a task that leaves
tasks-executing has ended, and its final feedback is due (judged by ``exec_deadline``). Feedback
after the end that a resend caused is EXEC-RESEND-001's, not EXEC-FB-004's.
"""

from __future__ import annotations

from collections.abc import Iterator

from conformance.checks.base import CheckContext, UnitState, check, reinterprets
from conformance.checks.command_history import response_timeout, str_of, violation
from conformance.checks.conversation import (
    FEEDBACK_WITHOUT_TASK_UUID,
    Task,
    conversations,
    task_uuid_sent,
)
from conformance.message import Message
from conformance.status import FINAL_STATUSES, meaning
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

REPEATS_STATUS = "repeats-status"
"""UnitState.private key: the unit said a task's 'running' again with nothing between and no
resend to answer (12.4's 'Update of the status' read as a periodic report): a 'running' after
a resend is then no sign that it started the task again (EXEC-RESEND-001)."""


@check("EXEC-FB-004", "EXEC-START-003", "EXEC-SIG-002", "EXEC-SIG-003", "EXEC-SIG-004",
       "EXEC-RESEND-001", on=(TopicKind.EXEC_FEEDBACK,))
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
        # its own final status (FIELD-NOTES, precision: empty task-uuid).
        if status is not None:
            unit.private[FEEDBACK_WITHOUT_TASK_UUID] = True
            unit.note("EXEC-FB-004", "feedback without a task-uuid: its tasks could not be "
                                     "tracked")
        return
    c = conversations(unit)
    t = msg.time
    unit.examine("EXEC-FB-004")
    task = c.tasks.get(task_uuid)
    if task is None:
        task = c.tasks[task_uuid] = Task(task_uuid, None, None, c.life)
    if task.final is not None:
        end_status, end_com_uuid, end_time = task.final
        if str_of(m, "com-uuid") == end_com_uuid:
            return
        again = task.resent is not None and task.resent > end_time  # resent after it ended
        rule = "EXEC-RESEND-001" if again else "EXEC-FB-004"
        yield violation(rule, msg, expected=f"no feedback for task {task_uuid} after its final "
                        f"status '{end_status}'", observed=f"status '{status}' "
                        f"{t - end_time:.2f} s later" + (" (after its start-task was resent: "
                                                         "executed again)" if again else ""),
                        path="$.status", detail="stop sending feedback once a task is "
                        "finished, failed or aborted")
        return
    if (status == "failed" and task.resend_failed is not None
            and t - task.resend_failed <= response_timeout(ctx)):
        # The unit said the resend 'failed' and fails the task in feedback too, though it runs
        # on: one fault of resend handling, not the task's end.
        yield violation("EXEC-RESEND-001", msg, expected=f"no 'failed' feedback for task "
                        f"{task_uuid}, which runs on", observed="'failed' feedback answering "
                        "the resent start-task", path="$.status",
                        detail="12.1: a resend must not touch the running task")
        return
    if status == "running":
        if task.running_feedback and task.last_status == "running":
            if task.resent is None:
                unit.private[REPEATS_STATUS] = True
            elif not unit.private.get(REPEATS_STATUS):
                yield violation("EXEC-RESEND-001", msg, expected=f"task {task_uuid} started "
                                "once", observed="a new 'running' after its start-task was "
                                "resent", path="$.status", detail="12.1: a resend is answered "
                                "from memory, not executed again")
        task.running_feedback += 1
    task.last_status, task.last_time = status, t
    if status in ("running", "paused") or status in FINAL_STATUSES:
        task.state = status
    for e in [e for e in c.expects if e.task_uuid == task_uuid]:
        if status in e.wanted:
            unit.examine(e.rule)
            c.expects.remove(e)
        elif status in FINAL_STATUSES:
            c.expects.remove(e)
            unit.examine(e.rule)
            yield violation(e.rule, msg, expected=f"{' or '.join(sorted(e.wanted))} after "
                            f"{e.command.describe()} was answered 'ok'",
                            observed=f"status '{status}'", path="$.status")
    if status in FINAL_STATUSES:
        c.ended(task, (status, str_of(m, "com-uuid"), t))
        if task.command is not None:
            unit.examine("EXEC-START-003")


@check("EXEC-START-003", "EXEC-RESEND-001", on=(TopicKind.DIRECT_EXECUTION_INFO,))
def tasks_executing_follow_tasks(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> list[Violation] | None:
    """5.3: tasks-executing lists the running tasks: a started task that leaves it has ended,
    and its final feedback is due; one listed twice after a resend was executed twice.
    (Runs on every direct_execution_info: a list or None; nothing to do without open tasks.)"""
    c = unit.private.get("conversations")
    if c is None or not c.running:
        return None
    m = v.message
    executing = m.get("tasks-executing") if type(m) is dict else None
    if type(executing) is not list:
        return None
    open_tasks = list(c.running.values())
    listed = [e.get("task-uuid") for e in executing if isinstance(e, dict)]
    found = None
    for task in open_tasks:
        n = listed.count(task.task_uuid)
        if n:
            task.listed, task.listed_at, task.left_at = True, msg.time, None
            if n > 1 and task.resent is not None:
                unit.examine("EXEC-RESEND-001")
                task.resent = None  # said once
                found = [violation("EXEC-RESEND-001", msg, expected=f"task {task.task_uuid} "
                                   f"once in tasks-executing", observed=f"listed {n} times "
                                   f"after its start-task was resent",
                                   path="$.tasks-executing")]
        elif task.listed and task.left_at is None:
            task.left_at = msg.time
    return found


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

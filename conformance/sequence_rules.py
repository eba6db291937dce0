"""The rules the model of direct execution (``conformance.protocol``) judges on a task's
feedback by the order of commands before it (12.1, 12.2.2; decisions in docs/MODEL.md): a task
that runs on after an accepted $abort (EXEC-SEQ-001), a signal that changes a task it does not
name (EXEC-SEQ-002), a resent signal applied again (EXEC-RESEND-001). Pure: each reads the
model's commands and answers and the task's record, and returns its ``Finding``s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from conformance.expectation import Finding
from conformance.status import accepts_signal
from conformance.taskrecord import TaskRecord

if TYPE_CHECKING:
    from conformance.protocol import Command, Model


def wanted_signal(status: str, previous: str | None) -> str | None:
    """The built-in signal whose effect feedback ``status`` (after ``previous``) is: 'paused'
    for $pause, 'running' again after 'paused' for $continue, 'aborted' for $abort."""
    if status == "running":
        return "$continue" if previous == "paused" else None
    return {"paused": "$pause", "aborted": "$abort"}.get(status)


def keeps_running(model: Model, task: TaskRecord, status: str, previous: str | None,
                  t: float) -> list[Finding]:
    """EXEC-SEQ-001 (12.2.2): once $abort is accepted the task stops; 'running' again (from
    'paused', or a response timeout after the answer) says it went on; one in flight not."""
    stop = task.acked_since(float("-inf"), ("$abort",))
    if stop is None or status != "running":
        return []
    when, signal, com = stop
    if previous == "running" and t - when <= model.response_timeout:
        return []
    how = "resumed from 'paused'" if previous == "paused" else \
        f"still 'running' {t - when:.2f} s later"
    word = model.answered.get(com, ("ok",))[0]
    return [Finding("EXEC-SEQ-001", task.task_uuid, com,
                    f"task {task.task_uuid} stops after {signal} was answered {word!r}",
                    f"feedback 'running' after the {word!r} ({how})", t)]


def touched_by_another(model: Model, task: TaskRecord, status: str, previous: str | None,
                       t: float) -> list[Finding]:
    """EXEC-SEQ-002 (12.2.2): a signal names one task-uuid and changes only that task.
    A task says what another task's signal asked for ('paused' for $pause, 'running' again
    after 'paused' for $continue, 'aborted' for $abort), within the response timeout of
    that signal (accepted), with no such signal sent to it in that time (answered or
    not), and, for 'aborted', no start-task or $continue in that time (either may pre-empt
    it)."""
    wanted = wanted_signal(status, previous)
    if wanted is None:
        return []
    since = t - model.response_timeout
    culprit: tuple[float, Command] | None = None
    for com, sent in reversed(model.sent_at.items()):  # the latest first
        if sent < since:
            break
        cmd = model.commands.get(com)
        if cmd is None:
            continue
        if cmd.name == "signal-task" and cmd.signal == wanted:
            if cmd.task_uuid == task.task_uuid:
                return []  # its own (perhaps answered after its feedback)
            if culprit is None and accepts_signal(model.answered.get(com, (None,))[0]):
                culprit = (sent, cmd)
        elif wanted == "$abort" and (cmd.name == "start-task" or cmd.signal == "$continue"):
            return []  # pre-empted: a second task may end the first (EXEC-START-003)
    if culprit is None:
        return []
    sent, cmd = culprit
    return [Finding("EXEC-SEQ-002", task.task_uuid, cmd.com_uuid,
                    f"only task {cmd.task_uuid} changed by {wanted} (its task-uuid)",
                    f"task {task.task_uuid} says '{status}' {t - sent:.2f} s after that "
                    f"{wanted} was sent and accepted", t,
                    "also-aborted" if wanted == "$abort" else "")]


def reapplied(model: Model, task: TaskRecord, status: str, previous: str | None,
              t: float) -> list[Finding]:
    """EXEC-RESEND-001 (2, 12.1: a resend is the same command, answered as the first and not
    executed again): a task says a $pause's or $continue's effect again ('paused' after
    'running', 'running' after 'paused') within the response timeout of a resend of that
    signal to it, whose first sending it had already shown, with no other such signal to it
    in that time whose effect it still owed (docs/MODEL.md 'Where the spec is silent: the decisions (also in `conformance/rules.toml`)')."""
    wanted = wanted_signal(status, previous)
    if wanted not in ("$pause", "$continue"):
        return []  # $abort's and $enough's ends are final: a second one is EXEC-FB-004's
    since = t - model.response_timeout
    again: Command | None = None
    for com, sent in reversed(model.sent_at.items()):
        if sent < since:
            break
        cmd = model.commands.get(com)
        if cmd is None or cmd.name != "signal-task" or cmd.signal != wanted \
                or cmd.task_uuid != task.task_uuid:
            continue
        first = model.first_sent.get(com, sent)
        shown = any(first <= when < sent and said == status for when, said in task.statuses)
        if not shown or not accepts_signal(model.answered.get(com, (None,))[0]):
            return []  # its effect still owed (or refused): this status may be its own
        again = again or cmd
    if again is None:
        return []
    return [Finding("EXEC-RESEND-001", task.task_uuid, again.com_uuid,
                    f"the resent {wanted} (com-uuid {again.com_uuid}) answered as the first "
                    f"and not applied again", f"task {task.task_uuid} says '{status}' again "
                    f"after the resend, {wanted} already applied once", t)]

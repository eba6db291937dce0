"""Responses on exec/response, matched to their command by response-to and judged (12.1, 12.3).

A response answers a command once per time it was sent, in time, with a value that fits the
command: 'pong' to a ping, 'running' or 'failed' (refusing invalid or unoffered tasks) to a
start-task, a signal-task accepted (any answer but 'failed') implies feedback (checked by ``exec_feedback`` and
``exec_deadline``), query-status agrees with the task's history, a resend is answered again
the same way. Commands the unit left unanswered before the one it answers are its own faults.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Generator, Iterator
from typing import Any

from conformance import protocol
from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import (
    OVER_A_GAP,
    late,
    left_unanswered,
    response_timeout,
    str_of,
    violation,
)
from conformance.checks.conversation import (
    ANSWER_RULE,
    CONVERSATIONS,
    Command,
    Conversations,
    Expect,
    conversations,
    expects_answers,
    latest,
    state_of,
    task_uuid_sent,
)
from conformance.checks.registry import check, reinterprets
from conformance.message import Message
from conformance.status import accepts_signal
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

EXPECTS_KEPT = 64
START_ANSWERS = ("running", "failed", "finished")
"""12.1's response values ("Possible values: running, failed, finished"), each a fit answer
to a start-task."""
STRAY_PONGS_KEPT = 8
SIGNAL_FEEDBACK = {s: ({status}, protocol.SIGNAL_RULE[s])
                   for s, (status, _) in protocol.SIGNAL_EFFECT.items()}
"""12.2.2 (the model's tables): the feedback an accepted signal implies, and the rule it
proves."""
QUERY_ANSWERS = {state.value: answers for state, answers in protocol.QUERY_ANSWERS.items()
                 if state is not protocol.State.UNKNOWN}
"""12.1 (the model's table): what query-status may answer for a task whose latest feedback
was this status."""


@check("EXEC-006", "EXEC-009", "EXEC-010", "EXEC-PING-001", "EXEC-PING-002", "EXEC-START-001",
       "EXEC-START-002", "EXEC-START-004", "EXEC-START-005", "EXEC-SIG-001", "EXEC-QUERY-001",
       "EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-RESEND-003", "EXEC-ROBUST-002",
       on=(TopicKind.EXEC_RESPONSE,),
       reads=(CONVERSATIONS,))
def response_answers_command(ctx: CheckContext, unit: UnitState, msg: Message,
                             v: Validation) -> Iterator[Violation]:
    """12.1, 12.3: a response answers a command (response-to = its com-uuid), once, in time,
    with a value that fits the command."""
    m = v.message
    response_to = str_of(m, "response-to")
    c = conversations(unit, ctx)
    t = msg.time
    cmd = c.commands.get(response_to) if response_to is not None else None
    if cmd is None:
        if response_to is not None:
            yield from _answers_nothing(ctx, unit, c, msg, m, response_to)
        cmd = _start_named(unit, c, m)
        if cmd is None:
            return
    unit.examine("EXEC-006")
    c.answered_any = True
    # credited at any time, late or not (docs/FIELD-NOTES.md 'Precision': answers in flight)
    c.last_answer = t
    if cmd.judged:
        return
    value, task_uuid = str_of(m, "response"), str_of(m, "task-uuid")
    tracked = task_uuid_sent(m)  # a task named under another key is still followed
    c.heard(cmd, value, task_uuid)
    if cmd.answers > cmd.sends:
        yield violation("EXEC-009", msg, expected=f"one answer to {cmd.describe()} per time it "
                        f"was sent ({cmd.sends})", observed=f"answer number {cmd.answers}",
                        path="$.response-to", detail="answer each command once; a resend "
                        "again, with the same answer")
        return
    unit.examine("EXEC-009")
    in_time = yield from _judge_timing(ctx, unit, cmd, msg)
    if cmd.answers > 1:
        yield from _judge_resend_answer(unit, c, cmd, msg, value, task_uuid)
        return
    if cmd.sends > 1:
        unit.examine("EXEC-RESEND-002")  # resent before any answer, and answered (12.1)
    # The unit answers: commands it left unanswered before now were its own faults, not a
    # sign that it stopped answering.
    if c.unanswered:
        for earlier in c.unanswered_before(t):
            yield from judge_unanswered(ctx, unit, c, earlier)
    if in_time:
        yield from _judge_first_answer(ctx, unit, c, cmd, msg, value, task_uuid, tracked)


def _start_named(unit: UnitState, c: Conversations, m: Any) -> Command | None:
    """The start-task a response without a known response-to (its own fault: the schema's,
    EXEC-006) answers by the task-uuid it carries (12.3.3: a start-task response names its
    task): the one start-task of that task-uuid awaiting an answer. None when the answer is
    not a start-task's, names no task, or when none or several await one (the task-uuid
    does not tell which): said on EXEC-RESEND-002 when a resend awaits."""
    task_uuid = str_of(m, "task-uuid")
    if not task_uuid or str_of(m, "response") not in START_ANSWERS:
        return None
    waiting = [cmd for cmd in c.pending.values() if cmd.name == "start-task"
               and cmd.task_uuid == task_uuid and not cmd.judged and cmd.answers < cmd.owed]
    if len(waiting) > 1 and any(cmd.sends > 1 for cmd in waiting):
        unit.note("EXEC-RESEND-002", f"a response without its command's com-uuid in "
                                     f"response-to names task {task_uuid}, which "
                                     f"{len(waiting)} start-tasks await: which one it answers "
                                     f"cannot be told")
    return waiting[0] if len(waiting) == 1 else None


def _answers_nothing(ctx: CheckContext, unit: UnitState, c: Conversations, msg: Message,
                     m: Any, response_to: str) -> Iterator[Violation]:
    """EXEC-006: a response to no command seen. Judged only when the observer saw this unit's
    commands, and not in the first response timeout (it may answer one sent before)."""
    if str_of(m, "response") == "pong":
        c.stray_pongs.append((msg.time, response_to))
        del c.stray_pongs[:-STRAY_PONGS_KEPT]
    if c.first_command is None:
        unit.note("EXEC-006", f"no command seen on {unit.address.topic('exec/command')}: "
                              f"subscribe to it to judge responses")
        return
    if ctx.started is not None and msg.time - ctx.started < response_timeout(ctx):
        unit.note("EXEC-006", "responses in the first response-timeout of the observation "
                              "may answer commands sent before it")
        return
    if c.commands.evicted:
        return  # it may answer a command older than the ones kept: cannot tell
    unit.examine("EXEC-006")
    yield violation("EXEC-006", msg, expected=f"response-to = the com-uuid of a command sent "
                    f"to {unit.address.name}", observed=f"response-to {response_to}: no such "
                    f"command seen", path="$.response-to",
                    detail="copy the command's com-uuid into response-to (12.3)")


def _judge_first_answer(ctx: CheckContext, unit: UnitState, c: Conversations, cmd: Command,
                        msg: Message, value: str | None, task_uuid: str | None,
                        tracked: str | None = None) -> Iterator[Violation]:
    """The first answer fits its command (12.1, 12.3)."""
    rule = ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002")
    t = msg.time
    if cmd.name == "ping":
        unit.examine("EXEC-PING-002")  # matched by its response-to
        if value == "pong":
            unit.examine(rule)
        else:
            yield violation(rule, msg, expected=f"'pong' answering {cmd.describe()}",
                            observed=f"response {value!r}", path="$.response")
    elif cmd.name == "start-task":
        yield from _judge_start_answer(unit, c, cmd, msg, value, task_uuid, tracked)
    elif cmd.name == "signal-task":
        unit.examine(rule)  # answered; its vocabulary is EXEC-003's (or ERR-013's)
        _await_signalled(ctx, unit, c, cmd, value, t)
    elif cmd.name == "query-status":
        yield from _judge_query(unit, c, cmd, msg, value)
    else:  # unknown or malformed: 'failed' with a reason (12.1)
        if value == "failed":
            unit.examine(rule)
        else:
            yield violation(rule, msg, expected=f"'failed' answering {cmd.describe()}",
                            observed=f"response {value!r}", path="$.response",
                            detail="refuse what you cannot execute, with a fail-reason")


def _judge_start_answer(unit: UnitState, c: Conversations, cmd: Command, msg: Message,
                        value: str | None, task_uuid: str | None, tracked: str | None
                        ) -> Iterator[Violation]:
    """12.1, 12.3.3: a start-task is answered 'running' (the task it began is followed from
    here, under the task-uuid named), 'failed' (a refusal, due for invalid parameters or a
    task not offered) or 'finished' (12.1's third value: done at once, a take-off of a unit
    already airborne)."""
    rule = ANSWER_RULE["start-task"]
    if value in START_ANSWERS:
        unit.examine(rule)
    else:
        yield violation(rule, msg, expected=f"'running', 'failed' or 'finished' answering "
                        f"{cmd.describe()}", observed=f"response {value!r}",
                        path="$.response", detail="12.1: 'Possible values: running, failed, "
                        "finished'; a start-task is answered 'running', or 'failed' with a "
                        "fail-reason")
    yield from _judge_task_uuid(unit, cmd, msg, value, task_uuid)
    if value == "running":
        yield from _judge_refusals(unit, cmd, msg)
        started = task_uuid or cmd.task_uuid or tracked
        if started is not None:  # the model began it ('running', 12.1), or follows it
            task = c.followed(started)
            if task is None or task.command is not None:
                task = c.task(started, msg.time, cmd)
            task.command = cmd  # its feedback may come first
            if task.final is None:
                c.started(task)
    elif value == "failed":
        for r in ("EXEC-START-004", "EXEC-START-005"):
            if _refusal_due(unit, cmd, r):
                unit.examine(r)


def _await_signalled(ctx: CheckContext, unit: UnitState, c: Conversations, cmd: Command,
                     value: str | None, t: float) -> None:
    """12.2.2: an accepted signal (any answer but 'failed': ``status.accepts_signal``; 12.3.2
    is empty) implies the feedback it asks for, due within the feedback timeout (``Expect``), unless that feedback came first or the signal changes
    nothing in the task's state."""
    expected = SIGNAL_FEEDBACK.get(cmd.signal or "")
    task = c.followed(cmd.task_uuid)
    # The model's decision (EXEC-SEQ-001, docs/MODEL.md): $continue to a running task
    # and $pause to a paused one change nothing, so no feedback is owed for them (a
    # running task that last spoke its own words is running all the same).
    unchanged = task is not None and (cmd.signal, state_of(task)) in protocol.UNCHANGED
    last = latest(task) if task is not None else None
    accepted = accepts_signal(value)
    if (accepted and expected and task is not None and task.life == c.life
            and last is not None and last[1] in expected[0] and last[0] >= cmd.time):
        unit.examine(expected[1])  # its feedback came first: no order between topics (12)
    elif accepted and expected and task is not None and task.final is None \
            and task.life == c.life and not unchanged:
        if len(c.expects) < EXPECTS_KEPT:
            # The task's own feedback deadline where the profile gives one (its tasks).
            deadline = ctx.profile.task_feedback_timeouts.get(
                task.name or "", ctx.profile.feedback_timeout)
            c.expects.append(Expect(task.task_uuid, expected[0], expected[1], t + deadline,
                                    cmd))
        else:
            c.dropped += 1


def _judge_task_uuid(unit: UnitState, cmd: Command, msg: Message, value: str | None,
                     task_uuid: str | None) -> Iterator[Violation]:
    """12.1: the start-task response carries the task-uuid sent, or one the unit generated.
    Only the answer to a start-task sent without one shows the generated one (the words the
    rule quotes): the task-uuid sent, returned, is no pass (a rule left could-not-test
    by a start-task never answered)."""
    if cmd.task_uuid is not None:
        if task_uuid == cmd.task_uuid:
            unit.note("EXEC-START-002", "no start-task without a task-uuid was answered: "
                                        "whether the unit generates one was not seen")
        else:
            yield violation("EXEC-START-002", msg, expected=f"task-uuid {cmd.task_uuid} (sent "
                            f"in {cmd.describe()})", observed=f"task-uuid {task_uuid!r}",
                            path="$.task-uuid", detail="return the task-uuid the commander "
                            "sent (12.1)")
    elif value is not None and value != "failed":
        # 12.1 'a generated task-uuid will be returned in the response message': whatever
        # word accepts the start ('running'; 'ok' is EXEC-START-001's finding), only a
        # refusal names no task.
        if task_uuid:
            unit.examine("EXEC-START-002")
        else:
            yield violation("EXEC-START-002", msg, expected=f"a generated task-uuid "
                            f"({cmd.describe()} sent none)", observed=f"task-uuid "
                            f"{task_uuid!r}", path="$.task-uuid", detail="12.1: when "
                            "start-task has no task-uuid, generate one and return it")


def _refusal_due(unit: UnitState, cmd: Command, rule: str) -> bool:
    if rule == "EXEC-START-004":
        return cmd.invalid
    available = unit.tasks_available
    return bool(available) and cmd.task_name is not None and cmd.task_name not in available


def _judge_refusals(unit: UnitState, cmd: Command, msg: Message) -> Iterator[Violation]:
    """12.1: invalid parameters (EXEC-START-004) and a task not in tasks-available
    (EXEC-START-005, 5.3) are refused, not run."""
    if _refusal_due(unit, cmd, "EXEC-START-004"):
        yield violation("EXEC-START-004", msg, expected=f"'failed' for {cmd.describe()}, "
                        f"whose parameters break the task's specification (TASK-001)",
                        observed="'running'", path="$.response")
    if _refusal_due(unit, cmd, "EXEC-START-005"):
        yield violation("EXEC-START-005", msg, expected=f"'failed' for {cmd.describe()}: not "
                        f"in tasks-available ({', '.join(sorted(unit.tasks_available))})",
                        observed="'running'", path="$.response")


def _judge_query(unit: UnitState, c: Conversations, cmd: Command, msg: Message,
                 value: str | None) -> Iterator[Violation]:
    task = c.followed(cmd.task_uuid)
    last = latest(task) if task is not None else None
    if task is None or last is None or task.life != c.life:
        unit.note("EXEC-QUERY-001", "query-status only of tasks the traffic did not show")
        return
    if task.left_at is not None or (task.final is not None and task.final[0] not in
                                    QUERY_ANSWERS):
        return  # it ended without saying how: the traffic cannot tell what is right
    said_at, status = last
    if value == "unknown" and c.silent_until is not None and said_at < c.silent_until:
        unit.note("EXEC-QUERY-001", "'unknown' for a task from before a silence of the unit "
                                    "(a reboot keeping its agent-uuid is REBOOT-002's)")
        return
    allowed = QUERY_ANSWERS.get(status)
    if allowed is None:
        return  # a task-specific status: nothing to compare with
    unit.examine("EXEC-QUERY-001")
    if value not in allowed:
        yield violation("EXEC-QUERY-001", msg, expected=f"{' or '.join(allowed)}: task "
                        f"{task.task_uuid}'s latest feedback was '{status}'",
                        observed=f"response {value!r}", path="$.response",
                        detail="answer query-status from the task's whole history (12.1)")


def _judge_timing(ctx: CheckContext, unit: UnitState, cmd: Command, msg: Message
                  ) -> Generator[Violation, None, bool]:
    """12.1: an answer in time (EXEC-010, and the command's own rule for its first answer);
    returns whether it was in time."""
    waited, timeout = msg.time - cmd.last_sent, response_timeout(ctx)
    in_time = waited <= timeout
    if in_time:
        unit.examine("EXEC-010")
    elif ctx.gaps and ctx.in_gap(cmd.last_sent, msg.time):
        # The broker held or lost traffic meanwhile (an outage, a stall): when the unit
        # answered is unknown.
        unit.note("EXEC-010", OVER_A_GAP)
    else:
        # Late: how late is EXEC-010's finding; the command's own rule wanted it in time.
        yield violation("EXEC-010", msg, expected=f"an answer within {timeout:.1f} s (the "
                        f"profile's response_timeout)", observed=f"answered {waited:.2f} s "
                        f"after {cmd.describe()}", path="$.response-to",
                        detail="answer at once; a slow answer makes the commander resend")
        if cmd.answers == 1:
            # Answered after all: the command's rule found it late (a deadline the spec does
            # not give: a decided condition), no longer unanswered.
            rule = ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002")
            unit.examine(rule)
            yield dataclasses.replace(violation(
                rule, msg, expected=f"an answer to {cmd.describe()} within {timeout:.1f} s",
                observed=f"answered only after {waited:.2f} s", path="$.response-to"),
                condition="late", supersedes=cmd.com_uuid)
    return in_time


def _judge_resend_answer(unit: UnitState, c: Conversations, cmd: Command, msg: Message,
                         value: str | None, task_uuid: str | None) -> Iterator[Violation]:
    """12.1: a resend is answered again, with the same answer, and not executed again."""
    unit.examine("EXEC-RESEND-002")
    if cmd.name != "start-task" or not cmd.values:
        return
    unit.examine("EXEC-RESEND-001")
    first, first_task = cmd.values[0]
    if first != "running":
        return
    if value == "running" and task_uuid is not None and task_uuid != first_task:
        yield violation("EXEC-RESEND-001", msg, expected=f"the resent {cmd.describe()} "
                        f"executed once (task {first_task})", observed=f"started again as "
                        f"task {task_uuid}", path="$.task-uuid",
                        detail="12.1: remember com-uuids; answer a resend from memory")
    # A 'failed' answer ('A task is already running') refuses the resend: nothing ran twice
    # (12.1). It contradicts the first answer if the task runs on: the finding then
    # (EXEC-RESEND-003, decided; exec_feedback judges it by the task's later feedback).
    task = c.followed(first_task) if first_task is not None else None
    if task is None or task.final is not None:
        return
    unit.examine("EXEC-RESEND-003")
    if value == "failed":
        task.said_failed = (*task.said_failed, ("EXEC-RESEND-003", msg))[-2:]


def judge_unanswered(ctx: CheckContext, unit: UnitState, c: Conversations, cmd: Command
                     ) -> Iterator[Violation]:
    """A command the unit never answered fails its rule (12.1); a ping answered with another
    response-to is EXEC-PING-002's."""
    if not expects_answers(unit, c):
        unit.note(ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002"),
                  "commands seen, but the unit declares no 'direct execution' and answered none")
        return
    rule = ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002")
    timeout = response_timeout(ctx)
    if cmd.name == "ping":
        stray = next((r for tt, r in c.stray_pongs
                      if cmd.last_sent <= tt <= cmd.last_sent + timeout), None)
        if stray is not None:
            unit.examine("EXEC-PING-002")
            yield late("EXEC-PING-002", unit.address.topic("exec/command"), cmd,
                       f"a pong with response-to {cmd.com_uuid}",
                       f"a pong with response-to {stray}", cmd.last_sent,
                       "copy the command's com-uuid into response-to, unchanged (12.3)")
            return
    yield from left_unanswered(ctx, unit, rule, cmd, unit.address.topic("exec/command"),
                               "12.1: answer every command, 'failed' with a reason when it "
                               "cannot be executed")


@reinterprets("ERR-013", on=(TopicKind.EXEC_RESPONSE,), reads=(CONVERSATIONS,))
def signal_task_response_form(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                              found: list[Violation]) -> list[Violation]:
    """12.3.2 (signal-task response) is empty: the suite expects a start-task response's form
    and judges a response to a signal-task that misses it by ERR-013 (a warning by default),
    not by EXEC-002. Knowing what a response answers needs the command: stateful."""
    response_to = str_of(v.message, "response-to")
    c = unit.stash.get(CONVERSATIONS)
    if response_to is None or c is None:
        return found
    command = c.commands.get(response_to)
    if command is None or command.name != "signal-task":
        return found
    unit.examine("ERR-013")
    return [dataclasses.replace(
        f, rule="ERR-013", detail=f"answering signal-task {response_to}: 12.3.2 is empty; "
                                  f"the suite expects a start-task response's form "
                                  f"({f.detail or 'agent-uuid, com-uuid, response-to, response'})")
            if f.rule == "EXEC-002" else f for f in found]


@reinterprets("ERR-014", on=(TopicKind.EXEC_RESPONSE,), reads=(CONVERSATIONS,))
def no_task_named_no_task_uuid(ctx: CheckContext, unit: UnitState, msg: Message,
                               v: Validation, found: list[Violation]) -> list[Violation]:
    """12.1: a response names the task of the command it answers. ``task-uuid: ""`` answering
    a command that named no task (a malformed one, a ping) is no malformed id (ERR-014): there
    is no task to name (docs/FIELD-NOTES.md 'Precision': spec words). A started task must name one
    (EXEC-START-002's)."""
    m = v.message
    if not found or str_of(m, "task-uuid") != "":
        return found
    c = unit.stash.get(CONVERSATIONS)
    command = c.commands.get(str_of(m, "response-to") or "") if c is not None else None
    if command is None or command.task_uuid is not None or str_of(m, "response") == "running":
        return found
    unit.examine("ERR-014")
    return [f for f in found if not (f.rule == "ERR-014" and f.path == "$.task-uuid")]


@reinterprets("ERR-006", on=(TopicKind.EXEC_RESPONSE,), reads=(CONVERSATIONS,))
def success_answers_query_status(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation, found: list[Violation]) -> list[Violation]:
    """12.1 lists query-status's results as 'running, failed, success, unknown': 'success'
    answering query-status is the spec's own word (ERR-006's decision), and so is no finding
    there; answering another command it is out of place (the validator's warning stands). A
    response to a command not seen cannot tell: not judged."""
    if not found or str_of(v.message, "response") != "success":
        return found
    c = unit.stash.get(CONVERSATIONS)
    command = c.commands.get(str_of(v.message, "response-to") or "") if c is not None else None
    if command is not None and command.name != "query-status":
        unit.examine("ERR-006")
        return found
    if command is None:
        unit.note("ERR-006", "'success' answering a command not seen: not judged")
    else:
        unit.examine("ERR-006")
    return [f for f in found if f.rule != "ERR-006"]


@reinterprets("EXEC-007", on=(TopicKind.EXEC_RESPONSE,), reads=(CONVERSATIONS,))
def query_status_reports_a_status(ctx: CheckContext, unit: UnitState, msg: Message,
                                  v: Validation, found: list[Violation]) -> list[Violation]:
    """12.1: query-status 'return[s] the status of the task (running, failed, success,
    unknown)': a 'failed' answering it reports a task's status, it refuses nothing, so no
    fail-reason is owed (EXEC-007 is for a refused command). Knowing what a response answers
    needs the command: stateful; a response to a command not seen keeps the finding."""
    if not found or str_of(v.message, "response") != "failed":
        return found
    c = unit.stash.get(CONVERSATIONS)
    command = c.commands.get(str_of(v.message, "response-to") or "") if c is not None else None
    if command is None or command.name != "query-status":
        return found
    unit.examine("EXEC-007")
    return [f for f in found if f.rule != "EXEC-007"]

"""Conversations (spec 12; DESIGN 'Conversations, and whose fault it is'), judged from traffic.

A command on ``exec/command`` opens a conversation: its response (``response-to`` = its
com-uuid), then, for a started task, feedback until a final status; a resend (the same
com-uuid, the same content) belongs to the same conversation; query-status answers must agree
with what the traffic showed of the task. The same code judges a recording in ``lint`` and the
suite's own commands in ``pytest --unit``.

Blame goes to the root cause, so that one fault fails one rule:
- commands left unanswered are judged when the unit next answers a later command (each fails
  its command's rule) or at the end: a unit that answers none of two or more later commands of
  different kinds while it heartbeats went deaf (EXEC-ROBUST-001, naming the command before);
  a unit that died (HB-012) answers nothing, and its death is the finding;
- feedback after a final status that a resend caused is EXEC-RESEND-001's, not EXEC-FB-004's.

Everything is bounded: histories are LRUs, open expectations are capped and expire, and what
was dropped is counted and said in the report (``note``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections import OrderedDict
from collections.abc import Iterator
from typing import Any

import orjson

from conformance.checks.base import BoundedDict, CheckContext, UnitState, check, reinterprets
from conformance.message import Message
from conformance.status import meaning
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

COMMANDS_KEPT = 1024
"""Commands remembered per unit (resends, late answers, EXEC-006): at one a minute, 17 hours;
a few hundred bytes each, so a fleet of 200 units stays under about 100 MiB however long."""
TASKS_KEPT = 1024
PENDING_KEPT = 256
"""Commands awaiting an answer per unit; beyond it the oldest is dropped (and counted)."""
UNANSWERED_KEPT = 64
EXPECTS_KEPT = 64
STRAY_PONGS_KEPT = 8
FINAL_STATUSES = frozenset({"finished", "failed", "aborted"})  # 12.4
FEEDBACK_WITHOUT_TASK_UUID = "feedback-without-task-uuid"
"""UnitState.private key: the unit sent feedback without a task-uuid."""
_COM_UUID = re.compile(rb'"com-uuid"\s*:\s*"([^"\\]{1,100})"')

ANSWER_RULE = {"ping": "EXEC-PING-001", "start-task": "EXEC-START-001",
               "signal-task": "EXEC-SIG-001", "query-status": "EXEC-QUERY-001"}
"""The rule a command's missing or unfitting answer breaks; any other command (unknown or
malformed) should be answered 'failed': EXEC-ROBUST-002."""
MALFORMED = "(malformed)"
SIGNAL_FEEDBACK = {"$abort": ({"aborted"}, "EXEC-SIG-002"), "$enough": ({"finished"}, "EXEC-SIG-004"),
                   "$pause": ({"paused"}, "EXEC-SIG-003"), "$continue": ({"running"}, "EXEC-SIG-003")}
"""12.2.2: the feedback a signal answered 'ok' implies, and the rule it proves."""
QUERY_ANSWERS = {"running": ("running",), "paused": ("running", "paused"),
                 "finished": ("finished", "success"), "failed": ("failed",),
                 "aborted": ("failed", "aborted")}
"""12.1: what query-status may answer for a task whose latest feedback was this status
('success' is ERR-006's reading, judged by the validator; 'paused' and 'aborted' are 12.4's
words for what 12.1's list calls running and failed)."""


class Command:
    """One command sent to a unit, and what came back."""

    __slots__ = ("com_uuid", "name", "time", "last_sent", "sends", "answers", "values",
                 "task_uuid", "task_name", "signal", "sender", "excerpt", "digest", "invalid",
                 "life", "judged")

    def __init__(self, com_uuid: str, name: str, t: float, m: Any, digest: bytes,
                 excerpt: bytes, invalid: bool, life: str | None) -> None:
        self.com_uuid = com_uuid
        self.name = name
        self.time = self.last_sent = t
        self.sends = 1
        self.answers = 0
        self.values: list[tuple[str | None, str | None]] = []
        """(response, task-uuid) of each answer, at most 4."""
        self.task_uuid = _str(m, "task-uuid")
        task = m.get("task") if isinstance(m, dict) else None
        self.task_name = _str(task, "name")
        self.signal = _str(m, "signal")
        self.sender = _str(m, "sender")
        self.digest = digest
        self.excerpt = excerpt
        self.invalid = invalid
        """start-task whose parameters break the task's specification (TASK-001)."""
        self.life = life
        """The unit's agent-uuid when the command was sent."""
        self.judged = False

    def describe(self) -> str:
        what = self.name if self.name != MALFORMED else "a malformed command"
        if self.task_name:
            what += f" '{self.task_name}'"
        if self.signal:
            what += f" {self.signal}"
        return f"{what} (com-uuid {self.com_uuid})"


class Task:
    """One task of a unit as the traffic showed it (12.4)."""

    __slots__ = ("task_uuid", "name", "command", "life", "last_status", "last_time", "final",
                 "resent", "resend_failed", "listed", "left_at", "running_feedback")

    def __init__(self, task_uuid: str, name: str | None, command: Command | None,
                 life: str | None) -> None:
        self.task_uuid = task_uuid
        self.name = name
        self.command = command
        """The start-task that began it (None: the traffic showed only its feedback)."""
        self.life = life
        self.last_status: str | None = None
        self.last_time: float | None = None
        self.final: tuple[str, str | None, float] | None = None
        """(status, com-uuid, time) of its final feedback."""
        self.resent: float | None = None
        """When its start-task was last resent."""
        self.resend_failed: float | None = None
        """When a resend of its start-task was answered 'failed' (a contradiction)."""
        self.listed = False
        self.left_at: float | None = None
        """When it left tasks-executing (5.3) without a final feedback."""
        self.running_feedback = 0


class Expect:
    """Feedback a signal answered 'ok' implies (12.2.2), due by ``deadline``."""

    __slots__ = ("task_uuid", "wanted", "rule", "deadline", "command")

    def __init__(self, task_uuid: str, wanted: set[str], rule: str, deadline: float,
                 command: Command) -> None:
        self.task_uuid, self.wanted, self.rule = task_uuid, wanted, rule
        self.deadline, self.command = deadline, command


class Conversations:
    """What one unit was told and how it answered (bounded)."""

    def __init__(self) -> None:
        self.commands: BoundedDict = BoundedDict(COMMANDS_KEPT)
        self.pending: OrderedDict[str, Command] = OrderedDict()
        """Commands (and resends) awaiting an answer, oldest first."""
        self.unanswered: list[Command] = []
        """Commands that got no answer in time, judged when the unit next answers (or not)."""
        self.tasks: BoundedDict = BoundedDict(TASKS_KEPT)
        self.running: dict[str, Task] = {}
        """Tasks a start-task began in this life that have not ended (at most PENDING_KEPT)."""
        self.expects: list[Expect] = []
        self.stray_pongs: list[tuple[float, str]] = []
        self.answered_any = False
        self.life: str | None = None
        self.lives: list[str] = []
        self.first_command: float | None = None
        self.last_command: Command | None = None
        self.dropped = 0
        self.levels_reported: set[str] = set()
        self.silent_until: float | None = None
        """The end of the latest heartbeat silence over 2 periods: perhaps a reboot that kept
        its agent-uuid, whose history loss is REBOOT-002's to judge, not EXEC-QUERY-001's."""

    def started(self, task: Task) -> None:
        self.running[task.task_uuid] = task
        if len(self.running) > PENDING_KEPT:
            del self.running[next(iter(self.running))]
            self.dropped += 1

    def ended(self, task: Task, final: tuple[str, str | None, float]) -> None:
        task.final = final
        self.running.pop(task.task_uuid, None)


def per_unit(unit: UnitState, key: str, make: Any) -> Any:
    """The unit's conversation state under ``key``, made on first use and starting in the
    unit's current life (its agent-uuid): exec and TST conversations alike."""
    c = unit.private.get(key)
    if c is None:
        c = unit.private[key] = make()
        c.life = unit.agent_uuid
        if c.life is not None:
            c.lives.append(c.life)
    return c


def conversations(unit: UnitState) -> Conversations:
    return per_unit(unit, "conversations", Conversations)  # type: ignore[no-any-return]


def last_command_before(unit: UnitState, t: float) -> Command | None:
    """The latest command sent to the unit at or before ``t`` (for HB-012's finding)."""
    c = unit.private.get("conversations")
    if c is None:
        return None
    found = None
    for cmd in c.commands.values():
        if cmd.last_sent <= t and (found is None or cmd.last_sent >= found.last_sent):
            found = cmd
    return found


def _str(m: Any, key: str) -> str | None:
    x = m.get(key) if isinstance(m, dict) else None
    return x if isinstance(x, str) else None


def _timeout(ctx: CheckContext) -> float:
    return ctx.profile.response_timeout


def _expects_answers(unit: UnitState, c: Conversations) -> bool:
    """12.1: a unit answers commands when it declares direct execution or has answered any."""
    return c.answered_any or unit.claims("direct execution")


# --- commands -----------------------------------------------------------------------------------

@check("EXEC-008", "EXEC-010", on=(TopicKind.EXEC_COMMAND,))
def command_opens_conversation(ctx: CheckContext, unit: UnitState, msg: Message,
                               v: Validation) -> Iterator[Violation]:
    """Every command with a readable com-uuid opens (or, resent, continues) a conversation.
    2: 'Use UUID to identify a communication message'; 12.1 resends reuse it for the same
    command, so the same com-uuid with other content makes a resend ambiguous (EXEC-008, the
    commander's)."""
    m = v.message
    com_uuid = _str(m, "com-uuid")
    if com_uuid is None and m is None:
        # A command that is not JSON may still carry a readable com-uuid, and a robust unit
        # answers it 'failed' (EXEC-ROBUST-002).
        found = _COM_UUID.search(msg.payload if isinstance(msg.payload, bytes) else b"")
        com_uuid = found.group(1).decode("utf-8", "replace") if found else None
        content = bytes(msg.payload)
    else:
        content = orjson.dumps(m, option=orjson.OPT_SORT_KEYS) if com_uuid else b""
    if com_uuid is None:
        return
    c = conversations(unit)
    t = msg.time
    if c.first_command is None:
        c.first_command = t
    unit.examine("EXEC-008")
    # Kept: a digest of the content and its first 120 bytes, not the content (a command may
    # be 1 MiB, and 4096 are kept per unit).
    digest = hashlib.blake2b(content, digest_size=16).digest()
    before = c.commands.get(com_uuid)
    if before is not None and before.digest == digest:
        # 12.1: a resend. It is answered again and not executed again.
        before.sends += 1
        before.last_sent = t
        c.commands[com_uuid] = before
        _await(c, before)
        if before.name == "start-task":
            task = _task_of(c, before)
            if task is not None:
                task.resent = t
        c.last_command = before
        return
    if before is not None:
        # Ambiguous from here on: an answer with this response-to may be to either command.
        # The commander's fault (EXEC-008); the unit is not judged on what it cannot tell.
        before.judged = True
        before.digest = digest
        c.pending.pop(com_uuid, None)
        c.commands[com_uuid] = before
        yield Violation.of(
            "EXEC-008", expected=f"com-uuid {com_uuid} reused only to resend the same command",
            observed=f"other content than the command sent {t - before.time:.2f} s earlier: "
                     f"{before.excerpt.decode('utf-8', 'replace')}",
            topic=msg.topic, path="$.com-uuid", time=t, payload=msg.payload,
            detail="generate a fresh com-uuid for every new command")
        return
    name = _str(m, "command")
    # Not a readable command: what remains is to refuse it (EXEC-ROBUST-002). A known command
    # the schema finds fault with (a non-standard signal, a task as a string) keeps its rule.
    if not isinstance(m, dict) or not name or any(
            f.rule in ("MSG-002", "MSG-003", "MSG-004") for f in v.violations):
        name = MALFORMED
    invalid = name == "start-task" and any(f.rule == "TASK-001" for f in v.violations)
    cmd = Command(com_uuid, name, t, m, digest, bytes(memoryview(content)[:120]), invalid,
                  c.life)
    c.commands[com_uuid] = cmd
    c.last_command = cmd
    _await(c, cmd)
    if name == "start-task" and cmd.task_uuid is not None:
        c.tasks.pop(cmd.task_uuid, None)  # a start-task naming a task-uuid begins it anew


def _await(c: Conversations, cmd: Command) -> None:
    c.pending.pop(cmd.com_uuid, None)
    c.pending[cmd.com_uuid] = cmd
    if len(c.pending) > PENDING_KEPT:
        c.pending.popitem(last=False)
        c.dropped += 1


def _task_of(c: Conversations, cmd: Command) -> Task | None:
    for value, task_uuid in cmd.values:
        if value == "running" and task_uuid is not None:
            return c.tasks.get(task_uuid)  # type: ignore[no-any-return]
    return c.tasks.get(cmd.task_uuid) if cmd.task_uuid else None  # type: ignore[no-any-return]


# --- responses ----------------------------------------------------------------------------------

@check("EXEC-006", "EXEC-009", "EXEC-010", "EXEC-PING-001", "EXEC-PING-002", "EXEC-START-001",
       "EXEC-START-002", "EXEC-START-004", "EXEC-START-005", "EXEC-SIG-001", "EXEC-QUERY-001",
       "EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-ROBUST-002", on=(TopicKind.EXEC_RESPONSE,))
def response_answers_command(ctx: CheckContext, unit: UnitState, msg: Message,
                             v: Validation) -> Iterator[Violation]:
    """12.1, 12.3: a response answers a command (response-to = its com-uuid), once, in time,
    with a value that fits the command."""
    m = v.message
    response_to = _str(m, "response-to")
    if response_to is None:
        return
    c = conversations(unit)
    t = msg.time
    cmd = c.commands.get(response_to)
    if cmd is None:
        yield from _answers_nothing(ctx, unit, c, msg, m, response_to)
        return
    unit.examine("EXEC-006")
    c.answered_any = True
    if cmd.judged:
        return
    cmd.answers += 1
    value, task_uuid = _str(m, "response"), _str(m, "task-uuid")
    if len(cmd.values) < 4:
        cmd.values.append((value, task_uuid))
    if cmd.answers >= cmd.sends:
        c.pending.pop(cmd.com_uuid, None)
    late = cmd in c.unanswered
    if late:
        c.unanswered.remove(cmd)
    if cmd.answers > cmd.sends:
        yield _violation("EXEC-009", msg, expected=f"one answer to {cmd.describe()} per time it "
                         f"was sent ({cmd.sends})", observed=f"answer number {cmd.answers}",
                         path="$.response-to", detail="answer each command once; a resend "
                         "again, with the same answer")
        return
    unit.examine("EXEC-009")
    waited = t - cmd.last_sent
    if waited > _timeout(ctx):
        # Late: how late is EXEC-010's finding; the command's own rule wanted it in time.
        yield _violation("EXEC-010", msg, expected=f"an answer within {_timeout(ctx):.1f} s "
                         f"(the profile's response_timeout)", observed=f"answered "
                         f"{waited:.2f} s after {cmd.describe()}", path="$.response-to",
                         detail="answer at once; a slow answer makes the commander resend")
        if cmd.answers == 1:
            rule = ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002")
            unit.examine(rule)
            yield _violation(rule, msg, expected=f"an answer to {cmd.describe()} within "
                             f"{_timeout(ctx):.1f} s", observed=f"answered only after "
                             f"{waited:.2f} s", path="$.response-to")
            yield from _judge_unanswered(ctx, unit, c, before=cmd.last_sent)
            return
    else:
        unit.examine("EXEC-010")
    if cmd.answers == 1:
        # The unit answers: commands it left unanswered before this one were its own faults.
        yield from _judge_unanswered(ctx, unit, c, before=cmd.last_sent)
        yield from _judge_first_answer(ctx, unit, c, cmd, msg, value, task_uuid)
    else:
        yield from _judge_resend_answer(unit, c, cmd, msg, value, task_uuid)


def _answers_nothing(ctx: CheckContext, unit: UnitState, c: Conversations, msg: Message,
                     m: Any, response_to: str) -> Iterator[Violation]:
    """EXEC-006: a response to no command seen. Judged only when the observer saw this unit's
    commands, and not in the first response timeout (it may answer one sent before)."""
    if _str(m, "response") == "pong":
        c.stray_pongs.append((msg.time, response_to))
        del c.stray_pongs[:-STRAY_PONGS_KEPT]
    if c.first_command is None:
        unit.note("EXEC-006", f"no command seen on {unit.address.topic('exec/command')}: "
                              f"subscribe to it to judge responses")
        return
    if ctx.started is not None and msg.time - ctx.started < _timeout(ctx):
        unit.note("EXEC-006", "responses in the first response-timeout of the observation "
                              "may answer commands sent before it")
        return
    if c.commands.evicted:
        return  # it may answer a command older than the ones kept: cannot tell
    unit.examine("EXEC-006")
    yield _violation("EXEC-006", msg, expected=f"response-to = the com-uuid of a command sent "
                     f"to {unit.address.name}", observed=f"response-to {response_to}: no such "
                     f"command seen", path="$.response-to",
                     detail="copy the command's com-uuid into response-to (12.3)")


def _judge_first_answer(ctx: CheckContext, unit: UnitState, c: Conversations, cmd: Command,
                        msg: Message, value: str | None, task_uuid: str | None
                        ) -> Iterator[Violation]:
    """The first answer fits its command (12.1, 12.3)."""
    rule = ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002")
    t = msg.time
    if cmd.name == "ping":
        unit.examine("EXEC-PING-002")  # matched by its response-to
        if value == "pong":
            unit.examine(rule)
        else:
            yield _violation(rule, msg, expected=f"'pong' answering {cmd.describe()}",
                             observed=f"response {value!r}", path="$.response")
    elif cmd.name == "start-task":
        if value in ("running", "failed"):
            unit.examine(rule)
        else:
            yield _violation(rule, msg, expected=f"'running' or 'failed' answering "
                             f"{cmd.describe()}", observed=f"response {value!r}",
                             path="$.response", detail="12.3.3: a start-task is answered "
                             "'running', or 'failed' with a fail-reason")
        yield from _judge_task_uuid(unit, cmd, msg, value, task_uuid)
        if value == "running":
            yield from _judge_refusals(unit, cmd, msg)
            started = task_uuid or cmd.task_uuid
            if started is not None:
                task = c.tasks.get(started)
                if task is None or task.command is not None:
                    task = c.tasks[started] = Task(started, cmd.task_name, cmd, c.life)
                task.command, task.name = cmd, cmd.task_name  # its feedback may come first
                if task.final is None:
                    c.started(task)
        elif value == "failed":
            for r in ("EXEC-START-004", "EXEC-START-005"):
                if _refusal_due(unit, cmd, r):
                    unit.examine(r)
    elif cmd.name == "signal-task":
        unit.examine(rule)  # answered; its vocabulary is EXEC-003's (or ERR-013's)
        expected = SIGNAL_FEEDBACK.get(cmd.signal or "")
        task = c.tasks.get(cmd.task_uuid) if cmd.task_uuid else None
        if value == "ok" and expected and task is not None and task.final is None \
                and task.life == c.life:
            if len(c.expects) < EXPECTS_KEPT:
                c.expects.append(Expect(task.task_uuid, expected[0], expected[1],
                                        t + ctx.profile.feedback_timeout, cmd))
            else:
                c.dropped += 1
    elif cmd.name == "query-status":
        yield from _judge_query(unit, c, cmd, msg, value)
    else:  # unknown or malformed: 'failed' with a reason (12.1)
        if value == "failed":
            unit.examine(rule)
        else:
            yield _violation(rule, msg, expected=f"'failed' answering {cmd.describe()}",
                             observed=f"response {value!r}", path="$.response",
                             detail="refuse what you cannot execute, with a fail-reason")


def _judge_task_uuid(unit: UnitState, cmd: Command, msg: Message, value: str | None,
                     task_uuid: str | None) -> Iterator[Violation]:
    """12.1: the start-task response carries the task-uuid sent, or one the unit generated."""
    if cmd.task_uuid is not None:
        if task_uuid == cmd.task_uuid:
            unit.examine("EXEC-START-002")
        else:
            yield _violation("EXEC-START-002", msg, expected=f"task-uuid {cmd.task_uuid} (sent "
                             f"in {cmd.describe()})", observed=f"task-uuid {task_uuid!r}",
                             path="$.task-uuid", detail="return the task-uuid the commander "
                             "sent (12.1)")
    elif value == "running":
        if task_uuid:
            unit.examine("EXEC-START-002")
        else:
            yield _violation("EXEC-START-002", msg, expected=f"a generated task-uuid "
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
        yield _violation("EXEC-START-004", msg, expected=f"'failed' for {cmd.describe()}, "
                         f"whose parameters break the task's specification (TASK-001)",
                         observed="'running'", path="$.response")
    if _refusal_due(unit, cmd, "EXEC-START-005"):
        yield _violation("EXEC-START-005", msg, expected=f"'failed' for {cmd.describe()}: not "
                         f"in tasks-available ({', '.join(sorted(unit.tasks_available))})",
                         observed="'running'", path="$.response")


def _judge_query(unit: UnitState, c: Conversations, cmd: Command, msg: Message,
                 value: str | None) -> Iterator[Violation]:
    task = c.tasks.get(cmd.task_uuid) if cmd.task_uuid else None
    if task is None or task.last_status is None or task.life != c.life:
        unit.note("EXEC-QUERY-001", "query-status only of tasks the traffic did not show")
        return
    if task.left_at is not None or (task.final is not None and task.final[0] not in
                                    QUERY_ANSWERS):
        return  # it ended without saying how: the traffic cannot tell what is right
    if (value == "unknown" and c.silent_until is not None and task.last_time is not None
            and task.last_time < c.silent_until):
        unit.note("EXEC-QUERY-001", "'unknown' for a task from before a silence of the unit "
                                    "(a reboot keeping its agent-uuid is REBOOT-002's)")
        return
    allowed = QUERY_ANSWERS.get(task.last_status)
    if allowed is None:
        return  # a task-specific status: nothing to compare with
    unit.examine("EXEC-QUERY-001")
    if value not in allowed:
        yield _violation("EXEC-QUERY-001", msg, expected=f"{' or '.join(allowed)}: task "
                         f"{task.task_uuid}'s latest feedback was '{task.last_status}'",
                         observed=f"response {value!r}", path="$.response",
                         detail="answer query-status from the task's whole history (12.1)")


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
        yield _violation("EXEC-RESEND-001", msg, expected=f"the resent {cmd.describe()} "
                         f"executed once (task {first_task})", observed=f"started again as "
                         f"task {task_uuid}", path="$.task-uuid",
                         detail="12.1: remember com-uuids; answer a resend from memory")
    elif value == "failed":
        task = c.tasks.get(first_task) if first_task else None
        if task is not None and task.final is None:
            task.resend_failed = msg.time
        yield _violation("EXEC-RESEND-001", msg, expected=f"the first answer again ('running', "
                         f"task {first_task}) to the resent {cmd.describe()}",
                         observed="'failed', although the task runs", path="$.response",
                         detail="12.1: a resend is the same command; answer it as before, "
                         "do not execute it again")


# --- feedback -----------------------------------------------------------------------------------

@check("EXEC-FB-004", "EXEC-START-003", "EXEC-SIG-002", "EXEC-SIG-003", "EXEC-SIG-004",
       "EXEC-RESEND-001", on=(TopicKind.EXEC_FEEDBACK,))
def feedback_follows_task(ctx: CheckContext, unit: UnitState, msg: Message,
                          v: Validation) -> Iterator[Violation]:
    """12.4: feedback follows a task to one final status (finished, failed, aborted), and
    nothing follows that (a repeated delivery of the final message, same com-uuid, is no new
    feedback)."""
    m = v.message
    task_uuid, status = _str(m, "task-uuid"), _str(m, "status")
    status = meaning(status) or status  # 'done' ends a task as 'finished' (EXEC-FB-002's word)
    if task_uuid is None or status is None:
        if status is not None:  # which task it ends cannot be told (EXEC-FB-001's finding)
            unit.private[FEEDBACK_WITHOUT_TASK_UUID] = True
        return
    c = conversations(unit)
    t = msg.time
    unit.examine("EXEC-FB-004")
    task = c.tasks.get(task_uuid)
    if task is None:
        task = c.tasks[task_uuid] = Task(task_uuid, None, None, c.life)
    if task.final is not None:
        end_status, end_com_uuid, end_time = task.final
        if _str(m, "com-uuid") == end_com_uuid:
            return
        again = task.resent is not None and task.resent > end_time  # resent after it ended
        rule = "EXEC-RESEND-001" if again else "EXEC-FB-004"
        yield _violation(rule, msg, expected=f"no feedback for task {task_uuid} after its final "
                         f"status '{end_status}'", observed=f"status '{status}' "
                         f"{t - end_time:.2f} s later" + (" (after its start-task was resent: "
                                                          "executed again)" if again else ""),
                         path="$.status", detail="stop sending feedback once a task is "
                         "finished, failed or aborted")
        return
    if (status == "failed" and task.resend_failed is not None
            and t - task.resend_failed <= _timeout(ctx)):
        # The unit said the resend 'failed' and fails the task in feedback too, though it runs
        # on: one fault of resend handling, not the task's end.
        yield _violation("EXEC-RESEND-001", msg, expected=f"no 'failed' feedback for task "
                         f"{task_uuid}, which runs on", observed="'failed' feedback answering "
                         "the resent start-task", path="$.status",
                         detail="12.1: a resend must not touch the running task")
        return
    if status == "running":
        if task.running_feedback and task.last_status == "running" and task.resent is not None:
            yield _violation("EXEC-RESEND-001", msg, expected=f"task {task_uuid} started once",
                             observed="a new 'running' after its start-task was resent",
                             path="$.status", detail="12.1: a resend is answered from memory, "
                             "not executed again")
        task.running_feedback += 1
    task.last_status, task.last_time = status, t
    for e in [e for e in c.expects if e.task_uuid == task_uuid]:
        if status in e.wanted:
            unit.examine(e.rule)
            c.expects.remove(e)
        elif status in FINAL_STATUSES:
            c.expects.remove(e)
            unit.examine(e.rule)
            yield _violation(e.rule, msg, expected=f"{' or '.join(sorted(e.wanted))} after "
                             f"{e.command.describe()} was answered 'ok'",
                             observed=f"status '{status}'", path="$.status")
    if status in FINAL_STATUSES:
        c.ended(task, (status, _str(m, "com-uuid"), t))
        if task.command is not None:
            unit.examine("EXEC-START-003")


# --- what the unit publishes about its tasks and itself ----------------------------------------

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
            task.listed, task.left_at = True, None
            if n > 1 and task.resent is not None:
                unit.examine("EXEC-RESEND-001")
                task.resent = None  # said once
                found = [_violation("EXEC-RESEND-001", msg, expected=f"task {task.task_uuid} "
                                    f"once in tasks-executing", observed=f"listed {n} times "
                                    f"after its start-task was resent",
                                    path="$.tasks-executing")]
        elif task.listed and task.left_at is None:
            task.left_at = msg.time
    return found


@check("HB-013", on=(TopicKind.DIRECT_EXECUTION_INFO, TopicKind.EXEC_RESPONSE,
                     TopicKind.EXEC_FEEDBACK, TopicKind.SENSOR_INFO, TopicKind.TST_EXECUTION_INFO,
                     TopicKind.TST_RESPONSE, TopicKind.TST_FEEDBACK))
def acted_on_level_is_declared(ctx: CheckContext, unit: UnitState, msg: Message,
                               v: Validation) -> list[Violation] | None:
    """5.1: levels say what a unit does; one that acts on a level it does not declare is
    passed over by every commander that reads them (HB-013, once per level)."""
    levels = unit.levels
    if levels is None:
        return None
    level = _LEVEL_OF_KIND[v.topic.kind]
    if level in levels:
        unit.examine("HB-013")
        return None
    c = conversations(unit)
    if level in c.levels_reported:
        return None
    c.levels_reported.add(level)
    unit.examine("HB-013")
    return [_violation("HB-013", msg, expected=f"'{level}' in the heartbeat's levels "
                       f"({', '.join(levels) or 'none declared'})",
                       observed=f"{v.topic.kind.value} published", path="$",
                       detail=f"declare '{level}' in levels, or do not act on it")]


_LEVEL_OF_KIND = {
    TopicKind.DIRECT_EXECUTION_INFO: "direct execution", TopicKind.EXEC_RESPONSE:
    "direct execution", TopicKind.EXEC_FEEDBACK: "direct execution",
    TopicKind.SENSOR_INFO: "sensor", TopicKind.TST_EXECUTION_INFO: "tst execution",
    TopicKind.TST_RESPONSE: "tst execution", TopicKind.TST_FEEDBACK: "tst execution"}


# --- deadlines: judged on the unit's heartbeats and at the end ----------------------------------

@check("EXEC-RESEND-002", "EXEC-START-003", "EXEC-SIG-002", on=(TopicKind.HEARTBEAT,))
def deadlines_pass(ctx: CheckContext, unit: UnitState, msg: Message,
                   v: Validation) -> list[Violation] | None:
    """Deadlines are checked on each heartbeat of the unit (and at the end): answers due,
    feedback a signal implies, final feedback of a task that left tasks-executing. A new
    agent-uuid is a new life: what the old one left open is not judged (the reboot lost it).
    (Runs on every heartbeat: cheap when nothing is open.)"""
    c = unit.private.get("conversations")
    if c is None:
        return None
    m = v.message
    agent = m.get("agent-uuid") if type(m) is dict else None
    if agent != c.life and type(agent) is str and not msg.retain:
        found = _new_life(ctx, unit, c, agent, msg.time) if c.life is not None else None
        c.life = agent
        if agent not in c.lives:
            c.lives.append(agent)
            del c.lives[:-8]
        return found
    last, period = unit.last_heartbeat, unit.period(TopicKind.HEARTBEAT)
    if (last is not None and period is not None and not unit.heartbeat_retained
            and msg.time - last > 2 * period):
        c.silent_until = msg.time
    if not (c.pending or c.expects or c.running):
        return None
    return _expire(ctx, unit, c, msg.time) or None


def _new_life(ctx: CheckContext, unit: UnitState, c: Conversations, agent: str, t: float
              ) -> list[Violation] | None:
    if agent in c.lives:
        return None  # an earlier uuid again: two agents under one name (HB-011), no reboot
    from conformance.checks.identity import SILENCE_PERIODS, heartbeat_period

    # Down for more than 3 periods before this life began: what it left unanswered since it
    # went silent is the silence's (HB-010, HB-012), not each command's.
    last, period = unit.last_heartbeat, heartbeat_period(unit)
    dead_since = (last - period if last is not None and period
                  and t - last > SILENCE_PERIODS * period else None)
    found = _expire(ctx, unit, c, float("inf"), reboot=True, dead_since=dead_since)
    c.running.clear()  # what the old life ran is not judged (the reboot lost it)
    c.expects.clear()
    return found


def overdue(c: Any, now: float, timeout: float, reboot: bool) -> list[Any]:
    """Take the commands whose answer deadline has passed (at a reboot: all) off
    ``c.pending``. Those never answered join ``c.unanswered``, to be judged when the unit next
    answers or at the end; those answered fewer times than sent (a resend left unanswered) are
    returned. ``c`` is an exec or a TST conversation (``pending``, ``unanswered``, ``dropped``)."""
    resent: list[Any] = []
    while c.pending:
        cmd = next(iter(c.pending.values()))
        if cmd.last_sent + timeout >= now and not reboot:
            break
        c.pending.popitem(last=False)
        if cmd.judged:
            continue
        if cmd.answers == 0:
            c.unanswered.append(cmd)
            if len(c.unanswered) > UNANSWERED_KEPT:
                c.unanswered.pop(0)
                c.dropped += 1
        elif cmd.answers < cmd.sends:
            resent.append(cmd)
    return resent


def _expire(ctx: CheckContext, unit: UnitState, c: Conversations, now: float,
            reboot: bool = False, dead_since: float | None = None) -> list[Violation]:
    found: list[Violation] = []
    timeout = _timeout(ctx)
    for cmd in overdue(c, now, timeout, reboot):
        unit.examine("EXEC-RESEND-002")
        found.append(_late("EXEC-RESEND-002", unit, cmd, f"a second answer to the resent "
                           f"{cmd.describe()} within {timeout:.1f} s", "none", cmd.last_sent,
                           "12.1: answer a resend again, with the first answer"))
    if reboot:
        found.extend(_judge_streak(ctx, unit, c, ended_by="a reboot", dead_since=dead_since))
    for e in list(c.expects):
        if e.deadline < now or reboot:
            c.expects.remove(e)
            if reboot:
                continue
            unit.examine(e.rule)
            task = c.tasks.get(e.task_uuid)
            said = task.last_status if task is not None else None
            found.append(_late(e.rule, unit, e.command, f"{' or '.join(sorted(e.wanted))} "
                               f"within {ctx.profile.feedback_timeout:.1f} s of the 'ok' to "
                               f"{e.command.describe()}", f"latest status {said!r}",
                               e.command.last_sent, "12.2.2: do what the signal says, and "
                               "say so in feedback"))
    for task in list(c.running.values()):
        if task.left_at is not None and task.left_at + timeout < now:
            c.ended(task, ("left tasks-executing", None, task.left_at))
            if unit.private.get(FEEDBACK_WITHOUT_TASK_UUID):
                continue  # its final feedback may be one without task-uuid
            unit.examine("EXEC-START-003")
            found.append(_late("EXEC-START-003", unit, task.command, f"a final feedback for "
                               f"task {task.task_uuid} (finished, failed or aborted)",
                               f"it left tasks-executing at {task.left_at:.3f} with none "
                               f"(latest status {task.last_status!r})", task.left_at,
                               "12.4: send feedback with the final status when a task ends"))
    return found


def _judge_unanswered(ctx: CheckContext, unit: UnitState, c: Conversations, *,
                      before: float) -> Iterator[Violation]:
    """Commands left unanswered that were sent before an answered one: each fails its rule."""
    if not c.unanswered:
        return
    keep = []
    for cmd in c.unanswered:
        if cmd.last_sent <= before:
            yield from _unanswered(ctx, unit, c, cmd)
        else:
            keep.append(cmd)
    c.unanswered = keep


def _unanswered(ctx: CheckContext, unit: UnitState, c: Conversations, cmd: Command
                ) -> Iterator[Violation]:
    if not _expects_answers(unit, c):
        unit.note(ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002"),
                  "commands seen, but the unit declares no 'direct execution' and answered none")
        return
    rule = ANSWER_RULE.get(cmd.name, "EXEC-ROBUST-002")
    timeout = _timeout(ctx)
    if cmd.name == "ping":
        stray = next((r for tt, r in c.stray_pongs
                      if cmd.last_sent <= tt <= cmd.last_sent + timeout), None)
        if stray is not None:
            unit.examine("EXEC-PING-002")
            yield _late("EXEC-PING-002", unit, cmd, f"a pong with response-to {cmd.com_uuid}",
                        f"a pong with response-to {stray}", cmd.last_sent,
                        "copy the command's com-uuid into response-to, unchanged (12.3)")
            return
    unit.examine(rule)
    yield _late(rule, unit, cmd, f"an answer to {cmd.describe()} within {timeout:.1f} s",
                "no answer", cmd.last_sent, "12.1: answer every command, 'failed' with a "
                "reason when it cannot be executed")


def _judge_streak(ctx: CheckContext, unit: UnitState, c: Conversations, *, ended_by: str,
                  dead_since: float | None = None) -> list[Violation]:
    """The commands still unanswered when the life (or the observation) ends."""
    streak, c.unanswered = c.unanswered, []
    if dead_since is not None:
        died = [cmd for cmd in streak if cmd.last_sent >= dead_since]
        if died:
            unit.note(ANSWER_RULE.get(died[0].name, "EXEC-ROBUST-002"),
                      f"{len(died)} command(s) sent while the unit was dying or dead (HB-012)")
        streak = [cmd for cmd in streak if cmd.last_sent < dead_since]
    kinds = {cmd.name for cmd in streak}
    if len(streak) >= 2 and len(kinds) >= 2 and _expects_answers(unit, c):
        first = streak[0]
        before = [cmd for cmd in c.commands.values() if cmd.last_sent < first.last_sent]
        cause = max(before, key=lambda cmd: cmd.last_sent) if before else None
        named = first if first.name == MALFORMED or cause is None else cause
        unit.examine("EXEC-ROBUST-001")
        return [_late("EXEC-ROBUST-001", unit, first, f"answers to commands after "
                      f"{named.describe()}", f"none of the next {len(streak)} commands "
                      f"({', '.join(sorted(kinds))}) answered until {ended_by}", first.last_sent,
                      f"the unit stopped answering after {named.describe()}; it must "
                      f"survive any command (12.1)")]
    return [v for cmd in streak for v in _unanswered(ctx, unit, c, cmd)]


@check("EXEC-ROBUST-001", "EXEC-START-003", finish=True)
def conversations_at_end(ctx: CheckContext, unit: UnitState, now: float,
                         findings: Any) -> Iterator[Violation]:
    """At the end: answers still due are judged (a unit that died is HB-012's finding);
    tasks still running are not judged; what the bounds dropped is said.
    (Pure: works on a copy, so a provisional report changes nothing.)"""
    from copy import deepcopy

    from conformance.checks.identity import death

    original = unit.private.get("conversations")
    if original is None:
        return
    c = deepcopy(original)
    scratch = dataclasses.replace(unit, examined={}, notes={}, private={**unit.private,
                                                                      "conversations": c})
    found = _expire(ctx, scratch, c, now)
    dead = death(ctx, unit, now)
    found += _judge_streak(ctx, scratch, c, ended_by="the end of the observation",
                           dead_since=dead[0] if dead else None)
    running = [t for t in c.running.values() if t.left_at is None and t.life == c.life]
    if running:
        scratch.note("EXEC-START-003", f"{len(running)} task(s) still running when the "
                                       f"observation ended: not judged")
    if c.dropped:
        scratch.note("EXEC-ROBUST-001", f"{c.dropped} open expectations dropped (bounded "
                                        f"memory): not judged")
    for rule, n in scratch.examined.items():
        findings.examine(rule, n)
    for rule, why in scratch.notes.items():
        findings.note(rule, why)
    yield from found


def dropped(unit: UnitState) -> int:
    """Open expectations dropped for bounded memory (said in the report)."""
    c = unit.private.get("conversations")
    return c.dropped if c is not None else 0


# --- helpers ----------------------------------------------------------------------------------

def _violation(rule: str, msg: Message, *, expected: str, observed: str, path: str,
               detail: str = "") -> Violation:
    return Violation.of(rule, expected=expected, observed=observed, topic=msg.topic, path=path,
                        time=msg.time, payload=msg.payload, detail=detail)


def _late(rule: str, unit: UnitState, cmd: Command | None, expected: str, observed: str,
          t: float, detail: str) -> Violation:
    """A violation found when a deadline passed: its evidence is the command."""
    return Violation.of(rule, expected=expected, observed=observed,
                        topic=unit.address.topic("exec/command"), path="$", time=t,
                        payload=cmd.excerpt if cmd is not None else None, detail=detail)


@reinterprets("ERR-013", on=(TopicKind.EXEC_RESPONSE,))
def signal_task_response_form(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                              found: list[Violation]) -> list[Violation]:
    """12.3.2 (signal-task response) is empty: the suite expects a start-task response's form
    and judges a response to a signal-task that misses it by ERR-013 (a warning by default),
    not by EXEC-002. Knowing what a response answers needs the command: stateful."""
    response_to = _str(v.message, "response-to")
    c = unit.private.get("conversations")
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


@reinterprets("TASK-002", on=(TopicKind.EXEC_COMMAND,))
def task_the_unit_offers(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                         found: list[Violation]) -> list[Violation]:
    """9.12: tasks are vehicle-type specific beyond section 9; a start-task of a task the unit
    itself lists in tasks-available (5.3) is no unknown task (TASK-002 is for names no one
    offers). Knowing what the unit offers needs its history: stateful."""
    if not found or not unit.tasks_available:
        return found
    task = v.message.get("task") if isinstance(v.message, dict) else None
    name = _str(task, "name")
    if name is None or name not in unit.tasks_available:
        return found
    unit.examine("TASK-002")
    return [f for f in found if f.rule != "TASK-002"]

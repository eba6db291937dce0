"""A command on exec/command opens a conversation, or continues one when resent (12.1).

EXEC-008 (the commander's): 2 'Use UUID to identify a communication message', so the same
com-uuid with other content makes a resend ambiguous. The conversation state is
``conversation``'s; the answers are judged by ``exec_response``.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterator

import orjson

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import str_of
from conformance.checks.conversation import (
    CONVERSATIONS,
    MALFORMED,
    Command,
    Conversations,
    conversations,
)
from conformance.checks.registry import check, reinterprets
from conformance.message import Message
from conformance.taskrecord import TaskRecord
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation, head

_COM_UUID = re.compile(rb'"com-uuid"\s*:\s*"([^"\\]{1,100})"')


@check("EXEC-008", "EXEC-010", on=(TopicKind.EXEC_COMMAND,), reads=(CONVERSATIONS,))
def command_opens_conversation(ctx: CheckContext, unit: UnitState, msg: Message,
                               v: Validation) -> Iterator[Violation]:
    """Every command with a readable com-uuid opens (or, resent, continues) a conversation.
    2: 'Use UUID to identify a communication message'; 12.1 resends reuse it for the same
    command, so the same com-uuid with other content makes a resend ambiguous (EXEC-008, the
    commander's)."""
    m = v.message
    com_uuid, content = _com_uuid_and_content(msg, m)
    if com_uuid is None:
        return
    c = conversations(unit, ctx)
    t = msg.time
    if c.first_command is None:
        c.first_command = t
    unit.examine("EXEC-008")
    # Kept: a digest of the content and its first 120 bytes, not the content (a command may
    # be 1 MiB, and COMMANDS_KEPT are kept per unit).
    digest = hashlib.blake2b(content, digest_size=16).digest()
    before = c.commands.get(com_uuid)
    if before is not None and before.digest == digest:
        # 12.1: a resend. It is answered again and not executed again.
        c.resent(before, t)
        if before.name == "start-task":
            task = _task_of(c, before)
            if task is not None:
                task.resent = t
        c.last_command = before
        return
    if before is not None:
        yield _reused(c, before, digest, msg)
        return
    name = str_of(m, "command")
    # Not a readable command: what remains is to refuse it (EXEC-ROBUST-002). A known command
    # the schema finds fault with (a non-standard signal, invalid parameters) keeps its rule;
    # a start-task without a task object (none, or a string) has nothing to start: malformed,
    # as the robustness scenario sends and judges it (one fault, one rule: not EXEC-START-001).
    if not isinstance(m, dict) or not name or any(
            f.rule in ("MSG-002", "MSG-003", "MSG-004") for f in v.violations) or (
            name == "start-task" and not isinstance(m.get("task"), dict)):
        name = MALFORMED
    invalid = name == "start-task" and any(f.rule == "TASK-001" for f in v.violations)
    cmd = Command(com_uuid, name, t, m, digest, head(memoryview(content), 120), invalid,
                  c.life)
    c.commands[com_uuid] = cmd
    c.last_command = cmd
    c.await_answer(cmd)
    if name == "start-task" and cmd.task_uuid is not None:
        c.unfollow(cmd.task_uuid)  # a start-task naming a task-uuid begins it anew


def _com_uuid_and_content(msg: Message, m: object) -> tuple[str | None, bytes]:
    """The command's com-uuid (None: none readable) and the content a resend repeats. A
    command that is not JSON may still carry a readable com-uuid, and a robust unit answers
    it 'failed' (EXEC-ROBUST-002)."""
    com_uuid = str_of(m, "com-uuid")
    if com_uuid is None and m is None:
        found = _COM_UUID.search(msg.payload if isinstance(msg.payload, bytes) else b"")
        return (found.group(1).decode("utf-8", "replace") if found else None,
                bytes(msg.payload))
    return com_uuid, orjson.dumps(m, option=orjson.OPT_SORT_KEYS) if com_uuid else b""


def _reused(c: Conversations, before: Command, digest: bytes, msg: Message) -> Violation:
    """2: the same com-uuid with other content (EXEC-008, the commander's fault). Ambiguous
    from here on: an answer with this response-to may be to either command, so the unit is
    not judged on it any more."""
    com_uuid = before.com_uuid
    before.judged = True
    before.digest = digest
    c.pending.pop(com_uuid, None)
    c.commands[com_uuid] = before
    return Violation.of(
        "EXEC-008", expected=f"com-uuid {com_uuid} reused only to resend the same command",
        observed=f"other content than the command sent {msg.time - before.time:.2f} s "
                 f"earlier: {before.excerpt.decode('utf-8', 'replace')}",
        topic=msg.topic, path="$.com-uuid", time=msg.time, payload=msg.payload,
        detail="generate a fresh com-uuid for every new command")


def _task_of(c: Conversations, cmd: Command) -> TaskRecord | None:
    for value, task_uuid in cmd.values:
        if value == "running" and task_uuid is not None:
            return c.followed(task_uuid)
    return c.followed(cmd.task_uuid)


@reinterprets("TASK-002", on=(TopicKind.EXEC_COMMAND,))
def task_the_unit_offers(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                         found: list[Violation]) -> list[Violation]:
    """9.12: tasks are vehicle-type specific beyond section 9; a start-task of a task the unit
    itself lists in tasks-available (5.3) is no unknown task (TASK-002 is for names no one
    offers). Knowing what the unit offers needs its history: stateful."""
    if not found or not unit.tasks_available:
        return found
    task = v.message.get("task") if isinstance(v.message, dict) else None
    name = str_of(task, "name")
    if name is None or name not in unit.tasks_available:
        return found
    unit.examine("TASK-002")
    return [f for f in found if f.rule != "TASK-002"]

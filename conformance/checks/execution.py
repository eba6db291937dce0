"""Direct execution seen from outside (spec 12): responses and feedback carry the unit's
agent-uuid (EXEC-004, EXEC-FB-003), responses answer commands that were sent (EXEC-006), a
com-uuid names one command (EXEC-008), and no feedback follows a task's final status
(EXEC-FB-004). Every history is a bounded LRU."""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Iterator
from typing import Any

import orjson

from conformance.checks.base import BoundedDict, CheckContext, UnitState, check, reinterprets
from conformance.client import Message
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

COMMANDS_KEPT = 4096
TASKS_KEPT = 4096
PENDING_KEPT = 64
MAX_LIVE_UUIDS = 8  # agent-uuids whose last heartbeat time is kept (twins, reboots)
FINAL_STATUSES = frozenset({"finished", "failed", "aborted"})  # 12.4
_COM_UUID = re.compile(rb'"com-uuid"\s*:\s*"([^"\\]{1,100})"')


def _lru(unit: UnitState, key: str, limit: int) -> BoundedDict:
    d = unit.private.get(key)
    if d is None:
        d = unit.private[key] = BoundedDict(limit)
    return d  # type: ignore[no-any-return]


def _str(m: Any, key: str) -> str | None:
    x = m.get(key) if isinstance(m, dict) else None
    return x if isinstance(x, str) else None


@check("EXEC-008", on=(TopicKind.EXEC_COMMAND,))
def com_uuid_names_one_command(ctx: CheckContext, unit: UnitState, msg: Message,
                               v: Validation) -> Iterator[Violation]:
    """2: 'Use UUID to identify a communication message'; 12.1 resends reuse it for the same
    command. The same com-uuid with other content makes a resend ambiguous (EXEC-008)."""
    m = v.message
    com_uuid = _str(m, "com-uuid")
    if com_uuid is None and m is None:
        # A command that is not JSON may still carry a readable com-uuid, and a robust unit
        # answers it 'failed' (EXEC-ROBUST-002): remember it, or its answer looks like an
        # answer to nothing (EXEC-006).
        found = _COM_UUID.search(msg.payload if isinstance(msg.payload, bytes) else b"")
        com_uuid = found.group(1).decode("utf-8", "replace") if found else None
        content = bytes(msg.payload)
    else:
        content = orjson.dumps(m, option=orjson.OPT_SORT_KEYS) if com_uuid else b""
    if com_uuid is None:
        return
    commands = _lru(unit, "commands", COMMANDS_KEPT)
    if "first_command" not in unit.private:
        unit.private["first_command"] = msg.time
    unit.examine("EXEC-008")
    before = commands.get(com_uuid)
    # Kept: a digest of the content and its first 120 bytes, not the content (a command may
    # be 1 MiB, and orjson's output holds a 4 KiB buffer: 4096 kept per unit add up).
    digest = hashlib.blake2b(content, digest_size=16).digest()
    commands[com_uuid] = (digest, msg.time, _str(m, "command"), bytes(memoryview(content)[:120]))
    if before is not None and before[0] != digest:
        yield Violation.of(
            "EXEC-008", expected=f"com-uuid {com_uuid} reused only to resend the same command",
            observed=f"other content than the command sent {msg.time - before[1]:.2f} s "
                     f"earlier: {before[3].decode('utf-8', 'replace')}",
            topic=msg.topic, path="$.com-uuid", time=msg.time, payload=msg.payload,
            detail="generate a fresh com-uuid for every new command")
    # A start-task naming a task-uuid begins that task's history again: EXEC-FB-004 forgets
    # its earlier final status.
    if _str(m, "command") == "start-task":
        task_uuid = _str(m, "task-uuid")
        if task_uuid is not None:
            _lru(unit, "final", TASKS_KEPT).pop(task_uuid, None)


@check("EXEC-006", on=(TopicKind.EXEC_RESPONSE,))
def response_to_matches_command(ctx: CheckContext, unit: UnitState, msg: Message,
                                v: Validation) -> Iterator[Violation]:
    """12.1: a response answers a command (response-to = its com-uuid). Judged only when the
    observer saw this unit's exec/command, and not for responses that may answer a command
    sent before the observation began (within the profile's response timeout of its start)."""
    response_to = _str(v.message, "response-to")
    if response_to is None:
        return
    first = unit.private.get("first_command")
    if first is None:
        unit.note("EXEC-006", f"no command seen on {unit.address.topic('exec/command')}: "
                              f"subscribe to it to judge responses")
        return
    commands = _lru(unit, "commands", COMMANDS_KEPT)
    if response_to in commands:
        unit.examine("EXEC-006")
        return
    if ctx.started is not None and msg.time - ctx.started < ctx.profile.response_timeout:
        unit.note("EXEC-006", "responses in the first response-timeout of the observation "
                              "may answer commands sent before it")
        return
    if commands.evicted:
        return  # it may answer a command older than the ones kept: cannot tell
    unit.examine("EXEC-006")
    yield Violation.of(
        "EXEC-006", expected=f"response-to = the com-uuid of a command sent to "
                             f"{unit.address.name}",
        observed=f"response-to {response_to}: no such command seen", topic=msg.topic,
        path="$.response-to", time=msg.time, payload=msg.payload,
        detail="copy the command's com-uuid into response-to (12.3)")


def _agent_uuid_matches(rule: str, what: str, ctx: CheckContext, unit: UnitState, msg: Message,
                        v: Validation) -> Iterator[Violation]:
    agent_uuid = _str(v.message, "agent-uuid")
    if agent_uuid is None:
        return
    current = unit.agent_uuid
    if current is None:
        unit.note(rule, "no heartbeat seen before the first " + what)
        return
    if agent_uuid == current:
        unit.examine(rule)
        return
    if _heartbeat_is_live(unit, agent_uuid, msg.time):
        # Two live agents under one name: HB-011 reports that; this answer carries the uuid of
        # one of them, which is its own heartbeat's.
        unit.examine(rule)
        return
    violation = Violation.of(
        rule, expected=f"agent-uuid {current} (the heartbeat's)",
        observed=f"agent-uuid {agent_uuid}", topic=msg.topic, path="$.agent-uuid",
        time=msg.time, payload=msg.payload,
        detail=f"send the same agent-uuid in heartbeat and {what}s; it changes only on reboot")
    if agent_uuid in unit.agent_uuids:  # an earlier life's uuid: stale for sure
        unit.examine(rule)
        yield violation
    else:  # perhaps a reboot whose first heartbeat has not arrived yet: decide at the next one
        _lru(unit, "pending_uuid", PENDING_KEPT)[(rule, agent_uuid, msg.time)] = violation


@check("EXEC-004", on=(TopicKind.EXEC_RESPONSE,))
def response_agent_uuid_is_heartbeats(ctx: CheckContext, unit: UnitState, msg: Message,
                                      v: Validation) -> Iterator[Violation]:
    """12.1: 'Response message: Returns agent-uuid' (the unit's, as in its heartbeat)."""
    yield from _agent_uuid_matches("EXEC-004", "response", ctx, unit, msg, v)


@check("EXEC-FB-003", on=(TopicKind.EXEC_FEEDBACK,))
def feedback_agent_uuid_is_heartbeats(ctx: CheckContext, unit: UnitState, msg: Message,
                                      v: Validation) -> Iterator[Violation]:
    """12.1: feedback 'should contain agent-uuid' (the unit's, as in its heartbeat)."""
    yield from _agent_uuid_matches("EXEC-FB-003", "feedback", ctx, unit, msg, v)


def _heartbeat_is_live(unit: UnitState, agent_uuid: str, t: float) -> bool:
    """Whether a heartbeat with this agent-uuid arrived within two declared periods of ``t``."""
    seen = unit.private.get("heartbeat_uuid_times")
    period = unit.period(TopicKind.HEARTBEAT)
    last = seen.get(agent_uuid) if seen else None
    return last is not None and period is not None and t - last <= 2 * period


@check("EXEC-004", "EXEC-FB-003", on=(TopicKind.HEARTBEAT,))
def pending_agent_uuids_resolved(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> list[Violation] | None:
    """A response with an unknown agent-uuid is right if the next heartbeat carries it.
    (Runs on every heartbeat: a list or None, not a generator.)"""
    agent_uuid = _str(v.message, "agent-uuid")
    if agent_uuid is not None and not msg.retain:
        # A plain dict, not a BoundedDict: this runs on every heartbeat, and nearly always
        # updates the one uuid there is. Full: the uuid heard from longest ago goes.
        times = unit.private.get("heartbeat_uuid_times")
        if times is None:
            times = unit.private["heartbeat_uuid_times"] = {}
        elif agent_uuid not in times and len(times) >= MAX_LIVE_UUIDS:
            del times[min(times, key=times.__getitem__)]
        times[agent_uuid] = msg.time
    pending = unit.private.get("pending_uuid")
    if not pending or msg.retain:
        return None
    found = []
    for (rule, their_uuid, _t), violation in list(pending.items()):
        unit.examine(rule)
        if their_uuid != agent_uuid:
            found.append(violation)
    pending.clear()
    return found


@check("EXEC-004", "EXEC-FB-003", finish=True)
def pending_agent_uuids_at_end(ctx: CheckContext, unit: UnitState, now: float,
                               findings: Any) -> Iterator[Violation]:
    pending = unit.private.get("pending_uuid")
    for (rule, _uuid, _t), violation in (pending or {}).items():
        findings.examine(rule)
        yield violation


@check("EXEC-FB-004", on=(TopicKind.EXEC_FEEDBACK,))
def no_feedback_after_final_status(ctx: CheckContext, unit: UnitState, msg: Message,
                                   v: Validation) -> Iterator[Violation]:
    """12.4: finished, failed and aborted end a task: no feedback for it may follow (a
    repeated delivery of the final message itself, same com-uuid, is not a new feedback)."""
    m = v.message
    task_uuid, status = _str(m, "task-uuid"), _str(m, "status")
    if task_uuid is None or status is None:
        return
    unit.examine("EXEC-FB-004")
    final = _lru(unit, "final", TASKS_KEPT)
    ended = final.get(task_uuid)
    if ended is not None:
        end_status, end_com_uuid, end_time = ended
        if _str(m, "com-uuid") != end_com_uuid:
            yield Violation.of(
                "EXEC-FB-004", expected=f"no feedback for task {task_uuid} after its final "
                                        f"status '{end_status}'",
                observed=f"status '{status}' {msg.time - end_time:.2f} s later",
                topic=msg.topic, path="$.status", time=msg.time, payload=msg.payload,
                detail="stop sending feedback once a task is finished, failed or aborted")
        return
    if status in FINAL_STATUSES:
        final[task_uuid] = (status, _str(m, "com-uuid"), msg.time)


@reinterprets("ERR-013", on=(TopicKind.EXEC_RESPONSE,))
def signal_task_response_form(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                              found: list[Violation]) -> list[Violation]:
    """12.3.2 (signal-task response) is empty: the suite expects a start-task response's form
    and judges a response to a signal-task that misses it by ERR-013 (a warning by default),
    not by EXEC-002. Knowing what a response answers needs the command: stateful."""
    response_to = _str(v.message, "response-to")
    commands = unit.private.get("commands")
    if response_to is None or not commands:
        return found
    command = commands.get(response_to)
    if command is None or command[2] != "signal-task":
        return found
    unit.examine("ERR-013")
    return [dataclasses.replace(
        f, rule="ERR-013", detail=f"answering signal-task {response_to}: 12.3.2 is empty; "
                                  f"the suite expects a start-task response's form "
                                  f"({f.detail or 'agent-uuid, com-uuid, response-to, response'})")
            if f.rule == "EXEC-002" else f for f in found]

"""Direct execution seen from outside (spec 12): responses and feedback carry the unit's
agent-uuid (EXEC-004, EXEC-FB-003). Commands and their answers are ``conversation``'s.
Every history is bounded."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from conformance.checks.base import BoundedDict, CheckContext, UnitState
from conformance.checks.registry import check
from conformance.checks.stash import StashKey
from conformance.message import Message
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

PENDING_KEPT = 64
MAX_LIVE_UUIDS = 8  # agent-uuids whose last heartbeat time is kept (twins, reboots)
HEARTBEAT_UUID_TIMES: StashKey[dict[str, float]] = StashKey("heartbeat-uuid-times")
"""agent-uuid -> arrival of its latest live heartbeat (at most MAX_LIVE_UUIDS)."""
PENDING_UUID: StashKey[BoundedDict] = StashKey("pending-uuid")
"""(rule, agent-uuid, time) -> its violation, decided at the next heartbeat (at most
PENDING_KEPT)."""


def _str(m: Any, key: str) -> str | None:
    x = m.get(key) if isinstance(m, dict) else None
    return x if isinstance(x, str) else None


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
        unit.stash.setdefault(PENDING_UUID, lambda: BoundedDict(PENDING_KEPT))[
            (rule, agent_uuid, msg.time)] = violation


@check("EXEC-004", on=(TopicKind.EXEC_RESPONSE,), reads=(HEARTBEAT_UUID_TIMES, PENDING_UUID))
def response_agent_uuid_is_heartbeats(ctx: CheckContext, unit: UnitState, msg: Message,
                                      v: Validation) -> Iterator[Violation]:
    """12.1: 'Response message: Returns agent-uuid' (the unit's, as in its heartbeat)."""
    yield from _agent_uuid_matches("EXEC-004", "response", ctx, unit, msg, v)


@check("EXEC-FB-003", on=(TopicKind.EXEC_FEEDBACK,), reads=(HEARTBEAT_UUID_TIMES, PENDING_UUID))
def feedback_agent_uuid_is_heartbeats(ctx: CheckContext, unit: UnitState, msg: Message,
                                      v: Validation) -> Iterator[Violation]:
    """12.1: feedback 'should contain agent-uuid' (the unit's, as in its heartbeat)."""
    yield from _agent_uuid_matches("EXEC-FB-003", "feedback", ctx, unit, msg, v)


def _heartbeat_is_live(unit: UnitState, agent_uuid: str, t: float) -> bool:
    """Whether a heartbeat with this agent-uuid arrived within two declared periods of ``t``."""
    seen = unit.stash.get(HEARTBEAT_UUID_TIMES)
    period = unit.period(TopicKind.HEARTBEAT)
    last = seen.get(agent_uuid) if seen else None
    return last is not None and period is not None and t - last <= 2 * period


@check("EXEC-004", "EXEC-FB-003", on=(TopicKind.HEARTBEAT,),
       reads=(HEARTBEAT_UUID_TIMES, PENDING_UUID))
def pending_agent_uuids_resolved(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> list[Violation] | None:
    """A response with an unknown agent-uuid is right if the next heartbeat carries it.
    (Runs on every heartbeat: a list or None, not a generator.)"""
    agent_uuid = _str(v.message, "agent-uuid")
    if agent_uuid is not None and not msg.retain:
        # A plain dict, not a BoundedDict: this runs on every heartbeat, and nearly always
        # updates the one uuid there is. Full: the uuid heard from longest ago goes.
        times = unit.stash.get(HEARTBEAT_UUID_TIMES)
        if times is None:
            times = unit.stash[HEARTBEAT_UUID_TIMES] = {}
        elif agent_uuid not in times and len(times) >= MAX_LIVE_UUIDS:
            del times[min(times, key=times.__getitem__)]
        times[agent_uuid] = msg.time
    pending = unit.stash.get(PENDING_UUID)
    if not pending or msg.retain:
        return None
    found = []
    for (rule, their_uuid, _t), violation in list(pending.items()):
        unit.examine(rule)
        if their_uuid != agent_uuid:
            found.append(violation)
    pending.clear()
    return found


@check("EXEC-004", "EXEC-FB-003", finish=True, reads=(PENDING_UUID,))
def pending_agent_uuids_at_end(ctx: CheckContext, unit: UnitState, now: float,
                               findings: Any) -> Iterator[Violation]:
    pending = unit.stash.get(PENDING_UUID)
    for (rule, _uuid, _t), violation in (pending or {}).items():
        findings.examine(rule)
        yield violation

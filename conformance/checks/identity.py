"""A unit's identity and liveness over time (spec 5, 5.1): agent-uuid stability (HB-006), one
live agent per name (HB-011), silences (HB-010), stale retained messages (MSG-007), and every
declared level backed by its info message (HB-008)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, TypeGuard

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.conversation import CONVERSATIONS, commands_died_on
from conformance.checks.liveness import (
    DEATHS_KEPT,
    HB,
    IDENTITY,
    SILENCE_PERIODS,
    Identity,
    broker_gap,
    deaths,
    heartbeat_period,
    heartbeat_tracker,
)
from conformance.checks.registry import check
from conformance.message import Message
from conformance.topics import INFO_KIND_OF_LEVEL, TopicKind, level_name
from conformance.validator import Validation
from conformance.violation import Violation

REBOOT_SILENCE_PERIODS = 2.0  # HB-006's decision
FAST_RESTART_PERIODS = 30.0
"""HB-006: a unit may restart within a heartbeat period (a new agent-uuid without a silence)
once; a second such change within this many declared periods is no reboot."""
STALE_PERIODS = 3.0  # MSG-007's decision
LEVEL_INFO_PERIODS = 3.0  # HB-008: wait at least 3 declared heartbeat periods (and info_wait)


def _uuid(v: Validation) -> str | None:
    m = v.message
    u = m.get("agent-uuid") if isinstance(m, dict) else None
    return u if isinstance(u, str) else None


def _previous_live(unit: UnitState) -> float | None:
    """Arrival of the previous heartbeat, when it was live (a retained one's time is unknown)."""
    if unit.heartbeat_retained:
        return None
    return unit.last_heartbeat


# The heartbeat checks run on every heartbeat: they return a list or None (no generator), and
# count examinations straight into ``unit.examined`` (what ``unit.examine`` does).

@check("HB-006", "HB-011", on=(HB,), reads=(IDENTITY,))
def agent_uuid_changes_only_on_reboot(ctx: CheckContext, unit: UnitState, msg: Message,
                                      v: Validation) -> list[Violation] | None:
    """5.1: agent-uuid 'should change when rebooting', and only then. Against the previous
    live heartbeat: a new agent-uuid after a silence of more than two declared periods is a
    reboot; so is one new agent-uuid without a silence (a process restarted within a period:
    5.1 asks for a new uuid then). A second such change within ``FAST_RESTART_PERIODS`` is no
    reboot: the uuid is made per thread or per message (HB-006). An earlier one coming back
    without a silence is a second agent under the same name (HB-011)."""
    uuid, prev, last = _uuid(v), unit.agent_uuid, _previous_live(unit)
    if uuid is None or prev is None or msg.retain or last is None:
        if uuid is not None and prev is None:
            unit.note("HB-006", "only one heartbeat with an agent-uuid seen")
        return None
    examined = unit.examined
    examined["HB-006"] = examined.get("HB-006", 0) + 1
    examined["HB-011"] = examined.get("HB-011", 0) + 1
    if uuid == prev:  # the usual case
        return None
    period = unit.period(HB)
    silence = msg.time - last
    if (period is not None and silence > REBOOT_SILENCE_PERIODS * period) or ctx.in_gap(
            last, msg.time):
        return None  # a reboot (or the observer was away and cannot tell)
    if uuid in unit.agent_uuids:
        return [Violation.of(
            "HB-011", expected=f"one agent-uuid under {unit.address.name}",
            observed=f"agent-uuid {uuid} again, {silence:.3f} s after a heartbeat of {prev}",
            topic=msg.topic, path="$.agent-uuid", time=msg.time, payload=msg.payload,
            detail="two agents publish under one unit name; give each its own UNIT name (3.1)")]
    if period is None:
        return None
    identity = unit.stash.setdefault(IDENTITY, Identity)
    before, identity.fast_change = identity.fast_change, msg.time
    if before is None or msg.time - before > FAST_RESTART_PERIODS * period:
        identity.fast_changes = 1
        return None  # one fast restart is a reboot: the new uuid is what 5.1 asks for
    identity.fast_changes += 1
    # Two restarts in a row without a silence may be two restarts (the suite's bound: a
    # decided condition); a third says the uuid is made per thread or message (5.1's words).
    return [Violation.of(
        "HB-006", condition="" if identity.fast_changes > 2 else "restarts",
        expected=f"agent-uuid {prev} until a reboot (a silence over "
                           f"{REBOOT_SILENCE_PERIODS:g} declared periods, "
                           f"{REBOOT_SILENCE_PERIODS * period:.2f} s, or one fast restart)",
        observed=f"agent-uuid {uuid} after only {silence:.3f} s, the second change without a "
                 f"silence within {msg.time - before:.1f} s", topic=msg.topic,
        path="$.agent-uuid", time=msg.time, payload=msg.payload,
        detail="generate the agent-uuid once per process start, not per thread or message")]


@check("HB-010", on=(HB,), reads=(IDENTITY,))
def unit_does_not_fall_silent(ctx: CheckContext, unit: UnitState, msg: Message,
                              v: Validation) -> list[Violation] | None:
    """5.1: the heartbeat registers availability; a silence over 3 declared periods warns.
    A silence that ended in a burst after a silence of every topic is judged at the next
    heartbeat, once the burst has shown whether the broker stalled."""
    identity = unit.stash.setdefault(IDENTITY, Identity)
    pending = identity.silences_pending
    if not pending:
        return _silence(ctx, unit, msg, v)
    identity.silences_pending = None
    found = _silence(ctx, unit, msg, v)
    kept = [f for f in pending if f.time is None or not ctx.in_gap(f.time, msg.time)]
    return [*kept, *(found or ())] or None


def _silence(ctx: CheckContext, unit: UnitState, msg: Message,
             v: Validation) -> list[Violation] | None:
    """5.1: the heartbeat registers availability; a silence over 3 declared periods warns,
    saying whether the unit came back with the same agent-uuid (resumed) or a new one."""
    last = _previous_live(unit)
    if msg.retain or last is None:
        return None
    period = unit.period(HB)
    if period is None:
        unit.note("HB-010", "no valid declared heartbeat rate")
        return None
    examined = unit.examined
    examined["HB-010"] = examined.get("HB-010", 0) + 1
    silence = msg.time - last
    identity = unit.stash.setdefault(IDENTITY, Identity)
    held = identity.silences_held
    if silence <= SILENCE_PERIODS * period:  # the usual case: one attribute more
        if held and _uuid(v) == unit.agent_uuid:
            # It keeps its period now, in the same life: what was held were silences. The
            # first heartbeat of a new life soon after the last of the old one is no period
            # kept (a unit far slower than it declares restarts as slow, HB-003's).
            identity.silences_held = []
            return held
        return None
    if silence <= SILENCE_PERIODS * heartbeat_period(unit):
        # Far slower than declared all along (HB-003's gross mismatch): its own period it
        # keeps; what was held were no silences either.
        identity.silences_held = []
        return None
    tracker = heartbeat_tracker(unit)
    if ctx.reboots and _died_until_reboot(ctx, unit, identity, last, msg.time):
        return None
    if ctx.in_gap(last, msg.time):
        return None
    found = _silent_since(unit, msg, v, last, period)
    if found is None:
        return None
    if tracker is None or not tracker.n:
        # No interval yet within 3 periods: a unit that sends far slower than it declares is
        # HB-003's (its rate), not a string of silences. Held until it keeps its period once.
        identity.silences_held = [*held, *found][-8:]
        return None
    if ctx.quiet is not None and ctx.quiet >= last:
        # The whole observer was silent too: perhaps the broker stalled; the burst will say.
        identity.silences_pending, identity.silences_held = [*held, *found], []
        return None
    if held:
        identity.silences_held = []
        return [*held, *found]
    return found


def _silent_since(unit: UnitState, msg: Message, v: Validation, last: float,
                  period: float) -> list[Violation] | None:
    """HB-010's finding for a silence from ``last`` that ``msg`` ended; None when the unit
    came back with a new agent-uuid (a reboot: 5.1, unavailable while it restarts; one that
    never ends is HB-012's)."""
    uuid = _uuid(v)
    if uuid is None:
        came_back = "came back (its agent-uuid unreadable)"
    elif uuid == unit.agent_uuid:
        came_back = "came back with the same agent-uuid (resumed)"
    else:
        return None
    silence = msg.time - last
    return [Violation.of(
        "HB-010", expected=f"a heartbeat at least every {SILENCE_PERIODS * period:.2f} s "
                           f"({SILENCE_PERIODS:g} declared periods)",
        observed=f"silent for {silence:.2f} s ({silence / period:.1f} periods), then {came_back}",
        topic=msg.topic, time=last, payload=msg.payload,
        detail="a silence makes the unit look gone to every commander")]


def _died_until_reboot(ctx: CheckContext, unit: UnitState, identity: Identity, last: float,
                       t: float) -> bool:
    """Whether the unit, silent since ``last``, was silent for good until the suite rebooted
    it before ``t``: a death (HB-012, kept in ``identity.deaths``), not a silence."""
    revived = next((r for r in ctx.reboots if last < r <= t), None)
    if revived is None or revived - last <= SILENCE_PERIODS * heartbeat_period(unit) \
            or broker_gap(ctx, last, revived):
        return False
    deaths = identity.deaths
    deaths.append((last, revived))
    del deaths[:-DEATHS_KEPT]
    return True


@check("HB-012", finish=True, reads=(IDENTITY, CONVERSATIONS))
def unit_does_not_die(ctx: CheckContext, unit: UnitState, now: float,
                      findings: Any) -> Iterator[Violation]:
    """5.1: the heartbeat registers availability. One that stops for good is a death (error):
    the finding names the last command the unit received before it fell silent."""
    if unit.last_heartbeat is None or unit.period(HB) is None:
        return
    findings.examine("HB-012")
    period = heartbeat_period(unit)
    for last, end in deaths(ctx, unit, now):
        silence = min(end, now) - last
        commands = commands_died_on(unit, last, period)
        how = ("it never came back" if end == float("inf")
               else "it came back only when the suite rebooted it")
        # With no command before it, the unit was switched off or left: the spec asks no
        # unit to stay (decided: warns); one that fell silent on a command died on it.
        yield Violation.of(
            "HB-012", condition="" if commands else "no-command",
            expected=f"a heartbeat at least every {SILENCE_PERIODS * period:.2f} s "
                               f"until the end of the observation",
            observed=f"no heartbeat for {silence:.2f} s ({silence / period:.1f} periods); "
                     f"{how}{_commands_said(commands, last)}",
            topic=unit.address.topic("heartbeat"), time=last,
            payload=commands[0].excerpt if commands else None,
            detail="a unit that dies on a command must survive it (12.1)" if commands else
                   "a unit that leaves the arena stops its heartbeat; one that crashed on its "
                   "own restarts")


NAMED_KEPT = 8
"""Commands HB-012 names at most (the rest are counted)."""


def _commands_said(commands: list[Any], last: float) -> str:
    """The commands a death may have been caused by, the last first, each with its time
    relative to the last heartbeat ``last``."""
    if not commands:
        return "; it had received no command"
    said = [f"{cmd.describe()}, {abs(cmd.last_sent - last):.2f} s "
            f"{'after' if cmd.last_sent >= last else 'before'} its last heartbeat"
            + (" (answered)" if cmd.answers else "") for cmd in commands[:NAMED_KEPT]]
    more = len(commands) - NAMED_KEPT
    if len(commands) == 1:
        return f"; the command it may have died on: {said[0]}"
    return (f"; the commands it received as it fell silent, the last first: {'; '.join(said)}"
            + (f"; and {more} more" if more > 0 else ""))


@check("MSG-007", on=(HB, TopicKind.SENSOR_INFO, TopicKind.DIRECT_EXECUTION_INFO,
                      TopicKind.TST_EXECUTION_INFO))
def retained_message_is_not_stale(ctx: CheckContext, unit: UnitState, msg: Message,
                                  v: Validation) -> list[Violation] | None:
    """A retained heartbeat or info message older than 3 declared periods makes a dead unit
    look alive to every new subscriber (MSG-007)."""
    if not msg.retain:
        return None
    m = v.message
    if not isinstance(m, dict):
        return None
    stamp, rate = m.get("stamp"), m.get("rate")
    if not (_number(stamp) and _number(rate) and rate > 0):
        unit.note("MSG-007", "a retained message without a numeric stamp and rate")
        return None
    unit.examine("MSG-007")
    age = msg.time - stamp
    if age <= STALE_PERIODS / rate:
        return None
    return [Violation.of(
        "MSG-007", expected=f"a retained message at most {STALE_PERIODS / rate:.2f} s old "
                            f"({STALE_PERIODS:g} declared periods), or none",
        observed=f"retained, stamped {age:.1f} s before it arrived", topic=msg.topic,
        path="$.stamp", time=msg.time, payload=msg.payload,
        detail="publish heartbeat and info messages without the retain flag, or clear the "
               "retained message when the unit stops")]


def _number(x: object) -> TypeGuard[float]:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _level_since(unit: UnitState) -> dict[str, float]:
    return unit.stash.setdefault(IDENTITY, Identity).levels_since


def _info_seen(unit: UnitState, kind: TopicKind) -> bool:
    return unit.kinds_seen.get(kind, 0) > 0


@check("HB-008", on=(HB,), reads=(IDENTITY,))
def declared_level_has_info(ctx: CheckContext, unit: UnitState, msg: Message,
                            v: Validation) -> None:
    """Remembers when each level that has an info message was first declared; HB-008 is
    decided at finish, over the whole observation (spec 5: info messages may come 'with less
    update rate than the general HeartBeat', and a lint may join mid-stream)."""
    m = v.message
    levels = m.get("levels") if type(m) is dict else None
    identity = unit.stash.setdefault(IDENTITY, Identity)
    if type(levels) is not list or levels == identity.levels_seen:
        return None  # unchanged since the last heartbeat (the usual case): nothing new
    identity.levels_seen = levels
    since = identity.levels_since
    for lv in levels:
        if isinstance(lv, str):
            level = level_name(lv)
            if level in INFO_KIND_OF_LEVEL and level not in since:
                since[level] = msg.time
    return None


def info_wait(ctx: CheckContext, unit: UnitState) -> float:
    """Seconds a declared level may go without its info message: the profile's info_wait,
    and at least 3 declared heartbeat periods (HB-008's decision)."""
    period = unit.period(HB)
    return max(ctx.profile.info_wait, LEVEL_INFO_PERIODS * period if period else 0.0)


@check("HB-008", finish=True, reads=(IDENTITY,))
def declared_level_has_info_at_end(ctx: CheckContext, unit: UnitState, now: float,
                                   findings: Any) -> Iterator[Violation]:
    """Each level declared in the latest heartbeat is backed by its info message, seen at any
    time of the observation. Without one, the level fails only once it was observed for
    ``info_wait`` (time the observer was disconnected not counted); before that it is not
    judged, and says how long it was observed and how long it needs."""
    if unit.levels is None:
        return
    since = _level_since(unit)
    need = info_wait(ctx, unit)
    undecided: list[str] = []
    for level, first in since.items():
        kind = INFO_KIND_OF_LEVEL[level]
        if not unit.claims(level) or _info_seen(unit, kind):
            continue
        observed = now - first - ctx.gap_overlap(first, now)
        if observed >= need:
            yield _missing_info(unit, level, kind, observed, need, now)
        else:
            undecided.append(f"'{level}' declared without {kind.value}: observed "
                             f"{max(observed, 0.0):.1f} s; need {need:.1f} s to judge")
    if undecided:
        findings.note("HB-008", "; ".join(undecided))
    else:
        findings.examine("HB-008")


def _missing_info(unit: UnitState, level: str, kind: TopicKind, observed: float, need: float,
                  t: float) -> Violation:
    return Violation.of(
        "HB-008", expected=f"{kind.value} within {need:.1f} s of declaring level '{level}'",
        observed=f"no {kind.value} in {observed:.1f} s", topic=unit.address.topic(kind.value),
        path="$.levels", time=t,
        detail=f"publish {unit.address.topic(kind.value)}, or do not declare '{level}'")

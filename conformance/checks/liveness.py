"""A unit's liveness as the observer measures it (spec 5.1): the heartbeat period silences are
measured in, when a unit died, and the component the identity checks keep of it (``IDENTITY``).
No checks here (``identity`` has them): the conversation deadlines (``exec_deadline``,
``tst_deadline``), the rates and the report read these measures without registering checks
out of turn (checks run in the order ``checks/__init__.py`` imports their modules)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import dead_since, dying_from
from conformance.checks.stash import StashKey
from conformance.topics import TopicKind
from conformance.violation import Violation

if TYPE_CHECKING:
    from conformance.checks.command_history import CommandHistory
    from conformance.checks.rates import RateTracker

HB = TopicKind.HEARTBEAT
SILENCE_PERIODS = 3.0  # HB-010's decision
DEATHS_KEPT = 16


class Identity:
    """What the identity checks keep of a unit between its heartbeats."""

    __slots__ = ("fast_change", "fast_changes", "silences_pending", "silences_held", "deaths",
                 "levels_since", "levels_seen", "heartbeat_rate")

    def __init__(self) -> None:
        self.fast_change: float | None = None
        """When the agent-uuid last changed without a silence (HB-006)."""
        self.fast_changes = 0
        """Changes without a silence in a row, each soon after the one before (HB-006)."""
        self.silences_pending: list[Violation] | None = None
        """Silences judged at the next heartbeat, once a burst showed whether the broker
        stalled (HB-010)."""
        self.silences_held: list[Violation] = []
        """Silences held until the unit keeps its period once (HB-010; at most 8)."""
        self.deaths: list[tuple[float, float]] = []
        """(last heartbeat, the suite's reboot) of each death a reboot ended (HB-012)."""
        self.levels_since: dict[str, float] = {}
        """Level -> when it was first declared (HB-008)."""
        self.levels_seen: list[Any] | None = None
        """The latest heartbeat's raw levels (HB-008: unchanged, nothing new)."""
        self.heartbeat_rate: RateTracker | None = None
        """The heartbeat's rate tracker, which ``rates`` keeps here too when it makes one:
        silences are measured in the periods it measured (``heartbeat_period``)."""


IDENTITY: StashKey[Identity] = StashKey("identity")


GROSS_SLOW_INTERVALS = 2
"""HB-003's decision (checks/rates.py GROSS_SLOW_MIN_INTERVALS): every one of 2 intervals over
3 declared periods is a rate far slower than declared, not two silences."""


def heartbeat_period(unit: UnitState) -> float:
    """The period silences are measured in, seconds: the declared one, or the mean interval
    measured when every one of at least 2 intervals was over 3 declared periods, so that a unit
    sending far slower than it declares (the drone operator: declared 5 Hz, sent every 5 s) is
    judged by its rate (HB-003), not as silent or dead again and again."""
    declared = unit.period(HB) or 0.0
    tracker = heartbeat_tracker(unit)
    if tracker is not None and tracker.n == 0 and tracker.all_n >= GROSS_SLOW_INTERVALS:
        # every interval so far was over 3 declared periods: the unit's own period is longer
        return max(declared, tracker.all_total / tracker.all_n)
    return declared


def heartbeat_tracker(unit: UnitState) -> RateTracker | None:
    """The heartbeat's ``rates.RateTracker``, None before the first live heartbeat."""
    identity = unit.stash.get(IDENTITY)
    return identity.heartbeat_rate if identity is not None else None


def deaths(ctx: CheckContext, unit: UnitState, now: float) -> list[tuple[float, float]]:
    """(last heartbeat, end) of every death: silent for good until the suite rebooted the unit
    (end: the reboot), or until ``now`` (end: infinity)."""
    identity = unit.stash.get(IDENTITY)
    found = list(identity.deaths) if identity is not None else []
    dead = death(ctx, unit, now)
    if dead is not None:
        found.append((dead[1], float("inf")))
    return found


def dying_before_life(unit: UnitState, c: CommandHistory, t: float
                      ) -> tuple[float, float] | None:
    """(dying since, last heartbeat) of a unit whose new life began at ``t`` after a silence
    of more than SILENCE_PERIODS heartbeat periods (``command_history.dead_since``: what it
    left unanswered since is the silence's), None after a shorter one. Exec and TST alike."""
    return dead_since(unit, c, t, heartbeat_period(unit), SILENCE_PERIODS)


def dying_at_end(ctx: CheckContext, unit: UnitState, c: CommandHistory, now: float
                 ) -> tuple[float, float] | None:
    """(dying since, last heartbeat) of a unit dead at ``now`` (``death``), dying since the
    command it may have died on (``command_history.dying_from``); None while it lives."""
    dead = death(ctx, unit, now)
    return (dying_from(c, dead[1], heartbeat_period(unit)), dead[1]) if dead else None


DEATH_FLOOR = 1.0
"""Seconds of silence, at the least, before a heartbeat that stopped is a death."""


def death(ctx: CheckContext, unit: UnitState, now: float) -> tuple[float, float] | None:
    """(dying since, last heartbeat) when the unit's heartbeat stopped and never resumed before
    ``now``: silent for more than 3 periods (``heartbeat_period``), the observer connected.
    'Dying since' is one period before the last heartbeat: a command that killed it was
    received about then."""
    last = unit.last_heartbeat
    if last is None or unit.period(HB) is None:
        return None
    period = heartbeat_period(unit)
    # At least DEATH_FLOOR too: a recording cut 0.36 s after a 10 Hz unit's last heartbeat
    # (3.6 periods) shows where the recorder stopped, not that the unit did.
    if now - last <= max(SILENCE_PERIODS * period, DEATH_FLOOR) or broker_gap(ctx, last, now):
        # Over a gap of the broker it is unknown whether it fell silent; silent through a
        # reboot the suite requested (a zero-length gap of its own) is a death all the same.
        return None
    if any(0.0 <= r - last <= 2 * period for r in ctx.reboots):
        # Its silence began with a reboot the suite requested: whether and how it came back
        # (under its own name, or another: a random suffix per start) is REBOOT-001's.
        return None
    return last - period, last


def broker_gap(ctx: CheckContext, t0: float, t1: float) -> bool:
    """Whether the observer lost or the broker held traffic (a gap of non-zero length, not
    the instant of a reboot the suite requested) between ``t0`` and ``t1``."""
    return any(start < end and start <= t1 and end >= t0 for start, end in ctx.gaps)

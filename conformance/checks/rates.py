"""Rates of the periodic messages (HB-003, SI-002, DEI-002, TEI-002): measured vs declared.

A rate is judged over at least ``profile.min_intervals`` intervals: the mean period must be
within ``profile.rate_tolerance`` of the declared one, and no single interval may exceed
``profile.max_gap_periods`` declared periods (docs/FIELD-NOTES.md 'Timing jitter': this raised no
false
alarm at 1 and 10 Hz). Intervals that overlap a connection gap of the observer are left out.
Intervals over 3 declared periods are silences (HB-010: a boat out of range may fall silent);
they are left out of the mean while the other intervals are enough to judge, and counted in
otherwise (a unit that is always "silent" simply publishes far slower than it declares).
A gross mismatch fails before ``min_intervals``: the mean off by 3x after 3 intervals, or every
interval 3 declared periods or longer after 2 (declared 5 Hz, sent every 5 s).

An interval is measured between the unit's own stamps (5.1) where both messages carry one that
reads as Unix seconds, else between arrivals: a broker that held traffic delivers it in a
burst, and the stamps keep the unit's spacing. Intervals over a gap of the
observer (its connection down, or a stall of the broker found in the traffic,
``checks/stall.py``) are left out either way; the rate's note says both.

The interval across a reboot (an agent-uuid not seen before, spec 5.1; for a message without
one, the heartbeat's) is left out too: the restart's silence is HB-006's and
HB-010's to judge, not the rate's. Agent-uuids that take
turns (two agents under one name, HB-011) are no reboot: their doubled rate stays HB-003's.

Each periodic topic is its own stream, measured at its own rate: SensorInfo on both of the
spec's spellings (3.1 sensor_info, 5.2 sensor.info) is two streams at the declared rate, not
one at twice it (SI-002's note).

Memory is bounded: running sums, min and max, and a series of at most 600 points.

Live (``live_findings``, what lint's scorecard shows while it runs): the same judgement over
the latest ``profile.min_intervals`` clean intervals of each rate (a gross mismatch after
2 or 3), so an operator sees a unit turn red within seconds of a gross mismatch and within a
minute of a fine one at 1 Hz. It is a view, not a verdict: the rules are judged over the
whole observation, as before (a rate that recovered is judged on everything it did).
"""

from __future__ import annotations

from array import array
from collections import deque
from collections.abc import Iterator
from operator import add
from typing import TYPE_CHECKING

from conformance.checks.base import CheckContext, UnitState, usable_rate
from conformance.checks.liveness import IDENTITY, SILENCE_PERIODS, Identity
from conformance.checks.registry import check
from conformance.checks.stall import stamp_of
from conformance.checks.stash import StashKey
from conformance.message import Message
from conformance.results import RateStat
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Verdict, Violation, clock

if TYPE_CHECKING:
    from conformance.checks.rows import Findings

RATE_RULES = {
    TopicKind.HEARTBEAT: "HB-003",
    TopicKind.SENSOR_INFO: "SI-002",
    TopicKind.DIRECT_EXECUTION_INFO: "DEI-002",
    TopicKind.TST_EXECUTION_INFO: "TEI-002",
}
GROSS_FACTOR = 3.0  # HB-003's decision: a mean this far off fails early
WRONG_FACTOR = 2.0
"""A mean interval off by this factor or more (half or twice the declared rate): the declared
rate is not the rate the unit sends at (the rule's words); less, past the profile's tolerance,
is the suite's bound (the decided condition ``tolerance``)."""
GROSS_MIN_INTERVALS = 3
GROSS_SLOW_MIN_INTERVALS = 2
"""HB-003's decision: when every interval is at least GROSS_FACTOR declared
periods long, 2 intervals are enough to fail the rate (declared 5 Hz, sent every 5 s: each
interval 25 periods); a near miss still needs ``min_intervals``."""
MAX_SERIES = 600
MAX_CLOSED_SEGMENTS = 8
MAX_AGENTS = 4
MAX_RECENT = 64
"""Clean intervals kept for the live window (min_intervals beyond this is judged over 64)."""


class _Series:
    """(time, rate in Hz) points for a plot, at most MAX_SERIES: when full, pairs of points
    merge and each new point covers twice as many intervals. Kept in arrays of machine
    numbers (24 bytes a point, not a tuple of three objects): a fleet has thousands."""

    __slots__ = ("times", "sums", "counts", "stride", "acc_n", "acc_sum")

    def __init__(self) -> None:
        self.times = array("d")  # end time of each point
        self.sums = array("d")  # sum of its intervals, seconds
        self.counts = array("q")  # number of its intervals
        self.stride = 1
        self.acc_n = 0
        self.acc_sum = 0.0

    def add(self, t: float, interval: float) -> None:
        self.acc_n += 1
        self.acc_sum += interval
        if self.acc_n < self.stride:
            return
        self.times.append(t)
        self.sums.append(self.acc_sum)
        self.counts.append(self.acc_n)
        self.acc_n, self.acc_sum = 0, 0.0
        if len(self.times) >= MAX_SERIES:
            sums, counts = self.sums, self.counts
            self.times = self.times[1::2]  # each pair ends where its second point ended
            self.sums = array("d", map(add, sums[0::2], sums[1::2]))
            self.counts = array("q", map(add, counts[0::2], counts[1::2]))
            self.stride *= 2

    def rates(self) -> list[tuple[float, float]]:
        return [(t, n / s if s > 0 else 0.0)
                for t, s, n in zip(self.times, self.sums, self.counts, strict=True)]


class RateTracker:
    """Running interval statistics of one periodic message of one unit, for one declared rate."""

    __slots__ = ("kind", "rule", "topic", "declared", "last", "start", "end", "n", "total",
                 "min", "max", "max_at", "silences", "all_n", "all_total", "all_max",
                 "all_max_at", "all_min", "excluded", "series", "agents", "recent",
                 "last_stamp", "by_stamp")

    def __init__(self, kind: TopicKind, topic: str, declared: float | None) -> None:
        self.kind = kind
        self.rule = RATE_RULES[kind]
        self.topic = topic
        self.declared = declared
        self.last: float | None = None
        self.start: float | None = None
        self.end: float | None = None
        self.n = 0
        self.total = 0.0
        self.min = float("inf")
        self.max = 0.0
        self.max_at = 0.0
        self.silences = 0
        self.all_n = 0
        self.all_total = 0.0
        self.all_max = 0.0
        self.all_max_at = 0.0
        self.all_min = float("inf")
        self.excluded = 0
        """Intervals left out: across a reboot, or over a gap of the observer (an outage of
        its connection, or a stall of the broker: ``checks/stall.py``)."""
        self.last_stamp: float | None = None
        self.by_stamp = 0
        """Intervals measured between the unit's own stamps (5.1), not between arrivals."""
        self.series = _Series()
        self.agents: tuple[object, ...] = ()
        """The agent-uuids seen on this topic, latest last (at most MAX_AGENTS)."""
        self.recent: deque[tuple[float, float, bool]] = deque(maxlen=MAX_RECENT)
        """(end time, interval, a silence?) of the latest intervals: the live window."""

    def _agent(self, agent: object) -> None:
        """The message being added carries ``agent``, not the latest seen here. One never seen
        here means the unit restarted (spec 5.1): the silence of its restart is not an interval of its rate (HB-006
        and HB-010 judge it), so that message starts afresh. An agent-uuid seen before is no
        restart: two agents taking turns under one name (HB-011) double the topic's rate, and
        HB-003 says so."""
        agents = self.agents
        if agent in agents:
            self.agents = (*(a for a in agents if a != agent), agent)
            return
        if agents and self.last is not None:
            self.last = self.last_stamp = None
            self.excluded += 1
        self.agents = (*agents[-(MAX_AGENTS - 1):], agent)

    def add(self, ctx: CheckContext, t: float, agent: object = None,
            stamp: float | None = None) -> None:
        """A message that arrived at ``t``, carrying ``agent`` (its agent-uuid, if any) and
        ``stamp`` (its 5.1 stamp when it reads as Unix seconds: ``stall.stamp_of``)."""
        if agent is not None and (not self.agents or self.agents[-1] != agent):
            self._agent(agent)
        last, last_stamp = self.last, self.last_stamp
        self.last, self.last_stamp = t, stamp
        if self.start is None:
            self.start = t
        self.end = t
        if last is None:
            return
        dt = t - last
        if dt < 0:  # out of order (a replay merged from two files): not an interval
            return
        if ctx.gaps and ctx.in_gap(last, t):
            self.excluded += 1
            return
        if stamp is not None and last_stamp is not None and stamp > last_stamp:
            # The unit's own spacing: arrivals bunch when a broker or link
            # holds traffic and delivers it at once; the stamps say when it was sent.
            dt = stamp - last_stamp
            self.by_stamp += 1
        self.all_n += 1
        if dt < self.all_min:
            self.all_min = dt
        self.all_total += dt
        if dt > self.all_max:
            self.all_max, self.all_max_at = dt, t
        self.series.add(t, dt)
        if self.declared and dt > SILENCE_PERIODS / self.declared:
            self.silences += 1
            self.recent.append((t, dt, True))
            return
        self.n += 1
        self.total += dt
        self.recent.append((t, dt, False))
        if dt < self.min:
            self.min = dt
        if dt > self.max:
            self.max, self.max_at = dt, t

    def judge(self, ctx: CheckContext, unit: str) -> tuple[RateStat, list[Violation]]:
        """The rate's statistics and verdict, and its violations (pure: changes nothing): off
        by 2x or more fails the rule's words, past the profile's tolerance or with one long
        interval its decided conditions ``tolerance`` and ``interval``."""
        profile = ctx.profile
        need = profile.min_intervals
        declared = self.declared
        n, total, lo, hi, hi_at, silences_in = self._intervals(need)
        mean = total / n if n else None
        stat = self._stat(unit, n, mean, lo, hi, profile.rate_tolerance)
        if not declared:
            stat.reason = f"no valid declared rate in {self.kind.value}.rate"
            return stat, []
        period = 1.0 / declared
        gross = mean is not None and _gross(n, mean, self.all_min, period)
        how = self._how()
        if n < need and not gross:
            stat.reason = f"only {n} intervals observed; need {need}{how}"
            return stat, []
        found: list[Violation] = []
        # Intervals over 3 declared periods, judged because no others were (a unit far slower
        # than it declares: the drone operator's regular 5 s at 5 Hz are no 'silences').
        silences = ("" if not silences_in else ", every one over 3 declared periods"
                    if silences_in == n else f", {silences_in} of them over 3 declared periods")
        window = (f"over {n} intervals (min {lo:.3f} s, max {hi:.3f} s{silences})")
        assert mean is not None
        if gross and n < need:
            found.append(Violation.of(
                self.rule,
                expected=f"{declared:.2f} Hz (declared in {self.kind.value}.rate)",
                observed=f"{_hz(mean, 3)} {window}, off by more than {GROSS_FACTOR:g}x "
                         f"(judged after {n} intervals: a gross mismatch{how})",
                topic=self.topic, time=self.end, unit=unit,
                detail=f"mean interval {mean:.3f} s, declared period {period:.3f} s: is the "
                       f"rate in Hz? publish at the declared rate, or declare the rate used"))
        elif abs(mean - period) > profile.rate_tolerance * period:
            found.append(Violation.of(
                self.rule, condition="" if gross or _wrong(mean, period) else "tolerance",
                expected=f"{declared:.2f} Hz +-{profile.rate_tolerance:.0%} "
                         f"(declared in {self.kind.value}.rate)",
                observed=f"{1.0 / mean:.2f} Hz {window}" if mean > 0 else f"0 s mean {window}",
                topic=self.topic, time=self.end, unit=unit,
                detail=f"mean interval {mean:.3f} s, declared period {period:.3f} s: publish at "
                       f"the declared rate, or declare the rate actually used"))
        if n >= need and hi > profile.max_gap_periods * period:
            found.append(Violation.of(
                self.rule, condition="interval",
                expected=f"no interval over {profile.max_gap_periods:g} declared periods "
                         f"({profile.max_gap_periods * period:.3f} s)",
                observed=f"an interval of {hi:.3f} s ({hi / period:.1f} periods)",
                topic=self.topic, time=hi_at, unit=unit,
                detail=f"{window}; a single late message means the publisher stalls"))
        stat.judged, stat.findings = True, len(found)
        stat.reason = (f"{len(found)} violation{'s' if len(found) > 1 else ''}{how}" if found
                       else f"min {lo:.3f} s, max {hi:.3f} s{silences}{how}")
        return stat, found

    def _stat(self, unit: str, n: int, mean: float | None, lo: float, hi: float,
              tolerance: float) -> RateStat:
        """The rate's statistics (numbers; its verdict is the judge's)."""
        return RateStat(
            unit=unit, kind=self.kind.value, topic=self.topic, declared_hz=self.declared,
            measured_hz=(1.0 / mean if mean else None), intervals=n, mean_interval=mean,
            min_interval=(lo if n else None), max_interval=(hi if n else None),
            verdict=Verdict.SKIP, series=self.series.rates(), rule=self.rule,
            silences=self.silences, start=self.start, end=self.end, tolerance=tolerance)

    def _intervals(self, need: int) -> tuple[int, float, float, float, float, int]:
        """(count, total, shortest, longest, when the longest ended, silences counted in) of
        the intervals judged: those within 3 declared periods once there are ``need``, else
        every one (silences too: a unit far slower than it declares has no other)."""
        if self.n >= need:
            return self.n, self.total, self.min, self.max, self.max_at, 0
        n, hi = self.all_n, self.all_max
        return (n, self.all_total, min(self.min, hi) if n else float("inf"), hi,
                self.all_max_at, self.silences)

    def _how(self) -> str:
        """How the intervals were measured, for the rate's note."""
        said = []
        if self.by_stamp:
            said.append("intervals by the unit's stamps" if self.by_stamp == self.all_n else
                        f"{self.by_stamp} of {self.all_n} intervals by the unit's stamps")
        if self.excluded:
            said.append(f"{self.excluded} left out (a reboot, or a stall or outage of the "
                        f"broker)")
        return f"; {', '.join(said)}" if said else ""


    def live(self, ctx: CheckContext, unit: str) -> Violation | None:
        """The rate over the latest clean intervals, as a violation when it is off (gross
        after 3 intervals, past the tolerance after ``min_intervals``); None while it holds
        or too few intervals were seen. Pure: a view for the live scorecard, never recorded."""
        declared = self.declared
        if not declared or len(self.recent) < GROSS_SLOW_MIN_INTERVALS:
            return None
        profile = ctx.profile
        need = max(profile.min_intervals, GROSS_MIN_INTERVALS)
        # As judge() does: silences left out while the clean intervals are enough to judge,
        # counted in otherwise (a unit that is always "silent" publishes far too slowly).
        clean = [(t, dt) for t, dt, silent in self.recent if not silent]
        window = clean[-need:] if len(clean) >= need else [
            (t, dt) for t, dt, _ in list(self.recent)[-need:]]
        k = len(window)
        mean = sum(dt for _, dt in window) / k
        period = 1.0 / declared
        gross = _gross(k, mean, min(dt for _, dt in window), period)
        if not gross and (k < profile.min_intervals
                          or abs(mean - period) <= profile.rate_tolerance * period):
            return None
        since = window[0][0] - window[0][1]
        return Violation.of(
            self.rule, condition="" if gross or _wrong(mean, period) else "tolerance",
            expected=f"{declared:.2f} Hz +-{profile.rate_tolerance:.0%} "
                     f"(declared in {self.kind.value}.rate)",
            observed=f"{_hz(mean)} over the latest {k} intervals (since "
                     f"{clock(since)}){', a gross mismatch' if gross else ''}",
            topic=self.topic, time=window[-1][0], unit=unit,
            detail="live: judged over the whole observation when the run ends")


def _wrong(mean: float, period: float) -> bool:
    """Whether a mean interval is off the declared period by WRONG_FACTOR or more."""
    return mean >= WRONG_FACTOR * period or mean <= period / WRONG_FACTOR


def _gross(n: int, mean: float, shortest: float, period: float) -> bool:
    """A gross mismatch (HB-003's decision): the mean off by GROSS_FACTOR after
    GROSS_MIN_INTERVALS intervals, or every one of at least GROSS_SLOW_MIN_INTERVALS intervals
    GROSS_FACTOR declared periods or longer."""
    if n >= GROSS_MIN_INTERVALS and (mean > GROSS_FACTOR * period
                                     or mean < period / GROSS_FACTOR):
        return True
    return n >= GROSS_SLOW_MIN_INTERVALS and shortest >= GROSS_FACTOR * period


def live_findings(ctx: CheckContext, unit: UnitState) -> list[Violation]:
    """Each rate of ``unit`` that is off over its latest intervals (``RateTracker.live``)."""
    found = []
    for tracker in _trackers(unit).values():
        v = tracker.live(ctx, str(unit.address))
        if v is not None:
            found.append(v)
    return found


RATES: StashKey[dict[str, RateTracker]] = StashKey("rates")
"""The unit's rate trackers, one per periodic topic by its subtopic (read by ``identity``
too): sensor_info (3.1) and sensor.info (5.2, ERR-001) are two streams, each at its rate."""
RATES_CLOSED: StashKey[list[RateStat]] = StashKey("rates-closed")
"""The windows a change of the declared rate closed (at most MAX_CLOSED_SEGMENTS)."""


def _trackers(unit: UnitState) -> dict[str, RateTracker]:
    return unit.stash.setdefault(RATES, dict)


def _closed(unit: UnitState) -> list[RateStat]:
    return unit.stash.setdefault(RATES_CLOSED, list)


@check("HB-003", "SI-002", "DEI-002", "TEI-002", on=tuple(RATE_RULES),
       reads=(RATES, RATES_CLOSED, IDENTITY))
def rate_matches_declared(ctx: CheckContext, unit: UnitState, msg: Message,
                          v: Validation) -> list[Violation] | None:
    """Each periodic message is measured against the rate it declares; a change of the
    declared rate closes the window measured so far (judged then) and starts a new one.
    (Runs on every periodic message: returns a list or None, not a generator.)"""
    if msg.retain:  # a retained copy arrives at subscription time, not at its publication
        return None
    kind = v.topic.kind
    m = v.message
    rate = m.get("rate") if type(m) is dict else None
    declared = usable_rate(rate)
    found = None if declared is not None or not (
        isinstance(rate, (float, int)) and not isinstance(rate, bool) and rate > 0
    ) else [_unusable(kind, msg, rate, unit)]
    if declared is None:
        declared = unit.declared_rates.get(kind)
    trackers = unit.stash.get(RATES)
    if trackers is None:
        trackers = _trackers(unit)
    # By the topic's spelling, not its kind: a unit that publishes SensorInfo on both of the
    # spec's topics (3.1 sensor_info, 5.2 sensor.info) sends each at the declared rate.
    stream = v.topic.subtopic
    tracker = trackers.get(stream)
    if tracker is not None and declared is not None and tracker.declared != declared:
        stat, closed_found = tracker.judge(ctx, str(unit.address))
        found = closed_found + (found or [])
        if stat.judged:
            unit.examine(tracker.rule)
        closed = _closed(unit)
        closed.append(stat)
        del closed[:-MAX_CLOSED_SEGMENTS]
        tracker = None
    if tracker is None:
        tracker = trackers[stream] = RateTracker(kind, msg.topic, declared)
        if kind is TopicKind.HEARTBEAT:  # identity measures silences in its periods (HB-010)
            unit.stash.setdefault(IDENTITY, Identity).heartbeat_rate = tracker
    # The life it belongs to: its own agent-uuid, else the heartbeat's (info messages without
    # one, as the RISE agent's: the interval over a restart is no interval of the rate).
    if type(m) is dict:
        agent = m.get("agent-uuid")
        tracker.add(ctx, msg.time, unit.agent_uuid if agent is None else agent,
                    stamp_of(m, msg.time))
    else:
        tracker.add(ctx, msg.time, unit.agent_uuid)
    return found


def _number(x: float) -> str:
    """A number for a person, whatever its size (no repr of a 5000-digit int)."""
    try:
        return f"{float(x):.6g}"
    except OverflowError:  # only an int is too large for a float
        return f"a whole number of {int(x).bit_length()} bits"


def _unusable(kind: TopicKind, msg: Message, rate: float, unit: UnitState) -> Violation:
    """A declared rate refused as a value (``usable_rate``): a period no publisher keeps."""
    return Violation.of(
        RATE_RULES[kind], expected=f"a rate in Hz whose period (1/rate) is a finite number of "
        f"seconds (declared in {kind.value}.rate)", observed=f"{_number(rate)} Hz",
        topic=msg.topic, time=msg.time, unit=str(unit.address),
        detail="1/rate is not a finite period: no message can be sent at this rate, so "
               "it is off from any rate measured by more than any factor")


@check("HB-003", "SI-002", "DEI-002", "TEI-002", finish=True, reads=(RATES,))
def rate_matches_declared_at_end(ctx: CheckContext, unit: UnitState, now: float,
                                 findings: Findings) -> Iterator[Violation]:
    for tracker in _trackers(unit).values():
        stat, found = tracker.judge(ctx, str(unit.address))
        if not stat.judged:
            findings.note(tracker.rule, stat.reason)
        else:
            findings.examine(tracker.rule)
        yield from found


def rate_stats(ctx: CheckContext, unit: UnitState) -> list[RateStat]:
    """Every measured window of every periodic message of the unit, closed ones first."""
    out = list(_closed(unit))
    for tracker in _trackers(unit).values():
        out.append(tracker.judge(ctx, str(unit.address))[0])
    return out


def _hz(mean: float, digits: int = 2) -> str:
    """The rate of a mean interval; a recording may stamp every message alike (mean 0)."""
    return f"{1.0 / mean:.{digits}f} Hz" if mean > 0 else "a mean interval of 0 s"

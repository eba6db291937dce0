"""How long a certification watches the unit, in periods of its declared rates: whether it still
lives (HB-012's window), its execution info before the first command, the TST conversations'
open deadlines, the passive window the rates need before the passive rules are judged (the
profile's ``min_intervals``), and the ``--observe`` a rerun needs when evidence came late."""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any

from conformance.checks import Monitor
from conformance.checks.identity import SILENCE_PERIODS, heartbeat_period
from conformance.checks.tst_conversation import open_until
from conformance.scenarios import Context, Traffic
from conformance.scenarios.reboot import intervals
from conformance.suite.events import clock
from conformance.violation import Verdict

PERIODIC = ("heartbeat", "sensor_info", "direct_execution_info", "tst_execution_info")


class Observation:
    """Waits on the unit's periodic messages, with deadlines from its declared rates."""

    def __init__(self, context: Context, monitor: Monitor,
                 monitor_lock: AbstractContextManager[Any], *, observe: float) -> None:
        self.context = context
        self.unit = context.unit
        self.traffic: Traffic = context.traffic
        self.timing = context.timing
        self.monitor = monitor
        self._lock = monitor_lock
        self.observe = observe
        """--observe: seconds to watch the unit at least before the passive rules are judged."""
        self.clock = self.traffic.clock
        """The run's time: real, or virtual in the test suite's matrices."""
        self.started = self.clock.now()
        self._started_monotonic = self.clock.monotonic()

    def slowest_rate(self) -> float:
        """The slowest declared rate of the unit's periodic messages, Hz (1 when none)."""
        rates = [r for r in (self.context.rate_of(k) for k in PERIODIC) if r]
        return min(rates) if rates else 1.0

    def unit_died(self, *, settle: bool = False) -> str:
        """Why the unit counts as dead, or "" while it lives: no heartbeat for 3
        declared periods (HB-012's window) and none within 10 periods, the response
        deadline, or twice the longest interval it has shown, whichever is longer (a dropout
        of a few periods, HB-010's, is not death; nor is the next heartbeat of a unit far
        slower than it declares before 2 intervals tell its own period: the drone operator,
        5 Hz declared, 5.002 s apart, was called dead 2 ms before each heartbeat).
        A unit that heartbeats answers at once. ``settle``: a unit still within its 3
        periods is waited for too (before a verdict, not before a command)."""
        latest = self.traffic.latest("heartbeat")
        rate = self.context.rate_of("heartbeat")
        if latest is None or rate is None:
            return ""
        with self._lock:  # far slower than declared (HB-003's): its own period, as HB-012's
            own = heartbeat_period(self.monitor.state(self.unit))
        period = self.timing.scale * max(1.0 / rate, own)
        if not settle and self.clock.now() - latest.time <= SILENCE_PERIODS * period:
            return ""
        window = max(10 * period, self.timing.response, 2 * self._longest_interval())
        left = latest.time + window - self.clock.now()
        if left > 0 and self.traffic.wait_for(lambda e: True, left, after=latest.seq,
                                              subtopic="heartbeat",
                                              what="the unit's heartbeat") is not None:
            return ""
        renamed = self.context.notes.get("renamed")
        if renamed:  # after the suite's reboot: it lives, under another name (3.1)
            return (f"the unit came back under another name ('{renamed}') after the suite's "
                    f"reboot (REBOOT-001): nothing answers at its address")
        # "had not" (by the end of the wait): the suite's reboot may bring it back later
        return (f"the unit fell silent at {clock(latest.time)} and had not come back "
                f"{window:.0f} s later (HB-012): no answer could come")

    def _longest_interval(self, kept: int = 16) -> float:
        """The longest interval between the unit's latest ``kept`` heartbeats of one
        agent-uuid, seconds (0 before two)."""
        # (by the unit's stamps, as the reboot reads them; asked only during a silence)
        return max(intervals(self.traffic.since(0, "heartbeat")[-kept:]), default=0.0)

    def wait_execution_info(self) -> None:
        """Before commanding: the unit's direct_execution_info (its tasks and signals)."""
        if self.traffic.latest("direct_execution_info") is None:
            rate = self.context.rate_of("heartbeat")
            self.traffic.wait_for(lambda e: True, self.timing.periods(3, rate),
                                  subtopic="direct_execution_info")

    def settle(self) -> None:
        """Wait until the Monitor has judged what the TST conversations left open: one
        heartbeat of the unit after the latest deadline (none open: at once)."""
        with self._lock:
            until = open_until(self.monitor.state(self.unit), self.monitor.ctx)
        if until is None:
            return
        wait = until - self.clock.now() + self.timing.periods(2, self.context.rate_of("heartbeat"))
        self.traffic.wait_for(lambda e: e.time > until, max(0.0, wait), subtopic="heartbeat")

    def wait_passive_window(self) -> None:
        """Wait until the Monitor has judged every declared rate over at least the profile's
        ``min_intervals`` intervals (silences and gaps do not count) and every sensor that
        sensor_info lists has had its chance to be seen; deadline: twice that window plus 5 s.
        Raises ``OutOfTime`` at --max-duration."""
        need = self.context.profile.min_intervals
        slowest = self.slowest_rate()
        # --observe: at least that long since the run started (a rerun of a rule whose
        # evidence came late, e.g. a silence).
        observed_until = self._started_monotonic + self.observe
        deadline = max(self.clock.monotonic() + 2 * (need + 2) / slowest + 5.0, observed_until)
        period = 1.0 / slowest
        rates_ready: list[float] = []

        def enough() -> bool:
            if self.clock.monotonic() < observed_until:
                return False
            if not rates_ready:
                if not self._rates_judged(need):
                    return False
                rates_ready.append(self.clock.monotonic())
            # SI-003: a listed sensor gets three more periods to show up, once. The Monitor's
            # view, not the topic's: it also reads 5.2's 'sensor.info' (ERR-001).
            with self._lock:
                state = self.monitor.state(self.unit)
                listed, seen = state.sensors_listed, set(state.sensors_seen)
            return listed is None or all(s in seen for s in listed) or \
                self.clock.monotonic() - rates_ready[0] > 3 * period

        while not enough() and (left := deadline - self.clock.monotonic()) > 0:
            # Look again after the next periodic message (at most one period from now).
            self.traffic.wait_for(lambda e: e.subtopic in PERIODIC, min(left, period),
                                  after=self.traffic.mark(),
                                  what=f"{need} intervals of every declared rate")

    def _rates_judged(self, need: int) -> bool:
        with self._lock:
            unit = self.monitor.report().units.get(str(self.unit))
        if unit is None:
            return False
        # RateStat.intervals counts silences in while too few others were seen:
        # more than need + silences means the others alone are enough. A rate already failed
        # (a gross mismatch is judged from 2 intervals, HB-003's decision) waits for no more.
        return not any(s.declared_hz and s.verdict is not Verdict.FAIL
                       and s.intervals < need + s.silences for s in unit.rates)

    def observe_for(self, violation_times: list[float]) -> int:
        """Seconds of observation a rerun needs to see a rule's violations (at
        ``violation_times``, Unix seconds) again: when the first came later than the passive
        window would last (a silence, a uuid change), as long as it took then; else 0."""
        if not violation_times:
            return 0
        took = min(violation_times) - self.started
        window = (self.context.profile.min_intervals + 2) / self.slowest_rate()
        return int(took) + 2 if took > window else 0

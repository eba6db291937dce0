"""The linter: feeds every message and capture event to the passive checks (``Monitor``) and
keeps the running tallies the scorecard shows. The checks themselves live in
``conformance.checks`` (one implementation per rule, shared with the certification suite).
"""

from __future__ import annotations

import time
from collections import Counter, deque
from typing import Any

from conformance.checks.monitor import Monitor
from conformance.checks.routes import MAX_COMMANDERS, MAX_UNITS
from conformance.checks.rows import UNATTRIBUTED
from conformance.judge import violation_verdict
from conformance.message import Gap, Message
from conformance.profile import Profile
from conformance.recording import CUT, Event
from conformance.rules import CATALOGUE, Severity
from conformance.topics import parse_topic
from conformance.violation import Verdict, Violation

FLEET_RULES = ("HB-010", "HB-011", "HB-012", "HB-006", "EXEC-006", "EXEC-008", "MSG-007")
"""Observations about the fleet over time (silence, identity, commands and answers, retained
state): the scorecard lists them as they happen."""
NOT_A_UNIT = UNATTRIBUTED
"""Violations of topics that name no unit (the Monitor's report entry)."""
OTHER_UNITS = "(other units)"
MAX_TALLIED = MAX_UNITS + MAX_COMMANDERS
"""Units and commanders tallied one by one, as many as the Monitor tracks; a flood of invented
unit names is tallied together beyond this (bounded memory)."""
MAX_TOPIC_CACHE = 20_000
WATCH_EVERY = 0.5
"""Seconds (wall clock) between two looks for silent units: each looks at every unit."""
RETURN_BUDGET = 10.0
"""Seconds after the observer's reconnect within which the units it heard before are to be
heard again (each its second heartbeat: they reconnect on their own time, by their own
backoff), plus two of their longest declared heartbeat periods; until then, or until all are
back, the gap stays open (as the suite keeps it open until its unit is back)."""


class Linter:
    """Feeds a Monitor and tallies violations per unit and rule (bounded memory).

    ``fresh`` holds the first violation of each (unit, rule) not yet shown, ``fleet`` the
    latest fleet observations, ``events`` capture events not yet shown.
    """

    def __init__(self, monitor: Monitor, profile: Profile | None = None) -> None:
        self.monitor = monitor
        self.profile = profile or Profile()
        self.messages = 0
        self.violations = 0
        self.unexamined = 0
        self.first_time: float | None = None
        self.last_time: float | None = None
        self.by_unit: dict[str, Counter[str]] = {}
        self.firm: dict[str, set[str]] = {}
        """Per unit, the rules of which a condition the spec's words state was found (the
        others' findings so far are decided conditions: they warn unless adopted)."""
        self.fresh: list[tuple[Violation, float | None]] = []
        """(violation, the arrival time of the message that showed it)."""
        self.fleet: deque[Violation] = deque(maxlen=50)
        self.events: list[Event] = []
        self.gaps: list[Gap] = []
        self._open_gap: Gap | None = None
        self._unit_of_topic: dict[str, str] = {}
        self._returning: dict[str, int] | None = None
        """After a reconnect, until every unit alive before it is heard again: heartbeats
        seen since, per unit (``_watch_return``)."""
        self._return_by = 0.0
        self.live = False
        """Live traffic: silences are measured up to the wall clock (``now``), not up to the
        latest message (a fleet that fell silent as a whole sends none)."""
        self._silences_watched = float("-inf")
        self.silent: dict[str, float] = {}
        """Units silent right now (``watch_silences``): their address -> their last
        heartbeat."""

    # --- feeding ----------------------------------------------------------------------------
    def feed(self, messages: list[Message]) -> None:
        """Examine a batch of messages (arrival order)."""
        if not messages:
            return
        feed = self.monitor.feed
        for m in messages:
            if self._returning is not None:
                self._watch_return(m)
            found = feed(m)
            if found:
                self._tally(found, m.time)
        self.messages += len(messages)
        if self.first_time is None:
            self.first_time = messages[0].time
        self.last_time = messages[-1].time

    def feed_one(self, m: Message) -> None:
        if self._returning is not None:
            self._watch_return(m)
        found = self.monitor.feed(m)
        if found:
            self._tally(found, m.time)
        self.messages += 1
        if self.first_time is None:
            self.first_time = m.time
        self.last_time = m.time

    def record(self, unit: Any, rule: str, violation: Violation | None = None) -> None:
        """A finding made outside the message checks (a ROS bag's types and names,
        ``conformance.rosbag``): into the Monitor's report, tallied like the others. ``unit``
        is a ``UnitAddress``, or None for a finding that names no unit."""
        self.monitor.record(unit, rule, violation=violation)
        if violation is not None:
            self._tally([violation], violation.time)

    def event(self, event: Event) -> None:
        """A capture event: a lost or regained connection, or messages not examined; a
        recording's start and end only mark how long the observation lasted."""
        if event.kind in ("start", "end"):
            return
        if event.kind == "disconnected":
            if self._open_gap is None:
                self._open_gap = Gap(event.time, None, event.detail)
        elif event.kind == "connected":
            if self._open_gap is not None:
                self._close_gap(event.time)
        elif event.kind == CUT:  # a message whose content is unknown: as a gap, at a point
            self.monitor.connection_gap(event.time, event.time)
        elif event.kind == "unexamined" and event.count > 0:
            self.unexamined += event.count
            self.monitor.unexamined(event.count)
        self.events.append(event)
        del self.events[:-100]

    def _close_gap(self, end: float, *, final: bool = False) -> None:
        gap = self._open_gap
        assert gap is not None
        self._open_gap = None
        end = max(end, gap.start)
        closed = Gap(gap.start, end, gap.reason)
        self.gaps.append(closed)
        # Rates, silences and deadlines over a time we could not see are not judged (the
        # Monitor leaves it out), nor until the units alive before are heard again.
        if final:
            self.monitor.connection_gap(closed.start, end)
            return
        self.monitor.connection_gap(closed.start, None)
        units = [u for u in self.monitor.units() if self._alive_at(u, closed.start)]
        self._returning = {str(u): 0 for u in units}
        periods = [self.monitor.state(u).period("heartbeat") or 1.0 for u in units]
        self._return_by = end + RETURN_BUDGET + 2 * max(periods, default=1.0)
        if not units:
            self._heard_again(end)

    def _alive_at(self, unit: Any, t: float) -> bool:
        """Whether ``unit`` was heard within 3 heartbeat periods (at least 3 s) before ``t``."""
        state = self.monitor.state(unit)
        last = state.last_seen
        return last is not None and last >= t - 3 * max(1.0, state.period("heartbeat") or 1.0)

    def _watch_return(self, m: Message) -> None:
        """Before ``m`` is judged: close the open gap once every unit alive before it has
        heartbeated twice since the reconnect, or at the budget's end."""
        assert self._returning is not None
        if m.time >= self._return_by:
            self._heard_again(self._return_by)
        elif not m.retain and m.topic.endswith("/heartbeat"):
            unit = parse_topic(m.topic).unit
            key = str(unit) if unit is not None else None
            if key in self._returning:
                self._returning[key] += 1
                if all(n >= 2 for n in self._returning.values()):
                    self._heard_again(m.time)

    def _heard_again(self, t: float) -> None:
        self._returning = None
        self.monitor.heard_again(t)

    @property
    def open_gap(self) -> Gap | None:
        return self._open_gap

    def finish(self, now: float) -> None:
        """End of the run at ``now`` (Unix seconds): close an open gap, run the finish checks
        (their findings are in the Monitor's report)."""
        if self._open_gap is not None:
            self._close_gap(now, final=True)
        if self._returning is not None:
            self._heard_again(min(now, self._return_by))
        self.monitor.finish(now)

    # --- liveness, live -----------------------------------------------------------------------
    def now(self) -> float | None:
        """The time silences are measured at: the wall clock on live traffic, else the latest
        message's time (Unix seconds; None before the first)."""
        return time.time() if self.live else self.last_time

    def watch_silences(self) -> None:
        """Which units are silent right now (their heartbeat missing for more than
        ``SILENCE_PERIODS`` periods: ``checks.liveness.death``, the measure HB-010 and
        HB-012 judge by), each new one a fleet observation as it happens. Nobody is silent
        while the observer itself cannot hear (an open gap, or units not yet back after
        it). A unit heard again leaves the set; HB-010 then judges its silence."""
        from conformance.checks.liveness import SILENCE_PERIODS, death, heartbeat_period

        tick = time.monotonic()
        if tick - self._silences_watched < WATCH_EVERY:  # a look at every unit: bounded
            return
        self._silences_watched = tick
        now = self.now()
        if now is None or self._open_gap is not None or self._returning is not None or \
                getattr(self.monitor, "untimed", False):  # a capture without times
            self.silent = {}
            return
        silent = {}
        for unit in list(self.monitor.units()):
            state = self.monitor.state(unit)
            dead = death(self.monitor.ctx, state, now)
            if dead is None:
                continue
            key = str(getattr(state, "address", None) or unit)
            silent[key] = dead[1]
            if key not in self.silent:
                period = heartbeat_period(state)
                self.fleet.append(Violation(
                    "HB-010", f"a heartbeat at least every {SILENCE_PERIODS * period:.3g} s "
                    f"({SILENCE_PERIODS:g} heartbeat periods)",
                    f"silent since {_clock(dead[1])}: "
                    f"no heartbeat for {now - dead[1]:.1f} s (live: shown back when heard)",
                    topic=f"{key}/heartbeat", time=now, unit=key))
        for key, last in self.silent.items():
            if key not in silent:  # heard again: the silence's end is an observation too
                self.fleet.append(Violation(
                    "HB-010", "a heartbeat at least every 3 heartbeat periods",
                    f"silent from {_clock(last)} until heard again, {now - last:.0f} s or less "
                    f"(live; HB-010 judges the silence)", topic=f"{key}/heartbeat",
                    time=now, unit=key))
        self.silent = silent

    # --- tallies ----------------------------------------------------------------------------
    def unit_of(self, v: Violation) -> str:
        """The unit a violation is about (its ``unit``, else the unit of its topic)."""
        if v.unit:
            return v.unit
        cache = self._unit_of_topic
        unit = cache.get(v.topic)
        if unit is None:
            parsed = parse_topic(v.topic)
            unit = parsed.unit.base if parsed.unit is not None else NOT_A_UNIT
            if len(cache) >= MAX_TOPIC_CACHE:
                cache.clear()
            cache[v.topic] = unit
        return unit

    def _tally(self, found: list[Violation], when: float | None) -> None:
        by_unit = self.by_unit
        for v in found:
            self.violations += 1
            unit = self.unit_of(v)
            counts = by_unit.get(unit)
            if counts is None:
                if len(by_unit) >= MAX_TALLIED:
                    unit = OTHER_UNITS
                    counts = by_unit.setdefault(unit, Counter())
                else:
                    counts = by_unit[unit] = Counter()
            if v.rule not in counts:
                self.fresh.append((v, when if when is not None else v.time))
            counts[v.rule] += 1
            if v.condition == "" or not self._decided(v):
                self.firm.setdefault(unit, set()).add(v.rule)
            if v.rule in FLEET_RULES:
                self.fleet.append(v)

    def take_fresh(self) -> list[tuple[Violation, float | None]]:
        """First violations of each (unit, rule) since the last call."""
        fresh, self.fresh = self.fresh, []
        return fresh

    def take_events(self) -> list[Event]:
        events, self.events = self.events, []
        return events

    @staticmethod
    def _decided(v: Violation) -> bool:
        rule = CATALOGUE.get(v.rule)
        return rule is not None and rule.decided(v.condition)

    def is_error(self, rule: str, unit: str | None = None) -> bool:
        """Whether a violation of ``rule`` fails (else warns), as the judge will say at the
        end (``judge.violation_verdict``: a decided rule, or a rule of whose ``unit`` only
        decided conditions were found, warns unless the profile adopts it)."""
        found = CATALOGUE.get(rule)
        severity = self.profile.severity_of(rule)
        if found is None:
            return severity is Severity.ERROR
        strict = self.profile.adopts(rule)
        if unit is not None and not strict and rule not in self.firm.get(unit, ()):
            return False
        return violation_verdict(found, severity, strict=strict) is Verdict.FAIL

    def fails(self, v: Violation) -> bool:
        """Whether the finding ``v`` on its own fails (its condition's basis, the profile)."""
        rule = CATALOGUE.get(v.rule)
        if rule is None:
            return self.profile.severity_of(v.rule) is Severity.ERROR
        return violation_verdict(rule, self.profile.severity_of(v.rule),
                                 strict=self.profile.adopts(v.rule),
                                 condition=v.condition) is Verdict.FAIL

    def failing_units(self) -> list[str]:
        """Units with a violation of a rule of severity error so far."""
        return sorted(u for u, counts in self.by_unit.items()
                      if any(self.is_error(r, u) for r in counts))


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t))

"""What ``lint --serve`` shows, as immutable snapshots made in lint's own thread.

The Monitor and the Linter are fed and read only by lint's loop; the web server
(``lint.serve``) runs in other threads and reads nothing but the latest ``Snapshot``, which
``FleetView.observe`` replaces (one reference assignment) at most once a second, when the
scorecard is updated. A snapshot holds a row per unit and commander (status, declared and
measured rates with their recent history, worst findings), the first evidence of each finding,
the fleet-level findings and the counts ``/metrics`` exposes. At the end of the run
``FleetView.finish`` makes the last one from the run report (finish-time judgements included).

Everything is bounded: rows by the Monitor's units and commanders bound, the rate history of
at most ``MAX_PLOTTED`` units over ``HISTORY_S`` seconds, evidence per (unit, rule) once, at
most ``MAX_EVIDENCE`` of them.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

from conformance.facts import RunFacts, RunKind
from conformance.judge import judge
from conformance.lint.linter import FLEET_RULES
from conformance.lint.rows import STATUS_ORDER, LintRow, live_rows, report_rows, seen_fields
from conformance.report_meta import RunMeta
from conformance.reporting.jsonreport import dumps
from conformance.results import Party
from conformance.violation import Verdict, Violation

SNAPSHOT_EVERY = 1.0
"""Seconds (wall clock) between two snapshots while lint runs, at least; a snapshot that took
long spaces the next ones (``COST_SHARE``)."""
COST_SHARE = 0.1
"""At most this share of lint's time goes to snapshots (a fleet of thousands is shown less
often, never slows the judging down more)."""
SAMPLE_EVERY = 2.5
"""Seconds of traffic time between two samples of each unit's message counts (rate plots)."""
PLOT_WINDOW = 4
"""Each plotted point is the rate over the latest 4 sample intervals (10 s): a 1 Hz unit's
counts per 2.5 s jump between 2 and 3."""
HISTORY_S = 300.0
"""The rate plots cover the latest five minutes of traffic."""
MAX_PLOTTED = 256
"""Units whose rate history is kept (the first seen); further units show their rates only."""
MAX_EVIDENCE = 20_000
"""First violations kept for the unit pages (one per unit and rule)."""
WORST_SHOWN = 3
"""Findings named in a row of the fleet page."""
REPORT_EVERY = 2.0
"""Seconds between two reports made for ``/report.json`` while lint runs (made on request)."""


@dataclass(frozen=True)
class RateView:
    """A periodic message kind of a unit: declared and measured rates in Hz, and the measured
    rate over time as (traffic time in Unix seconds, Hz)."""

    kind: str
    declared: float | None
    measured: float | None
    history: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class Row(LintRow):
    """A unit or a commander as the fleet page shows it: what lint saw (``lint.rows``), its
    rates and its messages by kind."""

    rates: tuple[RateView, ...] = ()
    by_kind: tuple[tuple[str, int], ...] = ()
    """Messages by topic kind."""


@dataclass(frozen=True)
class Snapshot:
    """The fleet as it stood at ``made`` (wall clock); ``now`` is the time its silences were
    measured at (``Linter.now``: the wall clock live, else the traffic's latest time)."""

    version: int
    made: float
    now: float | None
    title: str
    live: bool
    finished: bool
    messages: int
    dropped: int
    gaps: int
    connected: bool | None
    rows: tuple[Row, ...] = ()
    fleet: tuple[tuple[str, Violation], ...] = ()
    """The latest fleet-level findings (silence, identity, answers to nothing), oldest first."""
    verdict: str = ""
    not_judged: str = ""

    def row(self, unit: str) -> Row | None:
        for r in self.rows:
            if r.unit == unit:
                return r
        return None

    def counts(self, party: Party = Party.UNIT) -> dict[str, int]:
        """Rows of ``party`` (unit or commander) by status."""
        out = dict.fromkeys(STATUS_ORDER, 0)
        for r in self.rows:
            if r.party == party:
                out[r.status] += 1
        return out


def _sorted(rows: list[Row]) -> tuple[Row, ...]:
    return tuple(sorted(rows, key=lambda r: (STATUS_ORDER[r.status], r.party != Party.UNIT,
                                             r.pseudo, r.unit)))


class FleetView:
    """Makes the snapshots of a lint run (call ``observe`` from lint's loop, ``finish`` once at
    the end); ``snapshot`` is read from any thread."""

    def __init__(self, title: str, *, live: bool) -> None:
        self.title = title
        self.live = live
        self._snapshot = Snapshot(0, time.time(), None, title, live, False, 0, 0, 0, None)
        self._last = float("-inf")
        self._every = SNAPSHOT_EVERY
        self._samples: dict[tuple[str, str], deque[tuple[float, int]]] = {}
        self._plotted: set[str] = set()
        self._last_sample: float | None = None
        self._evidence: dict[tuple[str, str], Violation] = {}
        self._report: bytes | None = None
        self._report_made = float("-inf")
        self._report_wanted = threading.Event()
        self._report_ready = threading.Condition()
        self._report_meta: dict[str, Any] = {}
        self._final_report: Any = None
        self._report_final: bytes | None = None

    @property
    def snapshot(self) -> Snapshot:
        return self._snapshot

    # --- lint's thread ------------------------------------------------------------------------
    def observe(self, linter: Any, *, connected: bool | None = None, force: bool = False) -> None:
        """Take what is new from ``linter`` (the first violation of each unit and rule, before
        the scorecard takes them) and, at most once a second, make a new snapshot."""
        for v, when in linter.fresh:
            key = (linter.unit_of(v), v.rule)
            if key not in self._evidence and len(self._evidence) < MAX_EVIDENCE:
                self._evidence[key] = v if v.time is not None or when is None else _at(v, when)
        self._sample(linter)  # on traffic time: a recording is read faster than real time
        now = time.monotonic()
        if not force and now - self._last < self._every:
            return
        self._last = now
        self._snapshot = self._make(linter, connected)
        self._every = max(SNAPSHOT_EVERY, (time.monotonic() - now) / COST_SHARE)
        if self._report_wanted.is_set() and now - self._report_made >= REPORT_EVERY:
            self._report_wanted.clear()
            self._report_made = now
            self._publish_report(_provisional_report(linter, self._report_meta))

    def finish(self, linter: Any, report: Any, *, verdict: str, not_judged: str = "") -> None:
        """The last snapshot, from the run ``report`` (every verdict final)."""
        self._sample(linter)
        rates = {r.unit: r.rates for r in self._make(linter, None).rows}
        rows = [Row(**seen_fields(row), rates=rates.get(row.unit, ())) for row in report_rows(report)]
        fleet = _fleet_findings(report)
        old = self._snapshot
        with self._report_ready:  # written on the first request (the report is final)
            self._final_report = report
        self._snapshot = Snapshot(
            old.version + 1, time.time(), linter.last_time, self.title, self.live, True,
            linter.messages, report.unexamined, len(report.gaps), None, _sorted(rows), fleet,
            verdict=verdict, not_judged=not_judged)

    def report_meta(self, **meta: Any) -> None:
        """What the provisional reports say about the run (broker, source) and the facts
        they are judged under (``facts``: a ``RunFacts``)."""
        self._report_meta = meta

    # --- any thread ---------------------------------------------------------------------------
    def report_json(self, wait: float = 5.0) -> bytes | None:
        """The report as it stands: a fresh one made by lint's loop within ``wait`` seconds,
        else the latest made (None when none was made yet)."""
        with self._report_ready:
            if self._final_report is not None:
                if self._report_final is None:  # nothing changes it any more: any thread
                    self._report_final = dumps(self._final_report)
                return self._report_final
            made = self._report_made
            self._report_wanted.set()
            self._report_ready.wait_for(lambda: self._report_made != made, timeout=wait)
            return self._report

    # --- internals ----------------------------------------------------------------------------
    def _publish_report(self, data: bytes) -> None:
        with self._report_ready:
            self._report = data
            self._report_made = time.monotonic()
            self._report_ready.notify_all()

    def _sample(self, linter: Any) -> None:
        """Every ``SAMPLE_EVERY`` s of traffic time, each plotted unit's messages by kind."""
        now = linter.last_time
        if now is None or (self._last_sample is not None and now - self._last_sample < SAMPLE_EVERY):
            return
        self._last_sample = now
        monitor = linter.monitor
        keep = int(HISTORY_S / SAMPLE_EVERY) + 1
        for unit in monitor.units():
            key = str(unit)
            if key not in self._plotted:
                if len(self._plotted) >= MAX_PLOTTED:
                    continue
                self._plotted.add(key)
            state = monitor.state(unit)
            seen = state.kinds_seen
            for kind in state.declared_rates:
                samples = self._samples.get((key, _kind(kind)))
                if samples is None:
                    samples = self._samples[(key, _kind(kind))] = deque(maxlen=keep)
                samples.append((now, seen.get(kind, 0)))

    def _rates(self, key: str, state: Any, seen: dict[Any, int]) -> tuple[RateView, ...]:
        out = []
        first: dict[Any, float] | None = None
        last: dict[Any, float] = {}
        for kind, declared in state.declared_rates.items():
            samples = list(self._samples.get((key, _kind(kind)), ()))
            history = tuple((t1, (n1 - n0) / (t1 - t0)) for (t0, n0), (t1, n1)
                            in zip(samples, samples[PLOT_WINDOW:], strict=False) if t1 > t0)
            if not history and len(samples) > 1:  # the first seconds: one point from them all
                (t0, n0), (t1, n1) = samples[0], samples[-1]
                history = ((t1, (n1 - n0) / (t1 - t0)),) if t1 > t0 else ()
            measured = _recent_rate(samples)
            if measured is None:  # not plotted: over the whole observation
                if first is None:
                    first, last = state.first_by_kind, state.last_by_kind
                measured = _overall_rate(first.get(kind), last.get(kind), seen.get(kind, 0))
            out.append(RateView(_kind(kind), float(declared), measured, history))
        return tuple(out)

    def _make(self, linter: Any, connected: bool | None) -> Snapshot:
        monitor = linter.monitor
        states = {str(getattr(state, "address", unit)): state
                  for unit, state in ((u, monitor.state(u)) for u in list(monitor.units()))}
        done = []
        for seen in live_rows(linter, self._evidence):
            state = states.get(seen.unit)
            if state is None:
                done.append(Row(**seen_fields(seen)))
                continue
            kinds = state.kinds_seen
            done.append(Row(**seen_fields(seen), rates=self._rates(seen.unit, state, kinds),
                            by_kind=tuple(sorted((_kind(k), n) for k, n in kinds.items()))))
        fleet = tuple((linter.unit_of(v), v) for v in list(linter.fleet))
        old = self._snapshot
        now = linter.now() if hasattr(linter, "now") else linter.last_time
        return Snapshot(old.version + 1, time.time(), now, self.title, self.live,
                        False, linter.messages, linter.unexamined,
                        len(linter.gaps) + (linter.open_gap is not None), connected,
                        _sorted(done), fleet)


def _kind(kind: Any) -> str:
    """A topic kind's protocol name (``heartbeat``, ``sensor_info``)."""
    return kind if type(kind) is str else str(getattr(kind, "value", kind))


def _at(v: Violation, when: float) -> Violation:

    return dataclasses.replace(v, time=when)


def _recent_rate(samples: list[tuple[float, int]], span: float = 30.0) -> float | None:
    """Messages per second over the latest ``span`` seconds of samples."""
    if len(samples) < 2:
        return None
    t1, n1 = samples[-1]
    t0, n0 = next(((t, n) for t, n in samples if t1 - t <= span), samples[-2])
    if t0 >= t1:
        t0, n0 = samples[-2]
    return (n1 - n0) / (t1 - t0) if t1 > t0 else None


def _overall_rate(first: float | None, last: float | None, n: int) -> float | None:
    """Messages per second between the first and the latest live one."""
    return (n - 1) / (last - first) if first is not None and last and last > first and n > 1 \
        else None


def _fleet_findings(report: Any, limit: int = 50) -> tuple[tuple[str, Violation], ...]:
    found = [(v.time or 0.0, unit, v) for unit, u in report.units.items()
             for rule, res in u.rules.items()
             if rule in FLEET_RULES and res.verdict in (Verdict.FAIL, Verdict.WARN)
             for v in res.violations[:5]]
    found.sort(key=lambda f: f[0])
    return tuple((unit, v) for _, unit, v in found[-limit:])


def _provisional_report(linter: Any, meta: dict[str, Any]) -> bytes:
    """The report as it stands, judged (end-of-run checks judged at the latest time, not
    stored); ``meta``: ``facts`` (``RunFacts``) and what the report says of the run."""
    meta = dict(meta)
    facts = meta.pop("facts", None) or RunFacts(kind=RunKind.LINT)
    said = RunMeta(provisional="the run goes on: this is the report as it stands")
    report = linter.monitor.report(said, finished=None, **meta)
    return dumps(judge(report, facts))

"""``/metrics`` of ``lint --serve``: the latest fleet snapshot (``lint.fleetview``) in the
Prometheus text exposition format, written by ``prometheus_client``, so an arena's Prometheus
and Grafana can alert on a unit that turns non-conformant
(``waraps_lint_unit_failing{unit="..."} == 1``).

Unit names come from topics (anything a publisher chose): each label value is made printable
(control characters shown escaped, ``display.printable``) and cut at ``NAME_CHARS``, a digest
of the whole name added where it was altered (``label``: a series per unit); each
labelled family holds at most ``MAX_SERIES`` series, the rest summed into one series labelled
``(other units)``, so a flood of invented unit names cannot flood a time-series database.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from typing import Any

from conformance.display import NAME_CHARS, printable, shorten
from conformance.lint.fleetview import Snapshot
from conformance.lint.linter import OTHER_UNITS

MAX_SERIES = 5000
"""Series per labelled metric family (``bounds.MAX_UNITS`` units would need 4096 each)."""
STATUS_WORDS = {"FAIL": "fail", "warn": "warn", "ok": "clean", "-": "silent"}


def label(text: str) -> str:
    """A label value from wire text: printable, at most ``NAME_CHARS`` characters, and one
    per name: a name that had to be escaped or cut ends in ``#`` and a digest of the whole
    name, so two names never share a series (past 200 characters, 'u\\x1b' written out and
    'u' with an ESC). A topic name holds no '#' (MQTT 4.7.1), so no name reads as one
    altered."""
    # Cut after escaping: 200 control characters escape to 800 (the digest tells them apart).
    shown = shorten(printable(text), NAME_CHARS)
    if shown == text:
        return shown
    digest = hashlib.blake2b(text.encode("utf-8", "surrogatepass"), digest_size=6).hexdigest()
    return f"{shown} #{digest}"


class _Capped:
    """Adds samples to a family, at most ``MAX_SERIES`` label sets; the values of further
    ones are summed under ``(other units)`` in place of the unit."""

    def __init__(self, family: Any, unit_at: int = 0) -> None:
        self.family = family
        self.unit_at = unit_at
        self.seen: set[tuple[str, ...]] = set()
        self.over: dict[tuple[str, ...], float] = {}

    def add(self, labels: list[str], value: float) -> None:
        key = tuple(labels)
        if key in self.seen or len(self.seen) < MAX_SERIES:
            self.seen.add(key)
            self.family.add_metric(labels, value)
        else:
            other = list(labels)
            other[self.unit_at] = OTHER_UNITS
            self.over[tuple(other)] = self.over.get(tuple(other), 0.0) + value

    def done(self) -> Any:
        for labels, value in self.over.items():
            self.family.add_metric(list(labels), value)
        return self.family


class SnapshotCollector:
    """A ``prometheus_client`` collector of the snapshot ``latest()`` returns (no state of its
    own: each scrape reads the latest snapshot)."""

    def __init__(self, latest: Callable[[], Snapshot]) -> None:
        self.latest = latest

    def collect(self) -> Iterator[Any]:
        from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

        s = self.latest()
        units = GaugeMetricFamily("waraps_lint_units", "Units and commanders by their status "
                                  "so far (fail, warn, clean, silent)", labels=["party", "status"])
        by = {(p, w): 0 for p in ("unit", "commander") for w in STATUS_WORDS.values()}
        for row in s.rows:
            by[(row.party, STATUS_WORDS[row.status])] += 1
        for (party, status), n in sorted(by.items()):
            units.add_metric([party, status], n)
        yield units
        failing = _Capped(GaugeMetricFamily(
            "waraps_lint_unit_failing", "1 when the unit or commander fails a rule of severity "
            "error so far (or a rate is off over its latest intervals), else 0",
            labels=["unit", "party"]))
        findings = _Capped(CounterMetricFamily(
            "waraps_lint_findings", "Violations found, by unit (or commander) and rule",
            labels=["unit", "rule", "verdict"]))
        messages = _Capped(CounterMetricFamily(
            "waraps_lint_unit_messages", "Messages read, by unit and topic kind",
            labels=["unit", "kind"]))
        rates = _Capped(GaugeMetricFamily(
            "waraps_lint_rate_hz", "Declared and measured (latest 30 s) rate of each periodic "
            "message kind, Hz", labels=["unit", "kind", "which"]))
        for row in s.rows:
            name = label(row.unit)
            failing.add([name, row.party], 1.0 if row.status == "FAIL" else 0.0)
            for f in row.findings:
                findings.add([name, f.rule, f.verdict], float(f.count))
            for kind, n in row.by_kind:
                messages.add([name, kind], float(n))
            for r in row.rates:
                if r.declared is not None:
                    rates.add([name, r.kind, "declared"], r.declared)
                if r.measured is not None:
                    rates.add([name, r.kind, "measured"], r.measured)
        yield from (failing.done(), findings.done(), messages.done(), rates.done())
        yield _counter(CounterMetricFamily, "waraps_lint_messages",
                       "Messages read by the linter", s.messages)
        yield _counter(CounterMetricFamily, "waraps_lint_dropped_messages",
                       "Messages not examined (the linter fell behind the broker, or a "
                       "capture could not print them)", s.dropped)
        yield _counter(CounterMetricFamily, "waraps_lint_observer_gaps",
                       "Connection gaps of the observer (rates over them are not judged)", s.gaps)
        done = GaugeMetricFamily("waraps_lint_finished", "1 once the run has ended and every "
                                 "verdict is final", value=1.0 if s.finished else 0.0)
        yield done


def _counter(cls: Any, name: str, doc: str, value: float) -> Any:
    family = cls(name, doc)
    family.add_metric([], float(value))
    return family


def exposition(latest: Callable[[], Snapshot]) -> bytes:
    """The text exposition of the latest snapshot."""
    from prometheus_client import CollectorRegistry, generate_latest

    registry = CollectorRegistry(auto_describe=False)
    registry.register(SnapshotCollector(latest))
    return generate_latest(registry)

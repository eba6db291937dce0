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
from conformance.lint.rows import STATUS_WORDS
from conformance.results import Party

MAX_SERIES = 5000
"""Series per labelled metric family (``bounds.MAX_UNITS`` units would need 4096 each)."""


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
                                  "(silent now, fail, warn, clean so far; unheard: nothing of "
                                  "its own seen)", labels=["party", "status"])
        by = {(p, w): 0 for p in Party for w in STATUS_WORDS.values()}
        for row in s.rows:
            by[(row.party, STATUS_WORDS[row.status])] += 1
        for (party, status), n in sorted(by.items()):
            units.add_metric([party, status], n)
        yield units
        # A family without a sample is left out (a HELP and TYPE over nothing).
        yield from (f for f in _row_families(s) if f.samples)
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
        yield GaugeMetricFamily(  # a lint whose loop stopped stops moving it (alert rules)
            "waraps_lint_snapshot_timestamp_seconds", "When lint last took stock of the "
            "fleet (at least every few seconds while it runs), Unix seconds", value=s.made)


def _row_families(s: Snapshot) -> list[Any]:
    """The families with a series per unit (or commander), from the snapshot's rows."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    failing = _Capped(GaugeMetricFamily(
        "waraps_lint_unit_failing", "1 when the unit or commander fails a rule so far as the "
        "verdict will say (or a rate is off over its latest intervals), else 0; a silence is "
        "waraps_lint_unit_up", labels=["unit", "party"]))
    up = _Capped(GaugeMetricFamily(
        "waraps_lint_unit_up", "1 while the unit is heard, 0 once its heartbeat is missing "
        "for more than 3 of its periods (silent; 1 again when it is heard)", labels=["unit"]))
    last_seen = _Capped(GaugeMetricFamily(
        "waraps_lint_unit_last_seen_timestamp_seconds", "When the unit's latest message "
        "arrived, Unix seconds", labels=["unit"]))
    findings = _Capped(CounterMetricFamily(
        "waraps_lint_findings", "Violations found, by unit (or commander) and rule",
        labels=["unit", "rule", "verdict"]))
    messages = _Capped(CounterMetricFamily(
        "waraps_lint_unit_messages", "Messages read, by unit and topic kind",
        labels=["unit", "kind"]))
    periods = _Capped(GaugeMetricFamily(  # base units: seconds, not Hz
        "waraps_lint_period_seconds", "Declared and measured (latest 30 s) period of each "
        "periodic message kind (1 / its rate), seconds", labels=["unit", "kind", "which"]))
    for row in s.rows:
        name = label(row.unit)
        failing.add([name, row.party], 1.0 if row.failing else 0.0)
        if row.party == "unit" and not row.pseudo and row.messages:
            up.add([name], 0.0 if row.status == "silent" else 1.0)
            if row.last_seen is not None:
                last_seen.add([name], row.last_seen)
        for f in row.findings:
            findings.add([name, f.rule, f.verdict], float(f.count))
        for kind, n in row.by_kind:
            messages.add([name, kind], float(n))
        for r in row.rates:
            for which, rate in (("declared", r.declared), ("measured", r.measured)):
                if rate:
                    periods.add([name, r.kind, which], 1.0 / rate)
    return [f.done() for f in (failing, up, last_seen, findings, messages, periods)]


def _counter(cls: Any, name: str, doc: str, value: float) -> Any:
    family = cls(name, doc)
    family.add_metric([], float(value))
    return family


CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
"""The text format ``exposition`` writes, as Prometheus expects it (prometheus_client's
``CONTENT_TYPE_LATEST`` names 1.0.0, which its ``generate_latest`` does not write)."""


def exposition(latest: Callable[[], Snapshot]) -> bytes:
    """The text exposition (format 0.0.4) of the latest snapshot."""
    from prometheus_client import CollectorRegistry, generate_latest

    registry = CollectorRegistry(auto_describe=False)
    registry.register(SnapshotCollector(latest))
    return generate_latest(registry)

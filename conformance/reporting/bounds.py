"""Every report file has a size bound whatever the input: ``MAX_REPORT_BYTES``.

A writer renders through ``bounded``: the report as it is when it fits; else the same report
with less in it, chosen from the size of a sample of its units: first each rule's evidence cut
to one violation, then only as many units as fit, the worst first. What was left out is said in
the report itself (``meta['report_truncated']``, which every format shows), so the file is
always whole and never silently partial. The strings in it are excerpted by the writers
(``display.shorten``). The exit status and the terminal are not affected: they come from the
whole report.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Callable
from typing import TypeVar

from conformance.report_meta import RunMeta
from conformance.results import RunReport
from conformance.violation import Verdict

MAX_REPORT_BYTES = 10_000_000
"""The largest report file written, in bytes (each of JSON, HTML and JUnit)."""
SAMPLE_UNITS = 8
TRUNCATED = "report_truncated"
"""The JSON ``meta`` key that says what a bounded report left out (``RunMeta``'s field)."""

Out = TypeVar("Out", str, bytes)

STEM_CHARS = 80
"""The most characters of a name a report's file name keeps (file systems allow 255 bytes)."""


def file_stem(name: str, limit: int = STEM_CHARS) -> str:
    """``name`` (a unit's, a recording's: anything a person or a unit chose) as the start of a
    report's file name: itself when it is at most ``limit`` characters of ``A-Za-z0-9._-``;
    else those characters kept, others as '_', cut to ``limit``, and a hash of the whole so
    that two names never share a file (a 300-character unit name)."""
    safe = "".join(c if c.isascii() and (c.isalnum() or c in "._-") else "_" for c in
                   name[:limit + 1]).lstrip(".")
    if safe == name and len(name) <= limit:
        return name
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:10]
    return f"{safe[:limit]}-{digest}"


def bounded(render: Callable[[RunReport], Out], report: RunReport,
            limit: int | None = None) -> Out:
    """``render(report)``, or the render of a smaller copy of it that fits in ``limit`` bytes
    (default ``MAX_REPORT_BYTES``), with a note of what was left out. Linear in the report's
    size: the whole report is rendered only when a sample says it fits."""
    limit = MAX_REPORT_BYTES if limit is None else limit
    units = len(report.units)
    if units > SAMPLE_UNITS and _estimate(render, report) > limit:
        out = None  # too large for sure: no need to render it whole
    else:
        out = render(report)
        if _size(out) <= limit:
            return out
    one = _evidence_cut(report, limit)
    if units <= SAMPLE_UNITS or _estimate(render, one) <= limit:
        out = render(one)
        if _size(out) <= limit:
            return out
    # Only as many units as fit, the worst first; halved until it fits (a unit can be large).
    per_unit = max(1.0, _estimate(render, one) / max(1, units))
    keep = min(units, max(1, int(limit * 0.9 / per_unit)))
    while True:
        smaller = _units_cut(one, keep, limit)
        out = render(smaller)
        if _size(out) <= limit or keep == 0:
            return out if _size(out) <= limit else render(_units_cut(one, 0, limit))
        keep //= 2


def _size(out: str | bytes) -> int:
    """Bytes of a rendered report as written (UTF-8)."""
    return len(out) if isinstance(out, bytes) or out.isascii() else len(out.encode("utf-8", "surrogatepass"))


def _estimate(render: Callable[[RunReport], Out], report: RunReport) -> float:
    """Bytes ``render(report)`` would take, from a sample of its units (the largest of
    ``SAMPLE_UNITS`` taken across the report, so one hostile unit is not averaged away)."""
    names = list(report.units)
    if len(names) <= SAMPLE_UNITS:
        return float(_size(render(report)))
    step = len(names) / SAMPLE_UNITS
    sample = [names[int(i * step)] for i in range(SAMPLE_UNITS)]
    empty = _size(render(dataclasses.replace(report, units={})))
    sizes = [_size(render(dataclasses.replace(report, units={n: report.units[n]}))) - empty
             for n in sample]
    return empty + sum(sizes) / len(sizes) * len(names)


def _note(report: RunReport, text: str) -> RunMeta:
    before = report.meta.report_truncated
    return dataclasses.replace(report.meta,
                               report_truncated=f"{before}; {text}" if before else text)


def _evidence_cut(report: RunReport, limit: int) -> RunReport:
    """Each rule's evidence cut to its first violation (counts and verdicts are kept)."""
    cut = 0
    units = {}
    for name, unit in report.units.items():
        rules = {}
        for rid, result in unit.rules.items():
            if len(result.violations) > 1:
                cut += len(result.violations) - 1
                result = dataclasses.replace(result, violations=result.violations[:1])
            rules[rid] = result
        units[name] = dataclasses.replace(unit, rules=rules)
    if not cut:
        return report
    note = (f"the report was over {limit / 1e6:g} MB: each rule shows its first violation only "
            f"({cut} more left out; the counts are whole)")
    return dataclasses.replace(report, units=units, meta=_note(report, note))


def _units_cut(report: RunReport, keep: int, limit: int) -> RunReport:
    """The ``keep`` worst units (then by name), with a note of the others' verdicts."""
    names = sorted(report.units, key=lambda n: (-report.units[n].worst().rank, n))
    kept = set(names[:keep])
    left = [report.units[n] for n in names[keep:]]
    worst: dict[str, int] = {}
    for unit in left:
        v = unit.worst().value
        worst[v] = worst.get(v, 0) + 1
    order = [v.value for v in sorted(Verdict, key=lambda v: -v.rank)]
    said = ", ".join(f"{worst[v]} {v}" for v in order if v in worst)
    note = (f"{len(left)} of {len(report.units)} units left out to stay under {limit / 1e6:g} MB "
            f"(their worst verdicts: {said}); the units shown are the worst first; the verdict "
            f"counts are of the units shown")
    return dataclasses.replace(
        report, units={n: u for n, u in report.units.items() if n in kept},
        meta=_note(report, note))

"""The HTML report: one self-contained file (inline CSS and SVG, no script, no network).

It opens with what a person came for: the run's verdict and why (``conformance.conclusion``:
``not certified``, ``interrupted`` or ``partial`` when the run did not complete or selected
rules, never a pass), each unit's status and levels (lint: what it observed, never a
certificate) and the failing rules. Then the header facts, each once and in words (kind, units, broker, profile,
agent-uuids, times, suite version, schemas hash, verdict counts), then per unit a scorecard
(verdict per rule with title, spec section and reason), a plot of every measured rate over time
against the declared rate, and the evidence of every failure and warning.

The markup lives in Jinja2 templates (``reporting/templates/``, package data) rendered with
autoescape on: everything a template prints is escaped unless a template made it, so escaping
cannot be forgotten (payloads, topics, unit names and details are hostile input). This module
only chooses and orders what is shown, and computes the plots' geometry.
"""

from __future__ import annotations

import functools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from conformance.conclusion import NOT_RUN, Conclusion, UnitStatus, facts_of, ranked_findings
from conformance.conclusion import of as conclusion_of
from conformance.display import shorten
from conformance.report_meta import RERUN_OF
from conformance.reporting.bounds import bounded
from conformance.reporting.files import atomic_write
from conformance.reporting.text import iso_time, printable, rerun_command
from conformance.results import Party, RateStat, RunReport, UnitReport
from conformance.rules import CATALOGUE, reading
from conformance.violation import RuleResult, Verdict, Violation

if TYPE_CHECKING:
    from jinja2 import Environment

COLOURS = {
    Verdict.PASS: "#1a7f37", Verdict.FAIL: "#cf222e", Verdict.WARN: "#9a6700",
    Verdict.SKIP: "#6e7781", Verdict.COULD_NOT_TEST: "#8250df",
}
ORDER = [Verdict.FAIL, Verdict.WARN, Verdict.COULD_NOT_TEST, Verdict.PASS, Verdict.SKIP]
RUN_VERDICT_COLOURS = {"not certified": "#cf222e", "interrupted": "#bc4c00",
                       "partial": "#bc4c00", "clean": "#1a7f37"}
# What the run was (RunReport.meta, by its JSON keys) in words, in this order, then the
# others; those shown elsewhere (the heading, the story) are left out.
META_WORDS = (("profile_source", "profile file"), ("timing_scale", "timing scale"),
              ("seed", "seed"), ("dry_run", "dry run"), ("allow_motion", "motion allowed"),
              ("reboot", "reboot"), ("commands_sent", "commands sent"),
              ("rerun", "repeat this run"))
META_SHOWN_ELSEWHERE = {"unit", "agent_uuid", "exit_status", "explore_story"}
SERIES_COLOURS = ["#0969da", "#bf3989", "#1a7f37", "#bc4c00", "#8250df", "#6e7781"]


def _finalize(value: Any) -> Any:
    """What a template prints: None as nothing, long strings excerpted and control characters
    made visible (wire data may hold anything); markup a template made itself passes as it is
    (autoescape does the rest)."""
    # The __html__ protocol, not isinstance(Markup): an in-process pytester run can drop
    # markupsafe from sys.modules, and a re-imported Markup class is another class than the
    # one the cached environment's templates make (their markup was escaped twice).
    if hasattr(value, "__html__"):
        return value
    return "" if value is None else printable(shorten(value))


@functools.cache
def environment() -> Environment:
    """The templates' environment, made once (jinja2 is imported only when a report is
    rendered: importing the package stays cheap)."""
    from jinja2 import Environment, PackageLoader, StrictUndefined

    env = Environment(loader=PackageLoader("conformance.reporting", "templates"),
                      autoescape=True, finalize=_finalize, undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True)
    env.globals.update(colours=COLOURS, order=ORDER, run_colours=RUN_VERDICT_COLOURS,
                       catalogue=CATALOGUE, anchor=anchor, iso_time=iso_time,
                       as_verdict=as_verdict, grouped=grouped)
    return env


def anchor(unit: str) -> str:
    return "u-" + "".join(c if c.isalnum() else "-" for c in unit)


def as_verdict(text: str) -> Verdict | None:
    """A rule verdict by its name; None for a run's own verdict (``not certified``...)."""
    try:
        return Verdict(text)
    except ValueError:
        return None


def run_verdict(report: RunReport) -> str:
    """The run's verdict (``conformance.conclusion``: the one verdict model)."""
    return conclusion_of(report).verdict


def render_html(report: RunReport, files: list[str] | None = None) -> str:
    """The whole report as one HTML document; ``files`` are the names of the files written
    with it (the footer says which)."""
    conclusion = conclusion_of(report)
    found = ranked_findings(report)
    units = [_unit(name, unit, conclusion.units[name]) for name, unit in report.units.items()]
    # A failed or warned rate rule shows its rate over time with its evidence.
    rate_plots: dict[tuple[str, str], list[Plot]] = {}
    for view in units:
        for plot in view.plots:
            if plot.stat.rule and plot.stat.verdict in (Verdict.FAIL, Verdict.WARN):
                rate_plots.setdefault((view.name, plot.stat.rule), []).append(plot)
    failing = [(u, r) for _, u, r in found if r.verdict is Verdict.FAIL]
    warned = [(u, r) for _, u, r in found if r.verdict is Verdict.WARN]
    return environment().get_template("report.html.j2").render(
        report=report, title=f"WARA-PS conformance {report.kind} report",
        verdict=conclusion.verdict, conclusion=conclusion, failing=failing, warned=warned,
        reruns={(u, r.rule): rerun_of(report, u, r) for u, r in failing + warned},
        untested=untested(report), untimed=facts_of(report).untimed,
        story=(report.meta.explore_story or "").split("\n"),
        gaps=[(a, b) for a, b in report.gaps if b - a >= MIN_GAP],
        head=_head_facts(report, conclusion), units=units, rate_plots=rate_plots,
        written=", ".join(files or [])) + "\n"


def rerun_of(report: RunReport, unit: str, result: RuleResult) -> str:
    """The command that reruns ``result``'s rule on ``unit``: the one the certification
    printed (``RunMeta.rerun_of``), else the report's own (``text.rerun_command``)."""
    said = report.meta.rerun_of.get(result.rule) if unit == report.meta.unit else None
    topic = result.violations[0].topic if result.violations else ""
    return str(said or rerun_command(report, unit, result.rule, topic))


IDENTIFIER = re.compile(r"[0-9a-fA-F]{8}-[0-9a-fA-F-]{27,}|\d+(?:\.\d+)?")
"""What differs between violations alike: uuids (com-uuid, task-uuid) and numbers."""


def grouped(violations: list[Violation]) -> list[list[Violation]]:
    """Violations alike (the same words, topic, path and hint but for their identifiers and
    numbers: twenty heartbeats with the same wrong type, each ping unanswered) in one group
    each, in the order of their first."""
    groups: dict[tuple[str, ...], list[Violation]] = {}
    for v in violations:
        key = (IDENTIFIER.sub("#", v.expected), IDENTIFIER.sub("#", v.observed), v.topic,
               v.path, IDENTIFIER.sub("#", v.detail))
        groups.setdefault(key, []).append(v)
    return list(groups.values())


MIN_GAP = 0.05
"""Seconds: a shorter observer gap is noise (it would read '0.0 s'), not shown."""


@dataclass
class Untested:
    """Rules of one unit that could not be tested for one reason (the reason names the option
    that would test them: ``--reboot-cmd``, ``--allow-motion``...)."""

    unit: str
    reason: str
    rules: list[str]
    not_run: bool
    """The rules never ran (not selected, the run cut short): no option tests them."""


def untested(report: RunReport) -> list[Untested]:
    """The could-not-test rules grouped by unit and reason, the ones that ran first."""
    not_run = set(report.not_run)
    groups: dict[tuple[str, str], Untested] = {}
    for name, unit in report.units.items():
        for r in unit.rules.values():
            if r.verdict is Verdict.COULD_NOT_TEST:
                key = (name, r.reason or "")
                group = groups.setdefault(key, Untested(name, r.reason or "", [],
                                                         r.rule in not_run))
                group.rules.append(r.rule)
    return sorted(groups.values(), key=lambda g: (g.not_run, -len(g.rules), g.unit))


@dataclass
class HeadFacts:
    """The header facts the template does not read straight off the report."""

    counts: dict[str, int]
    not_run: int
    exit_status: Any
    agent_uuids: list[tuple[str, str]]
    """(unit, its agent-uuids), for every unit that has a name."""
    meta: list[tuple[str, str]]


def _head_facts(report: RunReport, conclusion: Conclusion) -> HeadFacts:
    # The counts every output shows: the rules that never ran apart ('not run').
    counts = dict(conclusion.counts)
    not_run = counts.pop(NOT_RUN, 0)
    words = dict(META_WORDS)

    meta = [("rules", reading(conclusion.strict))]
    said = report.meta.to_dict()  # the JSON's keys: the page shows what the JSON says
    for key in dict.fromkeys([k for k, _ in META_WORDS] + sorted(said)):
        value = said.get(key)
        if value and key not in META_SHOWN_ELSEWHERE and not key.startswith(RERUN_OF):
            meta.append((words.get(key, key.replace("_", " ")), value))
    exit_status = report.meta.exit_status
    return HeadFacts(counts, not_run, conclusion.exit_code if exit_status is None else exit_status,
                     [(n, ", ".join(u.agent_uuids) or "-") for n, u in report.units.items()
                      if n != "(unattributed)"], meta)


@dataclass
class UnitView:
    """One unit's section: its rules ranked worst first, skips apart, and its rate plots."""

    name: str
    unit: UnitReport
    counts: dict[str, int]
    identity: str
    """agent-type / role / name"""
    agent_uuids: str
    levels: str
    sensors: str
    """The sensors its sensor_info lists, '' when it lists none."""
    shown: list[RuleResult]
    skipped: list[RuleResult]
    bad: list[RuleResult]
    plots: list[Plot] = field(default_factory=list)
    sparks: dict[str, Spark] = field(default_factory=dict)
    """rule -> its rate's small plot (a rate rule shows its intervals, not a count)."""
    verdict: str = ""
    """The row's verdict in the verdict model's words (lint: clean, warn, fail)."""
    status: str = ""
    """What the verdict model says of it (``UnitStatus.summary``)."""


def _unit(name: str, unit: UnitReport, status: UnitStatus) -> UnitView:
    ranked = sorted(unit.rules.values(), key=lambda r: ORDER.index(r.verdict))
    view = UnitView(name, unit, unit.verdict_counts(),
                    identity=f"{unit.agent_type} / {unit.role} / {unit.name}",
                    agent_uuids=", ".join(unit.agent_uuids) or "-",
                    levels=", ".join(unit.levels) or "-",
                    sensors=", ".join(unit.facts.sensors_listed),
                    shown=[r for r in ranked if r.verdict is not Verdict.SKIP], skipped=[],
                    bad=[], verdict=status.verdict, status=status.summary)
    if unit.party == Party.COMMANDER:  # what it sent, judged by the commander's rules
        return view
    view.skipped = [r for r in ranked if r.verdict is Verdict.SKIP]
    view.bad = [r for r in ranked if r.verdict in (Verdict.FAIL, Verdict.WARN)]
    view.plots = [plot_of(r, i) for i, r in enumerate(unit.rates)]
    view.sparks = sparks(unit)
    return view


@dataclass
class Spark:
    """A rate rule's intervals as a small plot in its scorecard row: the measured rate over
    time (the worst of its kinds), the declared rate dashed."""

    points: str
    declared_y: float | None
    words: str
    w: int = 120
    h: int = 22


def sparks(unit: UnitReport) -> dict[str, Spark]:
    """One small plot per rate rule of ``unit``: its worst rate (a failing one first)."""
    found: dict[str, Spark] = {}
    for stat in sorted(unit.rates, key=lambda s: ORDER.index(s.verdict)):
        if stat.rule in found or not stat.rule:
            continue
        pts = [(t, r) for t, r in stat.series if r == r and r != float("inf")]
        t0 = pts[0][0] if pts else 0.0
        span = (max(t for t, _ in pts) - t0 if pts else 0.0) or 1.0
        top = max([r for _, r in pts] + [(stat.declared_hz or 0) * 1.5, 1e-9]) * 1.1
        if stat.declared_hz:
            top = min(top, stat.declared_hz * 4)  # a burst would flatten the rest
        spark = Spark("", None, "")
        w, h = spark.w - 2, spark.h - 2
        spark.points = " ".join(f"{1 + (t - t0) / span * w:.1f},"
                                f"{1 + (1 - min(r, top) / top) * h:.1f}" for t, r in pts)
        if stat.declared_hz:
            spark.declared_y = 1 + (1 - min(stat.declared_hz, top) / top) * h
        declared = f"declared {stat.declared_hz:.2f} Hz" if stat.declared_hz else "none declared"
        spark.words = (f"{stat.kind}: {stat.measured_hz:.2f} Hz over {stat.intervals} intervals, "
                       f"{declared}" if stat.measured_hz else f"{stat.kind}: not measured")
        found[stat.rule] = spark
    return found


@dataclass
class Plot:
    """A rate plot's geometry in SVG user units (pixels): measured rate (Hz) over time, the
    declared rate dashed, the tolerance band when known."""

    stat: RateStat
    colour: str
    declared: str
    measured: str
    points: list[tuple[float, float]]
    band: tuple[float, float] | None = None
    """(y, height) of the tolerance band."""
    declared_y: float | None = None
    clipped: float | None = None
    """The rate (Hz) the plot is clipped at, if it is."""
    ticks: list[tuple[float, float]] = field(default_factory=list)
    """(y, rate in Hz) of the axis labels."""
    span: float = 0.0
    """Seconds the plot covers."""
    # The frame in SVG user units: its size, and the margins around the plotting area.
    w, h, left, right, top, bottom = 380, 170, 44, 10, 10, 26


def plot_of(stat: RateStat, index: int) -> Plot:
    """The geometry of ``stat``'s plot; ``index`` picks its colour."""
    p = Plot(stat, SERIES_COLOURS[index % len(SERIES_COLOURS)],
             declared=f"{stat.declared_hz:.2f} Hz" if stat.declared_hz else "none",
             measured=(f"{stat.measured_hz:.2f} Hz over {stat.intervals} intervals"
                       if stat.measured_hz else "not measured"), points=[])
    pts = [(t, r) for t, r in stat.series if r == r and r != float("inf")]
    t0 = stat.start if stat.start is not None else (pts[0][0] if pts else 0.0)
    t1 = max([stat.end or t0] + [t for t, _ in pts])
    # Every point at one instant: t0 + 1e-9 rounds back to t0 at 1.7e9 s (found by
    # fuzz/message_path: a ZeroDivisionError writing the HTML report).
    width = t1 - t0 if t1 > t0 else 1.0
    ymax = max([r for _, r in pts] + [(stat.declared_hz or 0) * 1.5, 1e-9]) * 1.1
    if stat.declared_hz and ymax > stat.declared_hz * 4:
        # A burst at 1000x the declared rate would flatten everything else: clip at 4x.
        ymax = p.clipped = stat.declared_hz * 4
        pts = [(t, min(r, ymax)) for t, r in pts]

    def x(t: float) -> float:
        return p.left + (t - t0) / width * (p.w - p.left - p.right)

    def y(r: float) -> float:
        return p.top + (1 - r / ymax) * (p.h - p.top - p.bottom)

    if stat.declared_hz:
        tol = stat.tolerance
        if tol is not None and 0 <= tol < 1:
            hi, lo = stat.declared_hz / (1 - tol), stat.declared_hz / (1 + tol)
            p.band = (y(min(hi, ymax)), max(0.0, y(lo) - y(min(hi, ymax))))
        p.declared_y = y(stat.declared_hz)
    p.points = [(x(t), y(r)) for t, r in pts]
    p.ticks = [(y(r), r) for r in (0.0, ymax if p.clipped else ymax / 1.1)]
    p.span = t1 - t0
    return p


def rate_plot(stat: RateStat, index: int) -> str:
    """One rate plot on its own (a figure: caption and SVG)."""
    return environment().get_template("rate_plot.html.j2").render(plot=plot_of(stat, index))


def write_html(report: RunReport, path: str | os.PathLike[str],
               files: list[str] | None = None) -> Path:
    """Write the report as one self-contained HTML file (atomically); the path written.
    ``files``: the names of the other files written with it."""
    return atomic_write(path, bounded(lambda r: render_html(r, files), report))

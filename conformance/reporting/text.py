"""Reports for people, as text: one violation in the form every output shares, and a
run's summary."""

from __future__ import annotations

import shlex
from datetime import UTC, datetime

from conformance.conclusion import LINT_NEVER_CERTIFIES, TRIAGE, ranked_findings
from conformance.conclusion import of as conclusion_of
from conformance.display import printable, shorten
from conformance.facts import RunKind
from conformance.results import RunReport
from conformance.rules import CATALOGUE, Rule, Severity
from conformance.topics import TopicError, UnitAddress, parse_topic
from conformance.violation import RuleResult, Verdict, Violation

TITLE_WIDTH = 64


def iso_time(t: float | None) -> str:
    """A Unix time as ISO 8601 UTC with milliseconds, '' for None."""
    if t is None:
        return ""
    try:
        return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds")
    except (OverflowError, OSError, ValueError):
        return repr(t)


def rerun_command(report: RunReport | None, unit: str, rule_id: str, topic: str = "") -> str:
    """How to repeat what found a violation of ``rule_id`` on ``unit``: for a lint report
    ``waraps-conformance lint --from <recording> --unit <unit>`` (or ``--broker <url>`` and
    its TLS options when it linted live traffic); for a certification (or no report) ``pytest --unit <unit> -k
    <rule>``. ``report`` is a ``RunReport``: its kind, broker and meta say which. A
    commander's row ('commander alice') is no unit: its finding is repeated by linting the
    unit whose command ``topic`` it was found on (or every unit, when the topic names none)."""
    if report is None or report.kind != RunKind.LINT:
        return f"pytest --unit {shlex.quote(unit)} -k {shlex.quote(rule_id)}"
    try:
        unit = UnitAddress.parse(unit).base
    except TopicError:
        parsed = parse_topic(topic).unit if topic else None
        unit = parsed.base if parsed is not None else ""
    only = f" --unit {shlex.quote(unit)}" if unit else ""
    meta = report.meta
    source = meta.source or ""
    broker = report.broker
    if broker and meta.recording_lines is None:  # live traffic (the URL has no password)
        tls = meta.tls_options or ""  # already shell-quoted
        return (f"waraps-conformance lint --broker {shlex.quote(broker)}"
                + (f" {tls}" if tls else "") + only)
    if not source or source in ("-", "<stdin>") or source.startswith("live "):
        source = shlex.quote("<recording>")  # a placeholder, but never a redirection
    else:
        source = shlex.quote(source)
    return f"waraps-conformance lint --from {source}{only}"


def render_violation(rule: str | Rule, violation: Violation, unit: str = "",
                     rerun_hint: str | None = None, verdict: Verdict | None = None,
                     report: RunReport | None = None) -> str:
    """One violation for a person (the form every output shares): rule id, title and verdict;
    expected; observed; topic; spec section; how to rerun. ``rerun_hint`` None gives the command for
    the unit (``rerun_command``: the lint command for a lint ``report``, else pytest), '' leaves the
    line out. ``verdict`` defaults to the rule's own severity."""
    r = rule if isinstance(rule, Rule) else CATALOGUE.get(rule)
    rule_id = r.id if r else str(rule)
    title = r.title if r else ""
    if verdict is None:
        verdict = Verdict.WARN if r is not None and r.severity is Severity.WARNING else Verdict.FAIL
    unit = unit or violation.unit
    head = f"{rule_id} {printable(title)}"
    lines = [f"{head:<{TITLE_WIDTH}} [{verdict.value}]"]

    def line(label: str, value: object) -> None:
        if value not in ("", None):
            lines.append(f"  {label:<9} {printable(shorten(value))}")

    line("expected", violation.expected)
    line("observed", violation.observed)
    line("topic", violation.topic)
    line("path", violation.path)
    line("at", iso_time(violation.time))
    line("payload", violation.excerpt)
    line("spec", r.section if r else "")
    if r is not None and violation.condition:  # the condition found, on its own basis
        try:
            found = r.condition(violation.condition)
            line("condition", found.title)
            line("basis", found.basis_text())
        except KeyError:
            line("basis", r.basis_text())
    else:
        line("basis", r.basis_text() if r else "")
    line("hint", violation.detail)
    if rerun_hint is None and unit:
        rerun_hint = rerun_command(report, unit, rule_id, violation.topic or "")
    line("rerun", rerun_hint or "")
    return "\n".join(lines)


def render_summary(report: RunReport) -> str:
    """A few lines per unit: verdict counts and the failing and warning rules."""
    conclusion = conclusion_of(report)  # the one verdict model: its words and counts
    out = [f"{report.kind} report, profile {report.profile}, broker {report.broker or '-'}: "
           f"{printable(conclusion.headline())}; "
           + ", ".join(f"{n} {v}" for v, n in conclusion.counts.items() if n)]
    for name, unit in report.units.items():
        c = unit.verdict_counts()
        status = conclusion.units[name]
        out.append(f"  {printable(shorten(name))}  [{status.verdict}]  {printable(status.summary)}; "
                   + ", ".join(f"{n} {v}" for v, n in c.items() if n))
        for r in unit.rules.values():
            if r.verdict in (Verdict.FAIL, Verdict.WARN):
                rule = CATALOGUE.get(r.rule)
                out.append(f"    {r.rule:<16} {r.verdict.value:<5} "
                           f"{printable(rule.title if rule else '')} ({printable(shorten(r.reason))})")
    if report.unexamined:
        out.append(f"  {report.unexamined} messages could not be examined")
    return "\n".join(out)


FINDINGS_PER_UNIT = 5
"""Findings shown per unit in the verdicts that open lint's text output (the reports hold all)."""


def render_verdicts(report: RunReport, per_unit: int = FINDINGS_PER_UNIT) -> str:
    """What lint's text output opens with: the run's verdict and counts (the same
    counts as the JSON and HTML reports), then each unit's verdict and its most severe findings
    first (``conformance.conclusion.TRIAGE``), units with the most severe findings first. A
    cap cuts only the least severe."""
    conclusion = conclusion_of(report)
    counts = ", ".join(f"{n} {v}" for v, n in conclusion.counts.items() if n)
    out = [f"verdict: {conclusion.verdict} ({counts})"
           + (f"; {LINT_NEVER_CERTIFIES}" if report.kind == RunKind.LINT else "")]
    by_unit: dict[str, list[tuple[int, RuleResult]]] = {}
    for rank, unit, result in ranked_findings(report):
        by_unit.setdefault(unit, []).append((rank, result))
    order = sorted(conclusion.units, key=lambda u: (
        by_unit[u][0][0] if u in by_unit else len(TRIAGE), u))
    for name in order:
        status = conclusion.units[name]
        rep = report.units[name]
        out.append(f"  {status.verdict.upper() if status.verdict == 'fail' else status.verdict:<5} "
                   f"{printable(name)}: {printable(status.summary)}")
        found = by_unit.get(name, [])
        for rank, result in found[:per_unit]:
            rule = CATALOGUE.get(result.rule)
            n = rep.violation_counts.get(result.rule, len(result.violations))
            what = f"{n} violation{'s' * (n != 1)}" if n else printable(result.reason)
            out.append(f"        {TRIAGE[rank]:<9} {result.rule} "
                       f"{printable(rule.title if rule else '')}: {what}")
        if len(found) > per_unit:
            out.append(f"        ... and {len(found) - per_unit} less severe: every finding is "
                       f"in the reports")
    return "\n".join(out)

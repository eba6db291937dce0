"""What a certification's terminal says at its end: the summary section (the unit's verdict,
its levels, the failed rules, what could not be tested and why, the reports, the line that
repeats the run) and the exit line after pytest's own counts. Every line goes through the
one escape (``printable_lines``) and never shows a password."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping
from typing import Any

import pytest

from conformance.conclusion import of as conclusion_of
from conformance.conclusion import ranked_findings
from conformance.display import printable, printable_lines
from conformance.masking import mask_password
from conformance.reporting import render_violation
from conformance.reporting.htmlreport import untested
from conformance.results import RunReport, UnitReport
from conformance.rules import CATALOGUE
from conformance.suite.gate import last_line
from conformance.suite.session import Certification
from conformance.violation import Verdict

Line = Callable[..., None]
"""Writes one line of the summary: ``line(text, red=True)``."""


def write_summary(c: Certification, tr: Any, explore_outcome: str) -> None:
    """The ``waraps-conformance`` section of pytest's terminal summary (``tr``: pytest's
    terminal reporter)."""

    def line(text: str, **markup: bool) -> None:
        # The unit's own words (its levels, names, reasons) never reach the terminal raw;
        # our own line breaks stay. Never a password (§5): the repeat line, an error's URL.
        tr.line(printable_lines(mask_password(text)), **markup)

    c.progress.clear()
    tr.section("waraps-conformance")
    if c.error:  # what went wrong and how to fix it; the verdict line below says no more
        line(f"not certified: {c.error}", red=True)
    for event in c.events:
        line(printable(event))
    report = c.report()
    conclusion = conclusion_of(report)
    counts = ", ".join(f"{n} {v}" for v, n in conclusion.counts.items() if n)
    head = conclusion.verdict if c.error else conclusion.headline()
    # The rules' counts, and the exploration apart: together they are pytest's tests.
    explored = f"; exploration: {explore_outcome}" if explore_outcome else ""
    line(f"{printable(c.unit)}: {printable(head)}; rules: {counts}{printable(explored)}",
         red=conclusion.verdict not in ("pass", "warn"))
    unit = conclusion.units.get(str(c.unit))
    for level in unit.levels if unit is not None else ():
        line(f"  {printable(level)}")
    for text in findings(report, str(c.unit), error_said=bool(c.error)):
        line(text, red=text.startswith("  failed"))
    for text in skipped_by_reason(report.units.get(str(c.unit))):
        line(text)
    if conclusion.judged_after_test:
        _failed_after(c, report, conclusion.judged_after_test, line)
    changed = judged_otherwise(c.evidence.enacted, report.units.get(str(c.unit)))
    if changed:
        line("judged otherwise at the end than when their tests ran (pytest shows the "
             "latter; the whole run has the last word, the reason is above): "
             + "; ".join(f"{r} {shown.value} -> {final.value}" for r, shown, final in changed))
    for kind, path in sorted(c.reports.paths.items()):
        line(f"{kind} report: {printable(path)}")
    if c.reports.error:
        line(c.reports.error, red=True)
    if not c.reports.paths:
        line("no report was written")
    line(f"repeat this run: {printable(c.rerun_command())}")


def exit_line(c: Certification, status: int) -> str:
    """The exit status and why (README 'Exit status'), so a log says what a gate read; the
    rules whose tests failed and that the whole run does not fail are named."""
    report = c.report()
    row = report.units.get(str(c.unit))
    failed_then = tuple(r for r, shown, _ in judged_otherwise(c.evidence.enacted, row)
                        if shown is Verdict.FAIL)
    text = last_line(report, conclusion_of(report), str(c.unit), status,
                     error_said=bool(c.error), failed_then=failed_then)
    return printable_lines(mask_password(text))


def _failed_after(c: Certification, report: RunReport, later: tuple[str, ...],
                  line: Line) -> None:
    """The rules whose tests passed before the traffic that fails them came: said, each with
    its first violation (the evidence came from a later scenario: the whole run reproduces
    it)."""
    line(f"failed after their tests ran (later traffic is evidence too; the "
         f"reports hold it): {printable(', '.join(later))}", red=True)
    rules = report.units[str(c.unit)].rules
    for rule in later:
        for v in rules[rule].violations[:1]:
            line(render_violation(rule, v, str(c.unit), rerun_hint=c.rerun_command()))


def judged_otherwise(enacted: Mapping[str, Verdict], row: UnitReport | None
                     ) -> list[tuple[str, Verdict, Verdict]]:
    """(rule, the verdict its test showed, the whole run's) where the two differ and the run's
    is no fail (those are "failed after their tests ran"): a gap found later (the broker
    stalled, the host held the unit) or the unit's death excuses what fell in it, the
    evidence a test had read too; an answer that came late is no longer missing."""
    if row is None:
        return []
    return [(r, shown, row.rules[r].verdict) for r, shown in sorted(enacted.items())
            if r in row.rules and row.rules[r].verdict not in (shown, Verdict.FAIL)]


def explore_outcome(report: pytest.TestReport, explored: str) -> str:
    """``pass (5 examples, 120 steps in 50 s ...)``, ``fail``, ``could-not-test (why)``."""
    if report.skipped:
        reason = str(report.longrepr[-1]) if isinstance(report.longrepr, tuple) else ""
        reason = reason.removeprefix("Skipped: ")
        if reason.startswith("could not test: "):
            return f"could-not-test ({reason.removeprefix('could not test: ')})"
        return f"skip ({reason})" if reason else "skip"
    word = "pass" if report.passed else "fail"
    return f"{word} ({explored})" if explored else word


def findings(report: RunReport, unit: str, *, error_said: bool = False) -> list[str]:
    """What the summary names after the levels: each failed rule with its title
    (its evidence is in pytest's failures above), then the rules that could not be tested,
    grouped by their reason, which names the option that would test them (``--reboot-cmd``),
    and the rules not run, counted (unless the error that kept them from running was said:
    ``error_said``)."""
    if unit not in report.units:
        return []
    # Most severe first, the order of the reports (conclusion.TRIAGE).
    lines = [f"  failed  {r.rule} {printable(CATALOGUE[r.rule].title)}"
             for _, name, r in ranked_findings(report)
             if name == unit and r.verdict is Verdict.FAIL and r.rule in CATALOGUE]
    for group in untested(report):
        if group.unit != unit:
            continue
        if group.not_run:
            if error_said:
                continue
            why = group.reason.removeprefix("not run: ")  # each word once
            lines.append(f"  not run {len(group.rules):>3}  {printable(why)}")
        else:
            lines.append(f"  could not test {', '.join(group.rules)}: "
                         f"{printable(group.reason)}")
    return lines


def skipped_by_reason(unit: UnitReport | None) -> list[str]:
    """The rules skipped as not applicable, grouped by their reason (one line a reason, not
    one a rule): ``skipped  17 not claimed: unit declares no 'tst execution' level``."""
    if unit is None:
        return []
    reasons = Counter(r.reason or "not examined" for r in unit.rules.values()
                      if r.verdict is Verdict.SKIP)
    return [f"  skipped {n:>3}  {printable(reason)}" for reason, n in reasons.most_common()]

"""Verdicts as pytest outcomes, without ever turning a skip into a pass (docs/ARCHITECTURE.md
'Verdicts').

pass -> passed; fail -> failed, with the violations rendered as every output shows them
(``render_violation``); warn -> passed with a ``ConformanceWarning`` (and the verdict in the test's
properties); skip -> skipped with its reason; could-not-test -> skipped, the reason prefixed "could
not test:".
"""

from __future__ import annotations

import warnings

import pytest

from conformance.display import printable
from conformance.reporting import render_violation
from conformance.rules import CATALOGUE
from conformance.suite.session import Certification
from conformance.violation import RuleResult, Verdict

SHOWN = 3
"""Violations shown per failing test; the reports hold the rest (up to the Monitor's limit)."""


class ConformanceWarning(pytest.PytestWarning):
    """A rule judged 'warn': an erratum reading or a recommended practice (the test passes)."""


def explain(certification: Certification, result: RuleResult) -> str:
    rule = CATALOGUE[result.rule]
    rerun = certification.rerun_command(result.rule)
    texts = [render_violation(rule, v, str(certification.unit), rerun_hint=rerun,
                              verdict=result.shown_as(i))
             for i, v in enumerate(result.violations[:SHOWN])]
    if not texts:
        # A verdict a scenario recorded without a violation (REBOOT-001's new name) quotes
        # the spec's words as every violation does.
        texts = [f"{rule.id} {rule.title}  [{result.verdict.value}]\n  {printable(result.reason)}\n"
                 f"  spec      {rule.section}\n  basis     {printable(rule.basis_text())}\n"
                 f"  rerun     {printable(rerun)}"]
    total = certification.judging.violation_total(result.rule) or len(result.violations)
    shown = min(SHOWN, len(result.violations))
    if total > shown:
        # A total, not the number kept as evidence (the Monitor keeps the first few).
        kept = len(result.violations)
        paths = certification.reports.paths.get("html")
        where = "" if not paths or kept <= shown else (
            f"; all in {printable(paths)}" if kept >= total
            else f"; the first {kept} in {printable(paths)}")
        texts.append(f"({shown} of {total} violations shown{where})")
    return "\n\n".join(texts)


def locate_skip(item: pytest.Item, report: pytest.TestReport) -> None:
    """A skip of a rule's test is located at its rule (``SKIPPED [1] HB-010: ...``), not at
    the line of the suite that raised it."""
    marker = item.get_closest_marker("waraps_rule")
    if marker is not None and report.skipped and isinstance(report.longrepr, tuple):
        # pytest prints (path, lineno, reason); lineno None leaves the line out.
        report.longrepr = (marker.args[0], None, report.longrepr[2])  # type: ignore[assignment]


def enact(certification: Certification, rule: str, node: pytest.Item) -> None:
    """Turn the verdict of ``rule`` for the unit under test into this test's outcome."""
    result = certification.result(rule)
    certification.evidence.enacted[rule] = result.verdict
    node.user_properties.append(("verdict", result.verdict.value))
    if result.reason:
        node.user_properties.append(("reason", result.reason))
    if result.verdict is Verdict.FAIL:
        pytest.fail(explain(certification, result), pytrace=False)
    if result.verdict is Verdict.WARN:
        # Located at the rule, not at this line: the suite's source is not the finding.
        warnings.warn_explicit(ConformanceWarning(explain(certification, result)),
                               ConformanceWarning, filename=rule, lineno=0, registry=None)
    elif result.verdict is Verdict.SKIP:
        pytest.skip(printable(result.reason or "not examined"))
    elif result.verdict is Verdict.COULD_NOT_TEST:
        pytest.skip(printable(f"could not test: {result.reason}"))

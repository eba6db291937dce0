"""Verdicts as pytest outcomes, without ever turning a skip into a pass (DESIGN 'Semantics').

pass -> passed; fail -> failed, with the violations rendered as STYLE.md shows them; warn ->
passed with a ``ConformanceWarning`` (and the verdict in the test's properties); skip ->
skipped with its reason; could-not-test -> skipped, the reason prefixed "could not test:".
"""

from __future__ import annotations

import warnings

import pytest

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
                              verdict=result.verdict) for v in result.violations[:SHOWN]]
    if not texts:
        texts = [f"{rule.id} {rule.title}  [{result.verdict.value}]\n  {result.reason}\n"
                 f"  spec      {rule.section}\n  rerun     {rerun}"]
    more = len(result.violations) - SHOWN
    if more > 0 or (result.reason and "violation" in result.reason and more >= 0):
        paths = certification.report_paths.get("html")
        texts.append(f"({result.reason}" + (f"; all in {paths})" if paths else ")"))
    return "\n\n".join(texts)


def enact(certification: Certification, rule: str, node: pytest.Item) -> None:
    """Turn the verdict of ``rule`` for the unit under test into this test's outcome."""
    result = certification.result(rule)
    node.user_properties.append(("verdict", result.verdict.value))
    if result.reason:
        node.user_properties.append(("reason", result.reason))
    if result.verdict is Verdict.FAIL:
        pytest.fail(explain(certification, result), pytrace=False)
    if result.verdict is Verdict.WARN:
        warnings.warn(ConformanceWarning(explain(certification, result)), stacklevel=2)
    elif result.verdict is Verdict.SKIP:
        pytest.skip(result.reason or "not examined")
    elif result.verdict is Verdict.COULD_NOT_TEST:
        pytest.skip(f"could not test: {result.reason}")

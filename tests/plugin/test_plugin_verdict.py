"""A failing rule's text counts its violations in total, not only those kept as evidence
(suite/verdict.py, without a broker)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from conformance.suite.verdict import SHOWN, explain
from conformance.violation import RuleResult, Verdict, Violation


class Certification:
    """The part of a Certification that ``explain`` reads: its judged totals and its report
    files (``suite/judging.py``, ``suite/writing.py``)."""

    unit = "waraps/unit/air/simulation/dji0"

    def __init__(self, total: int, html: Path | None) -> None:
        self.judging = SimpleNamespace(violation_total=lambda rule: total)
        self.reports = SimpleNamespace(paths={"html": html} if html else {})

    def rerun_command(self, rule: str) -> str:
        return f"pytest --unit {self.unit} -k {rule}"


def failing(kept: int) -> RuleResult:
    found = [Violation.of("EXEC-FB-002", expected="a standard status", observed="'Starting'")
             for _ in range(kept)]
    return RuleResult("EXEC-FB-002", Verdict.FAIL, f"{kept} violations", found)


def test_the_count_is_the_total_and_says_where_the_rest_is() -> None:
    text = explain(Certification(19, Path("r.html")), failing(10))  # type: ignore[arg-type]
    assert text.count("EXEC-FB-002 feedback status") == SHOWN
    assert text.endswith(f"({SHOWN} of 19 violations shown; the first 10 in r.html)")
    text = explain(Certification(5, Path("r.html")), failing(5))  # type: ignore[arg-type]
    assert text.endswith(f"({SHOWN} of 5 violations shown; all in r.html)")


def test_no_count_line_when_every_violation_is_shown() -> None:
    text = explain(Certification(2, Path("r.html")), failing(2))  # type: ignore[arg-type]
    assert "violations shown" not in text

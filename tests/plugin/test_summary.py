"""The terminal's summary: a rule whose test showed one verdict and the whole run another
(a gap or a death found later excused its evidence) is named with both, so pytest's PASSED
or FAILED is not taken for the last word; one the whole run fails is said elsewhere
("failed after their tests ran")."""

from __future__ import annotations

from conformance.results import UnitReport
from conformance.suite.summary import judged_otherwise
from conformance.violation import RuleResult, Verdict

CNT, PASS, FAIL, WARN = Verdict.COULD_NOT_TEST, Verdict.PASS, Verdict.FAIL, Verdict.WARN


def _row(verdicts: dict[str, Verdict]) -> UnitReport:
    return UnitReport(unit="waraps/unit/air/simulation/dji0", agent_type="air",
                      role="simulation", name="dji0",
                      rules={r: RuleResult(r, v) for r, v in verdicts.items()})


def test_a_rule_judged_otherwise_is_named_with_both_verdicts() -> None:
    final = {"REBOOT-002": CNT, "EXEC-QUERY-002": CNT, "PING-001": PASS, "QUERY-001": CNT,
             "START-001": FAIL, "FB-001": CNT}
    shown = {"REBOOT-002": PASS, "EXEC-QUERY-002": FAIL, "PING-001": PASS, "QUERY-001": CNT,
             "START-001": PASS, "FB-001": WARN, "NOT-IN-ROW": PASS}
    assert judged_otherwise(shown, _row(final)) == [
        ("EXEC-QUERY-002", FAIL, CNT), ("FB-001", WARN, CNT), ("REBOOT-002", PASS, CNT)]


def test_no_row_names_nothing() -> None:
    assert judged_otherwise({"REBOOT-002": PASS}, None) == []

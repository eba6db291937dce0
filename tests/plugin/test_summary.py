"""The terminal's summary: a rule whose test passed when it ran and that the whole run could
not test (a gap found later excused its evidence) is named, so pytest's PASSED is not taken
for the last word."""

from __future__ import annotations

from conformance.results import UnitReport
from conformance.suite.summary import untested_after_passing
from conformance.violation import RuleResult, Verdict


def _row(**verdicts: Verdict) -> UnitReport:
    return UnitReport(unit="waraps/unit/air/simulation/dji0", agent_type="air",
                      role="simulation", name="dji0",
                      rules={r.replace("_", "-"): RuleResult(r.replace("_", "-"), v)
                             for r, v in verdicts.items()})


def test_a_rule_passed_then_untested_is_named_and_no_other() -> None:
    row = _row(REBOOT_002=Verdict.COULD_NOT_TEST, PING_001=Verdict.PASS,
               QUERY_001=Verdict.COULD_NOT_TEST, START_001=Verdict.COULD_NOT_TEST)
    enacted = {"REBOOT-002": Verdict.PASS, "PING-001": Verdict.PASS,
               "QUERY-001": Verdict.COULD_NOT_TEST,  # its test said so itself
               "START-001": Verdict.WARN}
    assert untested_after_passing(enacted, row) == ("REBOOT-002", "START-001")


def test_no_row_names_nothing() -> None:
    assert untested_after_passing({"REBOOT-002": Verdict.PASS}, None) == ()

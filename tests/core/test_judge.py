"""The one judge (conformance/judge.py): no other module decides or changes a verdict; a
decided rule warns unless the run is strict; lint's gate reaches its JSON and its exit status
alike."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest

from conformance.facts import RunFacts
from conformance.judge import judge, judge_rule, violation_verdict
from conformance.reporting.jsonreport import dumps
from conformance.results import RunReport, UnitReport
from conformance.rules import CATALOGUE, Basis, Severity
from conformance.violation import Observed, RuleResult, Verdict, Violation

PACKAGE = Path(__file__).resolve().parents[2] / "conformance"
JUDGE = PACKAGE / "judge.py"
# A verdict made or changed: a RuleResult built, a row's rule replaced, a verdict or a
# conclusion assigned.
MAKES_A_VERDICT = re.compile(r"RuleResult\(|\.rules\[[^\]]+\]\s*=(?!=)|"
                             r"\bconclusion\s*=\s*conclude\(|\.conclusion\s*=(?!=)")
READS_BACK = {PACKAGE / "results.py"}
"""Where a report written earlier is read back (its verdicts as written, not decided)."""


def code_lines(besides: Path) -> Iterator[tuple[Path, str, str]]:
    """(file, where, code without its comment) of every line of the package outside the
    judge and the folder ``besides``."""
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == JUDGE or path.is_relative_to(besides):
            continue
        for n, line in enumerate(path.read_text("utf-8").splitlines(), 1):
            yield path, f"{path.relative_to(PACKAGE.parent)}:{n}: {line.strip()}", \
                line.split("#", 1)[0]


def test_no_module_but_the_judge_makes_or_changes_a_verdict() -> None:
    offenders = [where for path, where, code in code_lines(PACKAGE / "sim")
                 if MAKES_A_VERDICT.search(code) and not (
                     path in READS_BACK and "def _rule_result_from_dict" in
                     path.read_text("utf-8") and "d[\"rule\"]" in code)]
    assert not offenders, "verdicts are made only by conformance/judge.py:\n" + "\n".join(
        offenders)


def test_the_grep_finds_a_planted_verdict(tmp_path: Path) -> None:
    planted = 'found.rules[rule] = RuleResult(rule, Verdict.SKIP, "x")'
    assert MAKES_A_VERDICT.search(planted)
    assert not MAKES_A_VERDICT.search("if found.rules[rule] == other:")


def decided(rule_id: str = "HB-003") -> object:
    return dataclasses.replace(CATALOGUE[rule_id], basis=Basis.DECIDED,
                               decision="this suite reads it so")


@pytest.mark.parametrize(("strict", "verdict"), [(False, Verdict.WARN), (True, Verdict.FAIL)])
def test_a_decided_rule_warns_as_an_interop_risk_unless_strict(strict: bool,
                                                                verdict: Verdict) -> None:
    v = Violation.of("HB-003", expected="1 Hz", observed="0.2 Hz")
    found = judge_rule(decided(), severity=Severity.ERROR, strict=strict,  # type: ignore[arg-type]
                       violations=[v])
    assert found.verdict is verdict
    assert ("interop risk: the spec does not say; this suite decided: this suite reads it so"
            in found.reason) is (not strict)
    stated = judge_rule(CATALOGUE["HB-003"], severity=Severity.ERROR, strict=False,
                        violations=[v])
    assert stated.verdict is Verdict.FAIL
    assert violation_verdict(decided(), Severity.ERROR, strict=strict) is verdict  # type: ignore[arg-type]


def test_what_a_scenario_saw_is_evidence_the_judge_reads() -> None:
    """A scenario records what it saw (examined, not applicable, untestable), never a
    verdict: the judge makes it one."""
    rule = CATALOGUE["EXEC-PING-001"]

    def judged(**kw: object) -> RuleResult:
        return judge_rule(rule, severity=Severity.ERROR, strict=False, violations=[],
                          **kw)  # type: ignore[arg-type]

    assert judged(examined=1).verdict is Verdict.PASS
    assert judged(explicit=Observed.UNTESTABLE, explicit_reason="no task").verdict is \
        Verdict.COULD_NOT_TEST
    # said so: a skip the unit's declarations explain keeps a claimed level certified
    assert judged(explicit=Observed.NOT_APPLICABLE, explicit_reason="not claimed").reason == \
        "not applicable: not claimed"


def test_no_scenario_or_statistic_sets_a_verdict() -> None:
    """Scenarios and rate statistics carry evidence and numbers: no ``verdict=Verdict.``
    passed or assigned outside the judge (report rendering names a verdict it was given)."""
    sets = re.compile(r"\bverdict\s*=\s*Verdict\.(PASS|FAIL|WARN|COULD_NOT_TEST)")
    offenders = [where for _, where, code in code_lines(PACKAGE / "reporting")
                 if sets.search(code)]
    assert not offenders, "\n".join(offenders)


def test_exploration_counts_as_a_disagreement_only_what_the_judge_fails() -> None:
    """A decided rule (EXEC-FB-004) is no disagreement of the exploration unless the profile
    adopts it (the public L2 agent's story showed it as '[fail]' while the run warned it)."""
    from conformance.profile import from_dict, load
    from conformance.scenarios.explore_steps import judged

    def found(rule: str, condition: str = "") -> Violation:
        return Violation.of(rule, expected="", observed="", condition=condition)

    default = load("default")  # what a unit's drafted profile extends
    assert not judged(found("EXEC-FB-004"), default)
    assert judged(found("EXEC-RESEND-001"), default)  # implied: fails
    assert judged(found("EXEC-FB-004"), load("strict"))
    assert judged(found("EXEC-FB-004"), from_dict({"extends": "default",
                                                   "severity": {"EXEC-FB-004": "error"}}))
    assert not judged(found("HB-003"), default)  # no rule about commands
    # A decided condition of a stated rule (a pong after the response timeout) likewise.
    assert judged(found("EXEC-PING-001"), default)
    assert not judged(found("EXEC-PING-001", "late"), default)
    assert judged(found("EXEC-PING-001", "late"), load("strict"))


def fleet() -> RunReport:
    """A unit that passes and a commander whose command broke a rule (EXEC-001)."""
    unit = UnitReport("waraps/unit/air/simulation/dji0", "air", "simulation", "dji0",
                      rules={"HB-001": RuleResult("HB-001", Verdict.PASS, "examined 3 times")})
    commander = UnitReport("op0 (commander)", "", "", "", party="commander", rules={
        "EXEC-001": RuleResult("EXEC-001", Verdict.FAIL, "1 violation",
                               [Violation.of("EXEC-001", expected="a com-uuid",
                                             observed="none")])})
    return RunReport("lint", 1.0, 2.0, units={unit.unit: unit, commander.unit: commander})


@pytest.mark.parametrize(("gate", "verdict", "code"), [("all", "fail", 1), ("units", "clean", 0)])
def test_lint_s_gate_reaches_the_json_and_the_exit_status_alike(gate: str, verdict: str,
                                                                code: int) -> None:
    report = judge(fleet(), RunFacts(kind="lint", gate=gate))
    data = orjson.loads(dumps(report))
    assert (report.conclusion.verdict, report.conclusion.exit_code) == (verdict, code)
    assert (data["verdict"], data["conclusion"]["exit_code"]) == (verdict, code)
    assert data["facts"]["gate"] == gate


def test_a_judged_report_s_verdicts_are_frozen() -> None:
    report = judge(fleet(), RunFacts(kind="lint"))
    with pytest.raises(TypeError):
        report.units["op0 (commander)"].rules["EXEC-001"] = RuleResult(
            "EXEC-001", Verdict.PASS)


def claimed(**rules: RuleResult) -> RunReport:
    """A certification's report of a unit on the sensor and direct execution levels."""
    unit = UnitReport(UNIT, "air", "simulation", "dji0", levels=["sensor", "direct execution"],
                      rules={"HB-001": RuleResult("HB-001", Verdict.PASS, "examined 3 times"),
                             **{r.rule: r for r in rules.values()}})
    return RunReport("certification", 1.0, 2.0, units={UNIT: unit})


UNIT = "waraps/unit/air/simulation/dji0"
UNSEEN = "no message this rule applies to was seen"


def test_a_rule_of_a_claimed_level_never_provoked_is_could_not_test_and_the_level_is_not_certified(
        ) -> None:
    """docs/ARCHITECTURE.md 'Verdicts': a level is certified only when every rule of it was judged
    on evidence. A conversation rule skipped for want of its messages means the suite did not
    provoke them (a signal accepted in words the suite did not read as acceptance)."""
    report = judge(claimed(a=RuleResult("EXEC-SEQ-001", Verdict.SKIP, UNSEEN)),
                   RunFacts(kind="certification", unit=UNIT))
    result = report.units[UNIT].rules["EXEC-SEQ-001"]
    assert result.verdict is Verdict.COULD_NOT_TEST
    assert result.reason == f"the suite did not provoke the evidence: {UNSEEN}"
    status = report.conclusion.units[UNIT]
    assert [(lv.level, lv.certified) for lv in status.levels] == [
        ("sensor", True), ("direct execution", False)]
    assert "1 could not be tested" in status.levels[1].why


@pytest.mark.parametrize("skipped", [
    RuleResult("EXEC-SEQ-001", Verdict.SKIP, "not applicable: no task in tasks-available "
                                             "lists $abort (5.3)"),  # its declarations
    RuleResult("TST-008", Verdict.SKIP, UNSEEN),  # a level it does not claim
    RuleResult("MSG-007", Verdict.SKIP, UNSEEN),  # passive: nothing retained, nothing to judge
    RuleResult("EXEC-001", Verdict.SKIP, UNSEEN),  # the commander's side
])
def test_skips_the_unit_s_declarations_explain_leave_its_levels_certified(
        skipped: RuleResult) -> None:
    report = judge(claimed(a=skipped), RunFacts(kind="certification", unit=UNIT))
    assert report.units[UNIT].rules[skipped.rule].verdict is Verdict.SKIP
    assert all(lv.certified for lv in report.conclusion.units[UNIT].levels)


def test_lint_never_turns_a_skip_into_could_not_test() -> None:
    report = judge(claimed(a=RuleResult("EXEC-SEQ-001", Verdict.SKIP, UNSEEN)),
                   RunFacts(kind="lint"))
    assert report.units[UNIT].rules["EXEC-SEQ-001"].verdict is Verdict.SKIP


def test_a_failed_rules_evidence_shows_what_fails_it_first() -> None:
    """A decided finding (SI-004's 'listed') found before the stated one: the failed rule's
    evidence holds the stated one first, the order every output shows; a strict run, in
    which each fails the rule, and a warning keep the order found. ``keep`` cuts after."""
    rule = CATALOGUE["SI-004"]
    listed = Violation.of("SI-004", condition="listed", expected="listed", observed="missing")
    stated = Violation.of("SI-004", expected="published", observed="nothing on heading")
    found = judge_rule(rule, severity=Severity.ERROR, strict=False,
                       violations=[listed, listed, stated], keep=2)
    assert found.verdict is Verdict.FAIL and found.violations == [stated, listed]
    assert found.reason == "3 violations"
    strict = judge_rule(rule, severity=Severity.ERROR, strict=True, violations=[listed, stated])
    assert strict.violations == [listed, stated]
    warned = judge_rule(rule, severity=Severity.WARNING, strict=False,
                        violations=[listed, stated])
    assert warned.verdict is Verdict.WARN and warned.violations == [listed, stated]


def test_a_decided_finding_under_a_failed_rule_is_shown_as_what_it_alone_would_be() -> None:
    """The L1 agent's SI-004: the stated finding fails the rule, the decided 'listed' one
    beside it only warns; every output labels each by what it alone would be ([fail], then
    [warn]), and the JSON report keeps it (a strict run: each one fails)."""
    from conformance.results import _rule_result_from_dict, _rule_result_to_dict
    from conformance.rules import CATALOGUE, Severity
    from conformance.violation import Verdict, Violation

    rule = CATALOGUE["SI-004"]
    listed = Violation.of("SI-004", expected="listed", observed="missing", condition="listed")
    stated = Violation.of("SI-004", expected="published", observed="nothing on heading")
    result = judge_rule(rule, severity=Severity.ERROR, strict=False, violations=[listed, stated])
    assert result.verdict is Verdict.FAIL and result.violations == [stated, listed]
    assert [result.shown_as(i) for i in range(2)] == [Verdict.FAIL, Verdict.WARN]
    again = _rule_result_from_dict(_rule_result_to_dict(result))
    assert [again.shown_as(i) for i in range(2)] == [Verdict.FAIL, Verdict.WARN]
    assert again.failing == 1
    strict = judge_rule(rule, severity=Severity.ERROR, strict=True, violations=[listed, stated])
    assert [strict.shown_as(i) for i in range(2)] == [Verdict.FAIL, Verdict.FAIL]
    assert "failing" not in _rule_result_to_dict(strict)

"""The one verdict model (conformance.conclusion): a level is certified only by a complete run
that judged every rule of the level on evidence; every other run says why not."""

from __future__ import annotations

import pytest

from conformance.conclusion import (
    EXIT_CERTIFIED,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_NOT_CERTIFIED,
    EXIT_UNTESTED,
    TRIAGE,
    conclude,
    triage_rank,
)
from conformance.facts import RunFacts
from conformance.results import RunReport, UnitReport
from conformance.rules import CATALOGUE
from conformance.violation import RuleResult, Verdict, Violation

UNIT = "waraps/unit/air/simulation/dji0"
LEVELS = ["sensor", "direct execution"]


def report(kind: str = "certification", **verdicts: Verdict) -> RunReport:
    """Every catalogued rule passed, but those given (``HB_012=Verdict.FAIL``)."""
    rules = {}
    for rule in CATALOGUE:
        verdict = verdicts.get(rule.replace("-", "_"), Verdict.PASS)
        evidence = [Violation(rule, "x", "y", time=1_700_000_010.0)] \
            if verdict in (Verdict.FAIL, Verdict.WARN) else []
        rules[rule] = RuleResult(rule, verdict, "", evidence)
    unit = UnitReport(UNIT, "air", "simulation", "dji0", levels=list(LEVELS), rules=rules,
                      first_seen=1_700_000_000.0, last_seen=1_700_000_600.0,
                      message_count=100)
    return RunReport(kind, 1_700_000_000.0, 1_700_000_600.0, units={UNIT: unit})


def levels(run: RunReport) -> dict[str, str]:
    return {lv.level: lv.why for lv in conclude(run).units[UNIT].levels if not lv.certified}


def test_a_complete_run_with_every_rule_judged_certifies_its_levels() -> None:
    found = conclude(report())
    assert found.verdict == "pass" and found.exit_code == EXIT_CERTIFIED and not found.partial
    assert found.certified_levels(UNIT) == LEVELS
    assert found.units[UNIT].summary == "certified: sensor, direct execution"


def test_a_rule_of_a_level_that_could_not_be_tested_denies_that_level_only() -> None:
    run = report(EXEC_PING_001=Verdict.COULD_NOT_TEST)
    assert levels(run) == {"direct execution": "1 could not be tested"}
    assert conclude(run).certified_levels(UNIT) == ["sensor"]


@pytest.mark.parametrize("untested", ["REBOOT_001", "EXEC_PING_001"])
def test_a_complete_run_that_certified_less_than_the_unit_claims_does_not_exit_0(
        untested: str) -> None:
    # No rule failed, yet a claimed level is not certified (REBOOT-001 without --reboot-cmd
    # denies every level; EXEC-PING-001 one): a gate reading 0 as certified must not admit it.
    found = conclude(report(**{untested: Verdict.COULD_NOT_TEST}))
    assert found.verdict == "could-not-test" and not found.partial
    assert found.exit_code == EXIT_UNTESTED != EXIT_CERTIFIED


def test_a_rule_of_a_level_the_unit_does_not_claim_does_not_deny_the_exit_0() -> None:
    run = report(TST_004=Verdict.COULD_NOT_TEST)  # tst execution: not claimed
    assert conclude(run).exit_code == EXIT_CERTIFIED
    run.units[UNIT].levels = []
    assert conclude(run).exit_code == EXIT_UNTESTED  # it claims nothing: nothing certified


def test_a_failed_rule_of_every_level_and_a_death_deny_every_level() -> None:
    run = report(HB_012=Verdict.FAIL)
    found = conclude(run)
    assert found.verdict == "fail" and found.exit_code == EXIT_FAILED
    assert found.certified_levels(UNIT) == []
    for why in levels(run).values():
        assert why.startswith("1 failed; the unit died at 2023-11-14T22:13:30")


def test_a_skipped_rule_is_not_applicable_and_does_not_deny() -> None:
    assert conclude(report(SENS_004=Verdict.SKIP)).certified_levels(UNIT) == LEVELS


def test_an_exploration_cut_for_time_is_said_beside_the_verdict() -> None:
    """A slow unit's exploration that found no time left is never a silent skip: the unit's
    verdict says so (its levels stand on the rules judged)."""
    run = report()
    why = "the scripted scenarios took 87 s; a default run aims for 80 s at this unit's pace"
    run.facts = RunFacts(unit=UNIT, unexplored=why)
    found = conclude(run)
    assert found.units[UNIT].summary == (f"certified: sensor, direct execution; exploration "
                                         f"not run: {why}")
    assert found.certified_levels(UNIT) == LEVELS


@pytest.mark.parametrize(("facts", "verdict", "code", "why"), [
    ({"error": "cannot reach the broker"}, "not certified", EXIT_NOT_CERTIFIED,
     "cannot reach the broker"),
    ({"broker_lost": 1700000006.0}, "not certified", EXIT_NOT_CERTIFIED,
     "the broker was lost at 2023-11-14T22:13:26.000+00:00 and did not come back"),
    ({"interrupted": True, "cut_short": "--max-duration 60 s reached"}, "interrupted",
     EXIT_INTERRUPTED, "--max-duration 60 s reached"),
    ({"selection": "-k HB-003"}, "partial", EXIT_CERTIFIED,
     "only the selected rules ran: -k HB-003")])
def test_a_run_that_is_partial_never_passes_nor_certifies(facts: dict[str, object],
                                                         verdict: str, code: int,
                                                         why: str) -> None:
    # The rules that never ran are recorded could-not-test and listed (conformance/judge.py).
    run = report(EXEC_PING_001=Verdict.COULD_NOT_TEST, HB_003=Verdict.COULD_NOT_TEST)
    run.facts = RunFacts(unit=UNIT, **facts)  # type: ignore[arg-type]
    run.not_run = ["EXEC-PING-001", "HB-003"]
    found = conclude(run)
    assert (found.verdict, found.exit_code, found.partial) == (verdict, code, True)
    assert found.why == (why,)
    assert found.certified_levels(UNIT) == []
    assert levels(run) == {"sensor": why, "direct execution": f"1 not run; {why}"}
    assert found.counts["not run"] == 2 and found.counts["could-not-test"] == 0


def test_lint_says_what_it_observed_never_certified() -> None:
    found = conclude(report("lint"))
    assert found.verdict == "clean" and found.exit_code == 0
    assert found.units[UNIT].summary == "clean for 10 min, never commanded"
    assert found.certified_levels(UNIT) == []
    failed = conclude(report("lint", HB_003=Verdict.FAIL, HB_010=Verdict.WARN))
    assert failed.verdict == "fail" and failed.exit_code == 1
    assert failed.units[UNIT].summary == ("1 rule(s) failed, 1 rule(s) warned in 10 min "
                                          "observed, never commanded")


def test_triage_ranks_death_deafness_commands_messages_then_warnings() -> None:
    ranked = sorted(["HB-003", "EXEC-PING-001", "EXEC-ROBUST-001", "HB-012"],
                    key=lambda r: triage_rank(r, Verdict.FAIL))
    assert ranked == ["HB-012", "EXEC-ROBUST-001", "EXEC-PING-001", "HB-003"]
    assert TRIAGE[triage_rank("HB-012", Verdict.WARN)] == "warnings"


def _not_examined(run: RunReport, count: int = 3) -> RunReport:
    """``run`` whose unit sent ``count`` messages past MSG-004's bounds (decided: a warn)."""
    unit = run.units[UNIT]
    unit.rules["MSG-004"] = RuleResult("MSG-004", Verdict.WARN, "",
                                       [Violation("MSG-004", "x", "y", time=1_700_000_010.0)])
    unit.violation_counts["MSG-004"] = count
    return run


def test_a_certification_whose_evidence_could_not_be_examined_is_not_certified() -> None:
    found = conclude(_not_examined(report()))
    assert found.verdict == "not certified" and found.exit_code == EXIT_NOT_CERTIFIED
    assert found.certified_levels(UNIT) == []
    assert "3 message(s) could not be examined whole (MSG-004)" in found.units[UNIT].summary
    assert any("could not be examined whole" in why for why in found.why)
    # A failure stays the verdict it is.
    assert conclude(_not_examined(report(HB_003=Verdict.FAIL))).exit_code == EXIT_FAILED


def test_lint_of_evidence_that_could_not_be_examined_is_partial_never_clean() -> None:
    found = conclude(_not_examined(report("lint")))
    assert found.verdict == "partial" and found.exit_code == 4 and found.partial
    assert found.units[UNIT].verdict == "could-not-test"
    found = conclude(report("lint", MSG_005=Verdict.WARN))
    assert found.verdict == "warn" and found.exit_code == 0
    run = report("lint")
    run.facts = RunFacts(kind="lint", not_examined="2 line(s) of the recording could not be read")
    found = conclude(run)
    assert found.verdict == "partial" and found.exit_code == 4

"""The one judge: the evidence a run gathered and its typed facts in, each rule's verdict and
the run's conclusion out (docs/ARCHITECTURE.md 'Verdicts').

- ``judge_rule``: one rule for one row, from its evidence (violations, times examined, what a
  scenario recorded, evidence excused by a death or an outage) and its basis: a *decided*
  rule (the spec is silent; ``rules.toml``) warns as an interop risk unless the run is strict.
  The Monitor calls it for every rule of every row when it makes a report (``checks/rows.py``).
- ``judge``: the run's facts (``conformance.facts.RunFacts``) applied to that report: in a
  certification the commander's rules are the suite's own, an outage is the broker's, rules
  a partial run did not run are *not run*; in lint a capture without times judges no timed
  rule. Then the conclusion is made (``conformance.conclusion.conclude``), stored in the
  report, and the report's verdicts are frozen.

No other module decides or changes a verdict: ``tests/core/test_judge.py`` greps for it.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from types import MappingProxyType

from conformance.conclusion import conclude
from conformance.facts import RunFacts, RunKind, iso
from conformance.recording import UNTIMED_REASON, UNTIMED_RULES
from conformance.results import (
    COMMANDER_REASON,
    NOT_APPLICABLE,
    NOT_SEEN,
    UNPROVOKED,
    RateStat,
    RunReport,
    UnitReport,
)
from conformance.rules import CATALOGUE, Mode, Rule, Severity, Side
from conformance.topics import UnitAddress
from conformance.violation import Observed, RuleResult, Verdict, Violation

INTEROP_RISK = "interop risk: the spec does not say; this suite decided: "
"""What a decided rule's warning says (docs/ARCHITECTURE.md 'What a rule stands on')."""


def judge_rule(rule: Rule, *, severity: Severity, strict: bool, violations: list[Violation],
               count: int = -1, examined: int = 0, explicit: Observed | None = None,
               explicit_reason: str = "", default_reason: str = "",
               excused: str = "", firm: int = -1, keep: int | None = None) -> RuleResult:
    """The verdict of one rule for one row:

    - any violation: fail when the rule's severity (under the profile) is ``error`` and a
      violation found a condition that stands on the spec's words (stated or implied: the
      condition's basis, ``rules.Condition``), or any condition in a strict run; else warn
      (each decided condition found says so: an interop risk);
    - examined at least once without a violation: pass;
    - evidence that was all excused (``excused``: the unit had died, the broker was out):
      could-not-test, saying why;
    - what a scenario saw (``explicit``): not applicable, skip; untestable, could-not-test;
      with its reason; else skip (``default_reason``).

    ``count`` is the number of violations seen (``violations`` holds the first few as
    evidence; -1 means ``len(violations)``), ``firm`` how many of them found a condition
    that is not decided (-1: counted in ``violations``); a skip never becomes a pass. The
    result holds at most ``keep`` of them (None: all), those that fail the rule first
    (``failing_first``).
    """
    count = len(violations) if count < 0 else count
    if firm < 0:
        firm = sum(not rule.decided(v.condition) for v in violations)
    lenient = not strict and severity is Severity.ERROR
    if count:
        fails = severity is Severity.ERROR and (strict or firm > 0)
        verdict = Verdict.FAIL if fails else Verdict.WARN
        risk = _risks(rule, violations) if lenient and not firm else ""
        noun = "violation" if count == 1 else "violations"
        shown = (failing_first(rule, violations, strict=strict) if fails
                 else list(violations))[:keep]
        failing = -1 if strict or not fails else sum(
            not rule.decided(v.condition) for v in shown)
        failing = -1 if failing == len(shown) else failing  # -1: every one
        return RuleResult(rule.id, verdict, "; ".join(x for x in (f"{count} {noun}", risk) if x),
                          shown, failing=failing)
    if examined:
        noun = "time" if examined == 1 else "times"
        return RuleResult(rule.id, Verdict.PASS, f"examined {examined} {noun}", [])
    if excused and explicit is None:
        return RuleResult(rule.id, Verdict.COULD_NOT_TEST, excused, [])
    if explicit is not None:
        verdict = Verdict.COULD_NOT_TEST if explicit is Observed.UNTESTABLE else Verdict.SKIP
        reason = explicit_reason or default_reason
        if explicit is Observed.NOT_APPLICABLE and not reason.startswith(NOT_APPLICABLE):
            reason = NOT_APPLICABLE + reason  # what keeps a claimed level certified
        return RuleResult(rule.id, verdict, reason, [])
    return RuleResult(rule.id, Verdict.SKIP, default_reason or "not examined", [])


def failing_first(rule: Rule, violations: list[Violation], *, strict: bool) -> list[Violation]:
    """A failed rule's evidence, the violations that make it fail first (a condition stated
    or implied; in a strict run every one), then the decided ones, each part in its order:
    what every output shows first (the terminal, lint's text, the HTML and JSON reports)
    is then what the verdict stands on, never a decided finding that only warns
    (docs/ARCHITECTURE.md 'What a rule stands on')."""
    if strict:
        return list(violations)
    return sorted(violations, key=lambda v: rule.decided(v.condition))  # stable


def judge_rates(stats: Iterable[RateStat], rules: Mapping[str, RuleResult]) -> None:
    """Each rate statistic's verdict from its numbers: skip while it could not be judged,
    pass without a finding, else as its rule was judged (a decided condition warns)."""
    for stat in stats:
        if not stat.judged:
            stat.verdict = Verdict.SKIP
        elif not stat.findings:
            stat.verdict = Verdict.PASS
        else:
            judged = rules.get(stat.rule)
            stat.verdict = judged.verdict if judged is not None else Verdict.FAIL


def _risks(rule: Rule, violations: list[Violation]) -> str:
    """Why decided findings only warn: each decided condition found, with its decision."""
    found = dict.fromkeys(v.condition for v in violations) or {"": None}
    said = []
    for c in found:
        try:
            condition = rule.condition(c)
        except KeyError:
            condition = rule.own
        said.append(f"{INTEROP_RISK}{condition.decision}" if condition.decision
                    else INTEROP_RISK.rstrip(": "))
    return "; ".join(dict.fromkeys(said))


def violation_verdict(rule: Rule, severity: Severity, *, strict: bool,
                      condition: str = "") -> Verdict:
    """What a violation of ``rule`` (finding ``condition``) earns on its own (``validate`` of
    one message, a finding shown alone): fail for an error whose condition is stated or
    implied (or any error in a strict run), else warn."""
    if severity is Severity.ERROR and (strict or not rule.decided(condition)):
        return Verdict.FAIL
    return Verdict.WARN


def interop_risk(rule: Rule) -> str:
    """Why a decided rule only warns: the spec does not say, this suite decided."""
    return f"{INTEROP_RISK}{rule.decision}" if rule.decision else INTEROP_RISK.rstrip(": ")


def unexamined(rule: str) -> RuleResult:
    """A rule of which nothing was recorded at all (not even a reason): skip."""
    return RuleResult(rule, Verdict.SKIP, "not examined")


def judge(report: RunReport, facts: RunFacts) -> RunReport:
    """``report`` (each rule judged from its evidence by ``judge_rule``) under the run's
    ``facts``, with its conclusion; its verdicts are frozen afterwards."""
    if facts.kind == RunKind.CERTIFICATION and facts.unit:
        unit = _row(report, facts.unit)
        _commander_rules_aside(unit)
        if facts.broker_lost is not None:
            _excuse_outage(unit, facts.broker_lost)
        not_run: list[str] = []
        if facts.selection:
            chosen = set(facts.selected)
            not_run += _not_run(unit, [r for r in CATALOGUE if r not in chosen], (),
                                f"not run: not selected ({facts.selection})",
                                keep_failures=False)
        if facts.error or facts.interrupted or facts.broker_lost is not None:
            not_run += _not_run(unit, facts.selected or list(CATALOGUE), facts.ran,
                                facts.not_run_reason())
        report.not_run = list(dict.fromkeys(not_run))
        _unprovoked(unit)
    if facts.untimed:
        _untimed(report)
    for row in report.units.values():
        judge_rates(row.rates, row.rules)
    report.facts = facts
    report.conclusion = conclude(report)
    for row in report.units.values():
        row.rules = MappingProxyType(dict(row.rules))  # type: ignore[assignment]
    return report


def _row(report: RunReport, name: str) -> UnitReport:
    """The unit under test's row (an empty one when it was never heard)."""
    found = report.units.get(name)
    if found is None:
        address = UnitAddress.parse(name)
        found = report.units[name] = UnitReport(name, address.agent_type, address.role,
                                                address.name)
    return found


def _commander_rules_aside(unit: UnitReport) -> None:
    """In a certification the suite itself is the commander: what commanders send says
    nothing about the unit (``lint`` judges commanders). A failure stays one: it would be the
    suite's own bug."""
    for rule, result in list(unit.rules.items()):
        if CATALOGUE[rule].side is Side.COMMANDER and result.verdict is not Verdict.FAIL:
            unit.rules[rule] = RuleResult(rule, Verdict.SKIP, COMMANDER_REASON)


def _unprovoked(unit: UnitReport) -> None:
    """A claimed level is certified only on evidence (docs/ARCHITECTURE.md 'Verdicts'): a rule of it
    that needs a command (a conversation or active rule of the unit's side) and was skipped because
    nothing it applies to was seen was not provoked by the suite: could-not-test, saying so. A level
    the unit does not claim, and a skip for a reason its own declarations or messages give
    (``NOT_APPLICABLE``: no task lists $pause, no root-flag sent), stay skips."""
    from conformance.topics import level_name

    claimed = {level_name(level) for level in unit.levels}
    for rule, result in list(unit.rules.items()):
        found = CATALOGUE.get(rule)
        if (found is None or result.verdict is not Verdict.SKIP or found.mode is Mode.PASSIVE
                or found.side is not Side.UNIT or result.reason.startswith(NOT_APPLICABLE)
                or (found.spec_level is not None and found.spec_level not in claimed)):
            continue
        # The suite's doing when nothing came; a check's own reason (the unit's message has
        # no tasks-executing list to read) says why as it is.
        why = result.reason or "not examined"
        unit.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, UNPROVOKED + why if why in (
            NOT_SEEN, "not examined", "not run in this session") else why)


def _excuse_outage(unit: UnitReport, lost: float) -> None:
    """The broker was lost for good at ``lost``: an outage is never the unit's fault. What was
    found missing from then on (no answer, no heartbeat) could not be tested."""
    why = f"the broker was lost at {iso(lost)}: nothing could be observed after that"
    for rule, result in list(unit.rules.items()):
        times = [v.time for v in result.violations if v.time is not None]
        if result.verdict is Verdict.FAIL and times and min(times) >= lost:
            unit.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, why)


def _not_run(unit: UnitReport, selected: Iterable[str], ran: Collection[str], why: str, *,
             keep_failures: bool = True) -> list[str]:
    """Every selected rule whose test did not run is listed as not run (could-not-test,
    ``why``; never a pass); a failure already seen stays one unless ``keep_failures`` is off
    (rules left out of a selection judge nothing). Returns the rules marked."""
    marked = []
    for rule in selected:
        if rule in ran:
            continue
        result = unit.rules.get(rule)
        if keep_failures and result is not None and result.verdict is Verdict.FAIL:
            continue
        unit.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, why)
        marked.append(rule)
    return marked


def _untimed(report: RunReport) -> None:
    """A capture without arrival times (mosquitto_sub -v) neither passes nor fails the rules
    that need them: they are could-not-test on every row, and no rate is shown."""
    for row in report.units.values():
        for rule in UNTIMED_RULES:
            if rule in row.rules:
                row.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, UNTIMED_REASON)
                row.violation_counts.pop(rule, None)
                row.violation_times.pop(rule, None)
                row.examined.pop(rule, None)
        row.rates = []

"""What a certification concludes from the Monitor's report: the unit's rules only (the suite
is the commander), the rules that never ran, the run's verdict and its counts
(ARCHITECTURE 'A certification's verdict and exit status')."""

from __future__ import annotations

from collections.abc import Collection, Iterable

from conformance.results import COMMANDER_REASON, RunReport, UnitReport
from conformance.rules import CATALOGUE, Side
from conformance.topics import UnitAddress
from conformance.violation import RuleResult, Verdict

NOT_CERTIFIED = "not certified"
INTERRUPTED = "interrupted"
NOT_RUN = "not run"

# Rules about what a commander sends (the catalogue's side). In a certification the suite
# itself is the commander, so they say nothing about the unit: `waraps-conformance lint` judges
# commanders.
COMMANDER_RULES = frozenset(r.id for r in CATALOGUE.values() if r.side is Side.COMMANDER)


def set_commander_rules_aside(report: RunReport, unit: UnitAddress) -> None:
    """The suite's own commands are not the unit's to answer for: the report says what the
    pytest outcome says (a failure stays one: it would be the suite's own bug)."""
    found = report.units.get(str(unit))
    if found is None:
        return
    for rule in COMMANDER_RULES & found.rules.keys():
        if found.rules[rule].verdict is not Verdict.FAIL:
            found.rules[rule] = RuleResult(rule, Verdict.SKIP, COMMANDER_REASON)


def mark_not_run(report: RunReport, unit: UnitAddress, selected: Iterable[str],
                 ran: Collection[str], why: str) -> None:
    """A run that did not complete: every selected rule whose test did not run is listed
    as not run (could-not-test, ``why``; never a pass); a failure already seen stays one."""
    name = str(unit)
    found = report.units.get(name)
    if found is None:
        found = report.units[name] = UnitReport(name, unit.agent_type, unit.role, unit.name)
    not_run = []
    for rule in selected:
        if rule in ran:
            continue
        result = found.rules.get(rule)
        if result is not None and result.verdict is Verdict.FAIL:
            continue
        found.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, why)
        not_run.append(rule)
    report.meta["not_run"] = " ".join(not_run)


def verdict(report: RunReport, *, error: str | None, interrupted: bool) -> str:
    """The run's verdict: 'not certified' when the broker or the unit could not be
    reached, 'interrupted' when it did not complete, else the worst rule verdict."""
    if error:
        return NOT_CERTIFIED
    if interrupted:
        return INTERRUPTED
    return report.worst().value


def counts(report: RunReport) -> dict[str, int]:
    """Verdict counts, with the rules that never ran counted as 'not run'."""
    found = dict(report.verdict_counts())
    not_run = len(report.meta.get("not_run", "").split())
    if not_run:
        found[Verdict.COULD_NOT_TEST.value] -= not_run
        found[NOT_RUN] = not_run
    return found

"""What a certification makes of the Monitor's report before the verdict model reads it: the
unit's rules only (the suite is the commander), the rules that never ran, an outage not charged
to the unit. The verdict itself is ``conformance.conclusion`` (ARCHITECTURE 'A
certification's verdict and exit status')."""

from __future__ import annotations

from collections.abc import Collection, Iterable

from conformance.conclusion import INTERRUPTED, NOT_CERTIFIED, NOT_RUN  # noqa: F401
from conformance.conclusion import counts as conclusion_counts
from conformance.results import COMMANDER_REASON, RunReport, UnitReport
from conformance.rules import CATALOGUE, Mode, Side
from conformance.suite.events import clock
from conformance.topics import UnitAddress
from conformance.violation import RuleResult, Verdict

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
                 ran: Collection[str], why: str, *, keep_failures: bool = True) -> None:
    """A run that did not complete: every selected rule whose test did not run is listed
    as not run (could-not-test, ``why``; never a pass); a failure already seen stays one
    unless ``keep_failures`` is off (rules left out of a selection judge nothing)."""
    name = str(unit)
    found = report.units.get(name)
    if found is None:
        found = report.units[name] = UnitReport(name, unit.agent_type, unit.role, unit.name)
    not_run = []
    for rule in selected:
        if rule in ran:
            continue
        result = found.rules.get(rule)
        if keep_failures and result is not None and result.verdict is Verdict.FAIL:
            continue
        found.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, why)
        not_run.append(rule)
    listed = report.meta.get("not_run", "").split()
    report.meta["not_run"] = " ".join(dict.fromkeys(listed + not_run))


def excuse_outage(report: RunReport, unit: UnitAddress, lost: float) -> None:
    """The broker was lost for good at ``lost``: an outage is never the unit's fault. What
    was found missing from then on (no answer, no heartbeat) could not be tested."""
    found = report.units.get(str(unit))
    if found is None:
        return
    why = f"the broker was lost at {clock(lost)}: nothing could be observed after that"
    for rule, result in list(found.rules.items()):
        if result.verdict is not Verdict.FAIL:
            continue
        times = [v.time for v in result.violations if v.time is not None]
        if times and min(times) >= lost:  # an explicit failure was recorded while up
            found.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, why)


def excuse_gaps(report: RunReport, unit: UnitAddress, slack: float) -> None:
    """The broker lost or held traffic for a while and came back (an outage of the
    connection, or a stall found in the traffic: ``checks/stall.py``): a scenario waiting
    then saw nothing of what the unit sent (issue 25 §3). A rule that needed a conversation
    and failed only on evidence from such a gap, or from the ``slack`` seconds (the longest
    wait) before it, could not be tested; what the messages themselves show stays judged."""
    found = report.units.get(str(unit))
    gaps = [(start - slack, end) for start, end in report.gaps if end > start]
    if found is None or not gaps:
        return
    for rule, result in list(found.rules.items()):
        if result.verdict is not Verdict.FAIL or CATALOGUE[rule].mode is Mode.PASSIVE:
            continue
        times = [v.time for v in result.violations if v.time is not None]
        spans = [(s, e) for s, e in gaps if times and all(s <= t <= e for t in times)]
        if spans:
            start, end = spans[0]
            found.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, (
                f"the broker lost or held the traffic from {clock(start + slack)} for "
                f"{end - start - slack:.1f} s: its evidence falls in that window, where what "
                f"the unit sent is unknown (a broker's fault is never the unit's)"))


def counts(report: RunReport) -> dict[str, int]:
    """Verdict counts, with the rules that never ran counted as 'not run'
    (``conclusion.counts``)."""
    return conclusion_counts(report)

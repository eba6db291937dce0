"""A row of the report: what was found for one unit, or for one commander (docs/ARCHITECTURE.md
'Whose fault it is'), and the ``UnitReport`` made of it (verdicts per rule, facts, rates).

The Monitor keeps a ``Row`` per unit and per commander while it feeds; ``row_report`` turns one
into the report's row at report time (examined sets expanded into per-rule counts there).
"""

from __future__ import annotations

import dataclasses

from conformance import __version__
from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import OVER_A_GAP
from conformance.checks.conversation import dropped
from conformance.checks.liveness import deaths
from conformance.checks.rates import rate_stats
from conformance.facts import RunKind
from conformance.judge import judge_rates, judge_rule
from conformance.profile import Profile
from conformance.report_meta import UnitFacts
from conformance.results import Party, UnitReport, skip_reason
from conformance.rules import CATALOGUE, Mode, Rule, Side
from conformance.topics import UnitAddress
from conformance.validator import Examined
from conformance.violation import Observed, Violation

MAX_EVIDENCE = 20
"""Violations kept as evidence per rule and unit; the rest are only counted (bounded memory)."""
UNATTRIBUTED = "(unattributed)"
"""The report entry for topics that name no unit (``waraps/foo``, ``waraps/unit/air``)."""


class RuleRecord:
    """What was recorded for one rule of one unit: a count and the first few violations."""

    __slots__ = ("count", "firm", "evidence", "explicit", "reason", "first", "last", "excused")

    def __init__(self) -> None:
        self.count = 0
        self.firm = 0
        """How many of the violations found a condition the spec's words state or imply (the
        rest are decided: they warn unless the run adopts them)."""
        self.evidence: list[Violation] = []
        self.explicit: Observed | None = None
        self.reason = ""
        self.excused = ""
        """Why what a scenario found missing is not evidence (the unit had died, the link
        was down when it should have answered): the judge makes that could-not-test."""
        self.first: float | None = None
        self.last: float | None = None
        """Times of the first and the latest violation (of all, not only those kept)."""

    def add(self, v: Violation) -> None:
        if v.supersedes:
            self._supersede(v.supersedes, CATALOGUE.get(v.rule))
        self.count += 1
        rule = CATALOGUE.get(v.rule)
        firm = not _decided(rule, v.condition)
        self.firm += firm
        evidence = self.evidence
        if len(evidence) < MAX_EVIDENCE:
            evidence.append(v)
        elif firm:
            # Full of decided findings that only warn: the latest of them makes room for one
            # the verdict stands on (what every output shows first: ``judge.failing_first``).
            decided = [i for i, e in enumerate(evidence) if _decided(rule, e.condition)]
            if decided:
                del evidence[decided[-1]]
                evidence.append(v)
        t = v.time
        if t is not None:
            if self.first is None or t < self.first:
                self.first = t
            if self.last is None or t > self.last:
                self.last = t


    def _supersede(self, com_uuid: str, rule: Rule | None) -> None:
        """Drop the findings that the command ``com_uuid`` was not answered: it was answered
        late after all, and that finding takes their place."""
        gone = [v for v in self.evidence if v.command == com_uuid and v.condition == ""]
        if not gone:
            return
        self.evidence = [v for v in self.evidence if v not in gone]
        self.count -= len(gone)
        self.firm -= sum(not _decided(rule, v.condition) for v in gone)


def _firm(rule: Rule, evidence: list[Violation], count: int, recorded: int) -> int:
    """How many of ``count`` violations found a condition the spec's words state or imply:
    counted in ``evidence`` when it holds them all, else as recorded (the first few kept)."""
    held = sum(not _decided(rule, v.condition) for v in evidence)
    return held if len(evidence) >= count else max(held, recorded)


def _decided(rule: Rule | None, condition: str) -> bool:
    return rule is not None and rule.decided(condition)


class Findings:
    """What the finish checks found for one unit: kept apart, so a provisional report (before
    ``finish``) and a repeated ``finish`` never count twice."""

    __slots__ = ("examined", "notes", "violations")

    def __init__(self) -> None:
        self.examined: dict[str, int] = {}
        self.notes: dict[str, str] = {}
        self.violations: list[Violation] = []

    def examine(self, rule: str, times: int = 1) -> None:
        self.examined[rule] = self.examined.get(rule, 0) + times

    def note(self, rule: str, why: str) -> None:
        self.notes[rule] = why


class Row:
    __slots__ = ("state", "records", "groups", "final", "unit", "party")

    def __init__(self, state: UnitState, party: Party = Party.UNIT, label: str = "") -> None:
        self.state = state
        self.party = party
        """A unit's, or a row of what commanders sent (docs/ARCHITECTURE.md 'Whose fault it is')."""
        self.unit = label or ("" if state.address.prefix == UNATTRIBUTED else str(state.address))
        self.records: dict[str, RuleRecord] = {}
        self.groups: dict[Examined, int] = {}
        """Rules examined by the validator (shared sets) -> messages (expanded at report
        time)."""
        self.final: Findings | None = None

    def add(self, v: Violation) -> None:
        rec = self.records.get(v.rule)
        if rec is None:
            rec = self.records[v.rule] = RuleRecord()
        rec.add(v)

    def add_all(self, found: list[Violation]) -> list[Violation]:
        """Record ``found`` on this row, each carrying the row's unit; returns them so."""
        unit = self.unit
        found = [f if f.unit or not unit else dataclasses.replace(f, unit=unit) for f in found]
        for f in found:
            self.add(f)
        return found


def row_report(ctx: CheckContext, profile: Profile, kind: RunKind, address: UnitAddress | None,
           entry: Row, final: Findings, now: float) -> UnitReport:
    """The report's row of ``entry`` (the unit at ``address``, or a commander or the
    unattributed topics when None), with the end-of-run ``final`` findings, at ``now``."""
    state = entry.state
    examined = _examined(entry, final)
    notes = {**state.notes, **final.notes}
    extra: dict[str, list[Violation]] = {}
    for v in final.violations:
        extra.setdefault(v.rule, []).append(v)
    unit = str(address) if address is not None else (entry.unit or UNATTRIBUTED)
    rules = {}
    counts = {}
    times: dict[str, tuple[float, float]] = {}
    died = deaths(ctx, state, now) if address is not None else []
    held = _broker_gaps(ctx, profile)
    for rid in _rule_ids(entry, address, examined):
        rule = CATALOGUE.get(rid)
        if rule is None:
            continue
        rec = entry.records.get(rid)
        evidence = (rec.evidence if rec else []) + extra.get(rid, [])
        count = (rec.count if rec else 0) + len(extra.get(rid, ()))
        explicit, reason = (rec.explicit, rec.reason) if rec else (None, "")
        excused = rec.excused if rec else ""
        seen = examined.get(rid, 0)
        if rule.mode is not Mode.PASSIVE:
            evidence, count, excused, seen = _excuse_scenario(evidence, count, excused, seen,
                                                              died, held)
        firm = _firm(rule, evidence, count, rec.firm if rec else 0)
        if count:
            counts[rid] = count
            when = [t for t in (rec.first if rec else None, rec.last if rec else None,
                                *(v.time for v in extra.get(rid, ()))) if t is not None]
            if when:
                times[rid] = (min(when), max(when))
        rules[rid] = judge_rule(
            rule, severity=profile.severity_of(rid), strict=profile.adopts(rid),
            violations=evidence, keep=MAX_EVIDENCE, count=count, firm=firm, examined=seen,
            explicit=explicit, explicit_reason=reason, excused=excused,
            default_reason=skip_reason(rule, kind=kind, unit=unit,
                                       levels=state.levels, note=notes.get(rid, ""),
                                       party=entry.party))
    rates = rate_stats(ctx, state) if address is not None else []
    judge_rates(rates, rules)
    return UnitReport(
        party=entry.party,
        unit=unit, agent_type=address.agent_type if address else "",
        role=address.role if address else "", name=address.name if address else "",
        agent_uuids=list(state.agent_uuids), levels=list(state.levels or ()),
        message_count=state.message_count, first_seen=state.first_seen,
        last_seen=state.last_seen, rules=rules,
        rates=rates,
        examined={k: examined[k] for k in sorted(examined)}, violation_counts=counts,
        violation_times=times,
        facts=_facts(state))


def _examined(entry: Row, final: Findings) -> dict[str, int]:
    """Rule -> how often it was examined on the row: by its checks, by the validator's
    shared sets (expanded here), and at the end."""
    examined = dict(entry.state.examined)
    for group, n in entry.groups.items():
        for rule in group:
            examined[rule] = examined.get(rule, 0) + n
    for rule, n in final.examined.items():
        examined[rule] = examined.get(rule, 0) + n
    return examined


def _rule_ids(entry: Row, address: UnitAddress | None, examined: dict[str, int]) -> list[str]:
    """The rules a row reports: a commander's rules and any other it broke; without a unit
    only the rules examined or broken; a unit every rule of the catalogue."""
    if entry.party == Party.COMMANDER:
        return [r for r, rule in CATALOGUE.items() if rule.side is Side.COMMANDER
                or r in examined or r in entry.records]
    if address is None:
        return sorted(set(examined) | set(entry.records))
    return list(CATALOGUE)


def _excuse_scenario(evidence: list[Violation], count: int, excused: str, seen: int,
                     died: list[tuple[float, float]], held: list[tuple[float, float]]
                     ) -> tuple[list[Violation], int, str, int]:
    """A scenario rule's evidence, count, excuse and examinations, without what a death or a
    broker's gap explains."""
    before = count
    # A dead unit answers nothing: what a scenario found missing while it was dead is its
    # death's evidence (HB-012), not a fault of its own.
    evidence, count, excused = _excuse(evidence, count, excused, died,
                                       "the unit died (HB-012) before it could answer")
    # What a scenario found missing while the broker lost or held the traffic, or was due
    # within a response timeout before: the broker's fault.
    evidence, count, excused = _excuse(evidence, count, excused, held, OVER_A_GAP)
    if not count and before:
        # The examinations that found what was excused are no passes: a rule judged only
        # then could not be tested (never a pass the broker's outage made).
        seen = max(0, seen - before)
    return evidence, count, excused, seen


def _excuse(evidence: list[Violation], count: int, excused: str,
            spans: list[tuple[float, float]], why: str
            ) -> tuple[list[Violation], int, str]:
    """A scenario rule's evidence without what fell in ``spans`` (a death, a gap of the
    broker), its count lessened as much, and the excuse ``why`` when any was left out."""
    if not spans or not evidence:
        return evidence, count, excused
    kept = [v for v in evidence if not _during(v.time, spans)]
    if len(kept) == len(evidence):
        return evidence, count, excused
    return kept, count - (len(evidence) - len(kept)), excused or why


def _facts(state: UnitState) -> UnitFacts:
    """What the report tells people of the unit besides the verdicts."""
    return UnitFacts(
        declared_rates=dict(state.declared_rates),
        sensors_listed=tuple(state.sensors_listed or ()),
        sensors_seen=dict(state.sensors_seen),
        tasks_available=dict(state.tasks_available),
        tasks_executing=dict(state.tasks_executing),
        position=state.position,
        message_counts=dict(state.counts),
        conversations_dropped=dropped(state))


def _broker_gaps(ctx: CheckContext, profile: Profile) -> list[tuple[float, float]]:
    """The gaps of the observer (an outage, a stall; not the instant of a reboot the suite
    requested), each from a response timeout before it: a command sent then (a violation of
    the conversation checks is stamped with its command) was due to be answered in it. Not
    longer: a command whose deadline ran out before the outage began was judged on what the
    broker delivered (the public L2 agent's unanswered ping, 5 s before a broker kill, was
    excused by a 30 s slack and read as a pass)."""
    return [(start - profile.response_timeout, end) for start, end in ctx.gaps if end > start]


def _during(t: float | None, windows: list[tuple[float, float]]) -> bool:
    return t is not None and any(start <= t <= end for start, end in windows)


def suite_version() -> str:
    try:
        from importlib.metadata import version

        return version("waraps-conformance")
    except Exception:  # not installed: the source tree's version
        return __version__


def schemas_hash() -> str:
    try:
        from conformance.schema import schemas_hash
    except Exception:  # the schema module is not there (yet)
        return ""
    try:
        return str(schemas_hash())
    except Exception:
        return ""

"""Results: the report of a run (a row per unit or commander: a verdict for every rule, rate
statistics, facts for people) and its serialisation.

The verdicts in it are made by the one judge (``conformance.judge``) and read by every writer;
a rule passes only when it was actually examined: a skip never becomes a pass.
"""

from __future__ import annotations

import enum
import shlex
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from conformance.facts import RunFacts, RunKind
from conformance.masking import mask_password
from conformance.report_meta import RunMeta, UnitFacts
from conformance.rules import CATALOGUE, Mode, Rule, Side
from conformance.violation import RuleResult, Verdict, Violation


class Party(enum.StrEnum):
    """Whose row a report's row is (docs/ARCHITECTURE.md 'Whose fault it is'). A
    ``StrEnum``: it prints, serialises and compares as the word the reports carry."""

    UNIT = "unit"
    """A unit: what it publishes and how it answers."""
    COMMANDER = "commander"
    """A commander: what it sent, judged by the commander's rules."""


COMMANDER_REASON = ("commander-side rule: in a certification the suite itself is the commander "
                    "(waraps-conformance lint judges commanders)")


NOT_APPLICABLE = "not applicable: "
"""How a skip reason starts when the unit's own declarations or messages make the rule
inapplicable (no task lists the signal, an optional field it never sends): in a certification
that skip does not keep a claimed level from being certified; any other skip of a rule that
needs a command does (``judge``: the suite did not provoke the evidence)."""
UNPROVOKED = "the suite did not provoke the evidence: "
"""How a certification's could-not-test of an unexamined rule of a claimed level begins."""


UNIT_WORD_CHARS = 200
"""A unit address longer than this is not repeated in each rule's reason: the reasons of 800
units with 100 KB names took gigabytes (names stored once)."""


def _unit_word(unit: str) -> str:
    """The unit as a shell word in a reason, or a stand-in for an address too long to repeat."""
    return shlex.quote(unit) if len(unit) <= UNIT_WORD_CHARS else "ADDRESS (this unit's)"


def skip_reason(rule: Rule, *, kind: RunKind, unit: str, levels: tuple[str, ...] | None,
                note: str = "", party: Party = Party.UNIT) -> str:
    """Why a rule that was never examined is skipped (the reason a person reads).

    ``levels`` is what the unit declares in its heartbeat, or None when no heartbeat was seen;
    ``note`` is what the check itself said (``only 3 intervals observed; need 10``); ``party``
    is whose row it is (``unit`` or ``commander``).
    """
    if rule.side is Side.COMMANDER and party == Party.UNIT:
        if kind == RunKind.CERTIFICATION:
            return COMMANDER_REASON
        return "commander-side rule: what commanders send is judged on their own rows"
    if party == Party.COMMANDER:
        return note or "no command of this commander that the rule applies to was seen"
    if rule.id.startswith("ROS-") and not note:
        return "judged from ROS bags that hold the topics it is about (lint --from run.bag)"
    # A level the unit does not claim first: a TST rule of a unit without 'tst execution' is
    # not claimed, whatever a certification would send it.
    level = rule.spec_level if note == "" else None
    if level is not None and levels is not None and level not in levels:
        return f"not claimed: unit declares no '{level}' level"
    if rule.mode is Mode.ACTIVE and kind == RunKind.LINT:
        return f"needs a stimulus: run pytest --unit {_unit_word(unit)}"
    if rule.mode is Mode.CONVERSATION and kind == RunKind.LINT and not note:
        return (f"no command to this unit that the rule applies to was seen (pytest --unit "
                f"{_unit_word(unit)} sends them)")
    if level is not None and levels is None:
        return f"no heartbeat seen: cannot tell whether the unit claims the '{level}' level"
    if note:
        return note
    if rule.mode is Mode.ACTIVE:
        return "not run in this session"
    return NOT_SEEN


NOT_SEEN = "no message this rule applies to was seen"
"""A skip's reason when nothing the rule applies to came, and no check said why."""


def redact_broker(url: str) -> str:
    """A broker URL fit for a report: never with a password (``mqtts://user@host:8883``: the
    lint's rerun line pastes it)."""
    return mask_password(url or "", url=True, hidden=None)


@dataclass
class RateStat:
    """The measured rate of one periodic message of one unit against the rate it declares.

    Intervals are in seconds, rates in Hz. ``series`` is (arrival time, rate in Hz) at most
    600 points, downsampled for plots. Numbers, with ``judged`` (enough intervals to judge)
    and ``findings`` (the violations it showed); ``verdict`` is the judge's
    (``judge.judge_rates``), skip with ``reason`` while it could not be judged.
    """

    unit: str
    kind: str
    topic: str
    declared_hz: float | None
    measured_hz: float | None
    intervals: int
    mean_interval: float | None
    min_interval: float | None
    max_interval: float | None
    verdict: Verdict
    series: list[tuple[float, float]] = field(default_factory=list)
    rule: str = ""
    reason: str = ""
    silences: int = 0
    """Intervals longer than 3 declared periods (HB-010), left out of the mean when others
    are enough to judge."""
    start: float | None = None
    end: float | None = None
    tolerance: float | None = None
    """The profile's rate tolerance (0.2 = 20 % of the declared period)."""
    judged: bool = False
    findings: int = 0

    def to_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["verdict"] = self.verdict.value
        d["series"] = [[round(t, 6), round(r, 6)] for t, r in self.series]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RateStat:
        d = dict(d)
        d["verdict"] = Verdict(d["verdict"])
        d["series"] = [(float(t), float(r)) for t, r in d.get("series", [])]
        return cls(**d)


@dataclass
class UnitReport:
    """Everything a run found about one unit: a verdict for every applicable rule, its rates."""

    unit: str
    agent_type: str
    role: str
    name: str
    party: Party = Party.UNIT
    """A unit's row, or a row of what one commander sent (docs/ARCHITECTURE.md 'Whose fault
    it is')."""
    agent_uuids: list[str] = field(default_factory=list)
    levels: list[str] = field(default_factory=list)
    message_count: int = 0
    first_seen: float | None = None
    last_seen: float | None = None
    rules: dict[str, RuleResult] = field(default_factory=dict)
    rates: list[RateStat] = field(default_factory=list)
    examined: dict[str, int] = field(default_factory=dict)
    """How many times each rule was examined."""
    violation_counts: dict[str, int] = field(default_factory=dict)
    """How many violations of each rule were seen (``rules`` keeps the first few as evidence)."""
    violation_times: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Rule -> (first, latest) time of its violations, Unix seconds."""
    facts: UnitFacts = field(default_factory=UnitFacts)
    """What the unit declared and did, for people: sensors listed and seen, tasks, position."""

    def verdict_counts(self) -> dict[str, int]:
        counts = Counter(r.verdict.value for r in self.rules.values())
        return {v.value: counts.get(v.value, 0) for v in Verdict}

    def worst(self) -> Verdict:
        return Verdict.worst([r.verdict for r in self.rules.values()])

    def to_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["rules"] = {rid: _rule_result_to_dict(r) for rid, r in self.rules.items()}
        d["rates"] = [r.to_dict() for r in self.rates]
        d["facts"] = self.facts.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> UnitReport:
        d = dict(d)
        d["rules"] = {rid: _rule_result_from_dict(r) for rid, r in d.get("rules", {}).items()}
        d["rates"] = [RateStat.from_dict(r) for r in d.get("rates", [])]
        d["violation_times"] = {r: (float(a), float(b))
                                for r, (a, b) in d.get("violation_times", {}).items()}
        d["party"] = Party(d.get("party", Party.UNIT))
        d["facts"] = UnitFacts.from_dict(d.get("facts", {}))
        return cls(**d)


def _rule_result_to_dict(r: RuleResult) -> dict[str, Any]:
    out: dict[str, Any] = {"rule": r.rule, "verdict": r.verdict.value, "reason": r.reason,
           "violations": [v.to_dict() for v in r.violations]}
    if r.failing >= 0:  # those after the first ``failing`` only warn (``RuleResult.shown_as``)
        out["failing"] = r.failing
    rule = CATALOGUE.get(r.rule)
    if rule is not None and r.verdict in (Verdict.FAIL, Verdict.WARN):
        # A finding carries what its rule stands on (docs/ARCHITECTURE.md 'What a rule stands
        # on').
        out["basis"] = {"basis": rule.basis.value, "quote": rule.quote,
                        "because": rule.because, "decision": rule.decision}
        found = dict.fromkeys(v.condition for v in r.violations if v.condition)
        if found:  # and each further condition found, on its own basis
            out["conditions"] = {c: _condition_dict(rule, c) for c in found}
    return out


def _condition_dict(rule: Rule, condition: str) -> dict[str, str]:
    try:
        c = rule.condition(condition)
    except KeyError:  # a report of another version of the catalogue
        return {"title": "", "basis": ""}
    return {"title": c.title, "basis": c.basis.value, "quote": c.quote, "because": c.because,
            "decision": c.decision}


def _rule_result_from_dict(d: dict[str, Any]) -> RuleResult:
    return RuleResult(d["rule"], Verdict(d["verdict"]), d.get("reason", ""),
                      [Violation(**v) for v in d.get("violations", [])],
                      int(d.get("failing", -1)))


@dataclass
class RunReport:
    """One run (a certification or a lint): its context and a report per unit.

    Times are Unix seconds. ``broker`` never carries a password. ``gaps`` are the times the
    observer was disconnected; ``unexamined`` counts messages it could not examine.
    """

    kind: RunKind
    started: float
    finished: float | None
    broker: str = ""
    profile: str = "default"
    suite_version: str = ""
    schemas_hash: str = ""
    units: dict[str, UnitReport] = field(default_factory=dict)
    gaps: list[tuple[float, float]] = field(default_factory=list)
    unexamined: int = 0
    meta: RunMeta = field(default_factory=RunMeta)
    """What the run was, for people (source, seed, options): no verdict reads it."""
    facts: RunFacts | None = None
    """The run's facts the judge read (``conformance.judge.judge``); None before judging."""
    not_run: list[str] = field(default_factory=list)
    """The rules the judge listed as not run (a selection, a run that did not complete)."""
    conclusion: Any = None
    """The judge's ``conclusion.Conclusion``: every writer and the exit status read it."""

    def __post_init__(self) -> None:
        self.broker = redact_broker(self.broker)
        self.kind = RunKind(self.kind)  # a caller's plain word ("lint") made the member

    def verdict_counts(self) -> dict[str, int]:
        """Number of (unit, rule) results per verdict, every verdict present."""
        total: Counter[str] = Counter()
        for unit in self.units.values():
            total.update(unit.verdict_counts())
        return {v.value: total.get(v.value, 0) for v in Verdict}

    def worst(self) -> Verdict:
        return Verdict.worst([u.worst() for u in self.units.values()])

    def failures(self) -> list[tuple[str, RuleResult]]:
        """(unit, result) for every failed or warned rule, failures first."""
        out = [(u, r) for u, rep in self.units.items() for r in rep.rules.values()
               if r.verdict in (Verdict.FAIL, Verdict.WARN)]
        return sorted(out, key=lambda ur: (-ur[1].verdict.rank, ur[0], ur[1].rule))

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "waraps-conformance-report/1",
            "kind": self.kind, "started": self.started, "finished": self.finished,
            "broker": self.broker, "profile": self.profile, "suite_version": self.suite_version,
            "schemas_hash": self.schemas_hash,
            "verdict_counts": self.verdict_counts(), "worst": self.worst().value,
            "units": {name: u.to_dict() for name, u in self.units.items()},
            "gaps": [list(g) for g in self.gaps], "unexamined": self.unexamined,
            "meta": self.meta.to_dict(),
            "facts": self.facts.to_dict() if self.facts is not None else None,
            "not_run": list(self.not_run),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RunReport:
        return cls(
            kind=d["kind"], started=d["started"], finished=d.get("finished"),
            broker=d.get("broker", ""), profile=d.get("profile", "default"),
            suite_version=d.get("suite_version", ""), schemas_hash=d.get("schemas_hash", ""),
            units={n: UnitReport.from_dict(u) for n, u in d.get("units", {}).items()},
            gaps=[(float(a), float(b)) for a, b in d.get("gaps", [])],
            unexamined=int(d.get("unexamined", 0)), meta=RunMeta.from_dict(d.get("meta", {})),
            facts=RunFacts.from_dict(d["facts"]) if d.get("facts") else None,
            not_run=[str(r) for r in d.get("not_run", ())],
        )


def rule_title(rule_id: str) -> str:
    rule = CATALOGUE.get(rule_id)
    return rule.title if rule else rule_id


def rule_section(rule_id: str) -> str:
    rule = CATALOGUE.get(rule_id)
    return rule.section if rule else ""

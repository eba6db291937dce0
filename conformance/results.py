"""Results: the report of a run (a row per unit or commander: a verdict for every rule, rate
statistics, facts for people) and its serialisation.

The verdicts in it are made by the one judge (``conformance.judge``) and read by every writer;
a rule passes only when it was actually examined: a skip never becomes a pass.
"""

from __future__ import annotations

import enum
import shlex
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

from conformance.facts import RunFacts, RunKind
from conformance.masking import mask_password
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


class MalformedReport(ValueError):
    """A JSON report's ``meta`` or a unit's ``facts`` is not what a writer writes."""


RERUN_OF = "rerun "
"""How a JSON report's ``meta`` key of ``RunMeta.rerun_of`` begins: ``rerun HB-003``."""


@dataclass(frozen=True)
class RunMeta:
    """What a run was, for people (source, seed, options): no verdict reads it (the judge
    reads ``RunFacts``). Each field is the key of the JSON report's ``meta`` object and its text
    as every report shows it; None: not said (no key). A certification writes the suite's
    fields (``suite/session.py``), lint the lint's (``lint/runner.py``)."""

    # -- a certification's (every one written, '' when there is nothing to say)
    unit: str | None = None
    """The unit under test (its address)."""
    seed: str | None = None
    timing_scale: str | None = None
    profile_source: str | None = None
    """The profile's file (or the bundled profile's name)."""
    dry_run: str | None = None
    """``true`` or ``false``, as the options."""
    allow_motion: str | None = None
    allow_hostile: str | None = None
    safety: str | None = None
    """The safety decision in words (motion, hostile payloads)."""
    reboot: str | None = None
    agent_uuid: str | None = None
    """Of the unit's latest heartbeat."""
    commands_sent: str | None = None
    tst_command_topic: str | None = None
    explore: str | None = None
    """What the exploration did (``off``, ``not run``, its summary)."""
    explore_story: str | None = None
    """The story exploration found, one step a line (the HTML report shows it)."""
    rerun: str | None = None
    """The command that repeats the whole run."""
    rerun_of: Mapping[str, str] = field(default_factory=dict)
    """Rule -> the command that reruns a failed or warned rule alone, as the terminal printed
    it (its scenarios, ``--observe``, a stored exploration story); keys ``rerun <RULE>``."""
    exit_status: str | None = None
    """The exit status of a finished certification."""
    # -- a lint's
    source: str | None = None
    """The recording's name, or ``live <topic filters>``."""
    recording_lines: str | None = None
    """Lines of a recording read (present only for a recording: the rerun line reads it)."""
    recording_formats: str | None = None
    recording_problems: str | None = None
    """How many lines of the recording could not be read, and the first of them."""
    recording_problem_lines: str | None = None
    bag_messages_read: str | None = None
    tls_options: str | None = None
    """Live: the TLS options the rerun line repeats, already shell-quoted."""
    unexamined_reason: str | None = None
    duration_s: str | None = None
    """Seconds of traffic read."""
    units: str | None = None
    """The --unit addresses lint was restricted to."""
    not_judged: str | None = None
    """Traffic of units past the bound on units was not judged (why, in words)."""
    provisional: str | None = None
    """A report served while lint runs (``lint --serve``): not the run's last word."""
    # -- any run's
    report_truncated: str | None = None
    """What a report bounded in size left out (``reporting/bounds.py``)."""

    def to_dict(self) -> dict[str, str]:
        """The JSON report's ``meta`` object: every field said, and a ``rerun <RULE>`` each."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "rerun_of"}
        said: dict[str, str] = {k: v for k, v in out.items() if v is not None}
        said.update((RERUN_OF + rule, line) for rule, line in self.rerun_of.items())
        return said

    @classmethod
    def from_dict(cls, d: object) -> RunMeta:
        """The ``meta`` of a JSON report; a key no field has is a newer writer's, ignored (as
        ``RunFacts.from_dict`` does)."""
        if not isinstance(d, dict):
            raise MalformedReport(f"the report's meta is {_json_type(d)}, not an object")
        known = {f.name for f in fields(cls)} - {"rerun_of"}
        said: dict[str, Any] = {}
        rerun_of: dict[str, str] = {}
        for key, value in d.items():
            if not isinstance(value, str):
                raise MalformedReport(f"the report's meta {key!r} is {_json_type(value)}, "
                                      f"not text")
            if key.startswith(RERUN_OF):
                rerun_of[key.removeprefix(RERUN_OF)] = value
            elif key in known:
                said[key] = value
        return cls(**said, rerun_of=rerun_of)


T = TypeVar("T")


@dataclass(frozen=True)
class UnitFacts:
    """What a unit declared and did, for people (the HTML report's unit heading, the count of
    commands a lint row saw): no verdict reads it. Each field is a key of the JSON report's
    unit ``facts``; made by ``checks/rows.py`` from the unit's state."""

    declared_rates: Mapping[str, float] = field(default_factory=dict)
    """Topic kind (heartbeat, sensor_info, ...) -> the rate it declares, Hz."""
    sensors_listed: tuple[str, ...] = ()
    """What its latest sensor_info lists (sensor-data-provided)."""
    sensors_seen: Mapping[str, int] = field(default_factory=dict)
    """Sensor -> messages of it seen."""
    tasks_available: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    """Task name -> the signals it understands (5.3)."""
    tasks_executing: Mapping[str, str] = field(default_factory=dict)
    """task-uuid -> task-name (5.3)."""
    position: tuple[float, float, float | None] | None = None
    """Latest (latitude, longitude, altitude) from sensor/position."""
    message_counts: Mapping[str, int] = field(default_factory=dict)
    """Topic kind -> messages of it seen (``exec/command``...)."""
    conversations_dropped: int = 0
    """Open expectations dropped for bounded memory."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "declared_rates": dict(self.declared_rates),
            "sensors_listed": list(self.sensors_listed),
            "sensors_seen": dict(self.sensors_seen),
            "tasks_available": {k: list(v) for k, v in self.tasks_available.items()},
            "tasks_executing": dict(self.tasks_executing),
            "position": list(self.position) if self.position is not None else None,
            "message_counts": dict(self.message_counts),
            "conversations_dropped": self.conversations_dropped,
        }

    @classmethod
    def from_dict(cls, d: object) -> UnitFacts:
        """A unit's ``facts`` of a JSON report; a missing key is not said (a report of an
        older writer), a key no field has a newer writer's, ignored."""
        if not isinstance(d, dict):
            raise MalformedReport(f"a unit's facts are {_json_type(d)}, not an object")

        def read(key: str, parse: Callable[[Any], T], default: Any) -> T:
            value = d.get(key, default)
            try:
                return parse(value)
            except (TypeError, ValueError) as e:
                raise MalformedReport(f"a unit's facts {key!r}: {e}") from None

        return cls(
            declared_rates=read("declared_rates", lambda v: _mapping(v, _number), {}),
            sensors_listed=read("sensors_listed", lambda v: _items(v, _text), []),
            sensors_seen=read("sensors_seen", lambda v: _mapping(v, _count), {}),
            tasks_available=read("tasks_available",
                                 lambda v: _mapping(v, lambda s: _items(s, _text)), {}),
            tasks_executing=read("tasks_executing", lambda v: _mapping(v, _text), {}),
            position=read("position", _position, None),
            message_counts=read("message_counts", lambda v: _mapping(v, _count), {}),
            conversations_dropped=read("conversations_dropped", _count, 0))


def _json_type(value: object) -> str:
    """What a JSON value is, in words (for a malformed report's error)."""
    names = {dict: "an object", list: "a list", str: "text", bool: "a boolean", int: "a number",
             float: "a number", type(None): "null"}
    return names.get(type(value), type(value).__name__)


def _mapping(value: object, item: Callable[[Any], T]) -> dict[str, T]:
    if not isinstance(value, dict):
        raise TypeError(f"{_json_type(value)}, not an object")
    return {str(k): item(v) for k, v in value.items()}


def _items(value: object, item: Callable[[Any], T]) -> tuple[T, ...]:
    if not isinstance(value, list):
        raise TypeError(f"{_json_type(value)}, not a list")
    return tuple(item(v) for v in value)


def _text(value: object) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{_json_type(value)}, not text")
    return value


def _number(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{_json_type(value)}, not a number")
    return float(value)


def _count(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{_json_type(value)}, not a whole number")
    return value


def _position(value: object) -> tuple[float, float, float | None] | None:
    if value is None:
        return None
    lat, lon, alt = _items(value, lambda v: None if v is None else _number(v))
    if lat is None or lon is None:
        raise TypeError("a position without latitude or longitude")
    return (lat, lon, alt)


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
                      [Violation(**v) for v in d.get("violations", [])])


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

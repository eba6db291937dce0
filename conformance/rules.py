"""The rule catalogue: one entry per normative statement of the WARA-PS Core System API v0.7.

Every check, fault switch and report speaks of rules by these ids. An id is stable: never
renumber, only add. The spec's own errors are entries too (``ERR-*``), each with the decision
taken; by default the readings found in practice pass with a warning (severity ``warning``)
and the built-in ``strict`` profile turns them into failures.
"""

from __future__ import annotations

import enum
import tomllib
from dataclasses import dataclass
from importlib import resources

from conformance.topics import (
    DELEGATION,
    DIRECT_EXECUTION,
    SENSOR_LEVEL,
    TST_EXECUTION,
)


class Severity(str, enum.Enum):
    """How a violation of a rule counts: ``error`` fails, ``warning`` warns."""

    ERROR = "error"
    WARNING = "warning"


PSEUDO_LEVELS = ("topic", "any")
"""The suite's own levels, for rules no level of 5.1 owns: topic naming (3) and any message."""

class Level(str, enum.Enum):
    """The level a rule belongs to: one of ``PSEUDO_LEVELS`` or a level of 5.1
    (``topics.LEVELS``), e.g. ``Level.TOPIC``, ``Level.DIRECT_EXECUTION``. Spelled out so a
    type checker knows the members (``tests/core/test_rules.py`` holds them to both)."""

    TOPIC = "topic"
    ANY = "any"
    SENSOR = SENSOR_LEVEL
    DIRECT_EXECUTION = DIRECT_EXECUTION
    TST_EXECUTION = TST_EXECUTION
    DELEGATION = DELEGATION


class Mode(str, enum.Enum):
    """How a rule is judged: from any traffic (passive), from a command and its answers in the
    traffic (conversation: lint judges it where the traffic holds the command, the suite sends
    one), or only from a stimulus the suite itself controls (active)."""

    PASSIVE = "passive"
    CONVERSATION = "conversation"
    ACTIVE = "active"


class Basis(str, enum.Enum):
    """What a rule stands on (docs/ARCHITECTURE.md 'What a rule stands on'): only ``stated`` and
    ``implied`` rules fail a unit; a ``decided`` rule warns as an interop risk unless the run is
    strict."""

    STATED = "stated"
    """Words of the spec (``quote``, verbatim) from which the rule follows with nothing added."""
    IMPLIED = "implied"
    """A quote and the one sentence (``because``) why the rule follows from it necessarily."""
    DECIDED = "decided"
    """The spec is silent or contradicts itself: ``decision`` says what this project chose."""


class Side(str, enum.Enum):
    """Whose fault a violation is (docs/ARCHITECTURE.md 'Whose fault it is')."""

    UNIT = "unit"
    """What the unit publishes and how it answers."""
    COMMANDER = "commander"
    """What a commander sends: commands on exec/command and tst/command."""
    SENDER = "sender"
    """Whoever published the message: a rule about any message (topic, JSON, stamp)."""


@dataclass(frozen=True)
class Condition:
    """One condition a rule's checks find (docs/ARCHITECTURE.md 'What a rule stands on'): the unit
    of judgement. A rule's own words are its default condition (``id`` ""); every threshold,
    deadline, tolerance, closed list or schema keyword its quote does not contain is a condition of
    its own, decided, so it warns unless the run adopts it (``[[rule.condition]]`` in
    ``rules.toml``)."""

    id: str
    title: str
    basis: Basis
    decision: str = ""
    quote: str = ""
    because: str = ""

    @property
    def is_decided(self) -> bool:
        return self.basis is Basis.DECIDED

    def basis_text(self) -> str:
        """What the condition stands on, for people: the quote (and why it follows), or the
        decision (an interop risk: the spec does not say)."""
        if self.basis is Basis.DECIDED:
            # What the decision calls a fault warns: next to a warn badge it must not read
            # as a failure (docs/ARCHITECTURE.md 'What a rule stands on').
            said = ("decided (the spec does not say; a finding warns, and fails only where "
                    "the arena adopts it: --strict-rules, or the profile's severity)")
            return f"{said}: {self.decision}" if self.decision else said
        text = f'{self.basis.value}: "{self.quote}"' if self.quote else self.basis.value
        return text + (f" ({self.because})" if self.because else "")


@dataclass(frozen=True)
class Rule:
    id: str
    title: str
    section: str
    severity: Severity
    level: Level
    mode: Mode
    decision: str = ""
    """A decided rule's decision: what this suite chose where the spec is silent or
    contradicts itself, and why."""
    side: Side = Side.UNIT
    """Whose fault a violation is; every rule on a command topic is the commander's."""
    basis: Basis = Basis.STATED
    quote: str = ""
    """The spec's words the rule stands on, verbatim (stated and implied rules)."""
    because: str = ""
    """An implied rule: why it follows from ``quote`` necessarily."""
    note: str = ""
    """A clarification of a stated or implied rule that adds no condition."""
    conditions: tuple[Condition, ...] = ()
    """The conditions beside the rule's own words, each with its basis (mostly decided: a
    deadline, a tolerance, a closed list the spec does not give)."""

    @property
    def spec_level(self) -> str | None:
        """The level of 5.1 a unit declares for this rule to apply to it; None for a
        pseudo-level (topic, any), which every unit is judged on."""
        return None if self.level.value in PSEUDO_LEVELS else self.level.value

    @property
    def is_erratum(self) -> bool:
        return self.id.startswith("ERR-")

    @property
    def is_decided(self) -> bool:
        return self.basis is Basis.DECIDED

    def basis_text(self, condition: str = "") -> str:
        """What the rule (or one of its conditions) stands on, for people: the quote (and why
        it follows), or the decision (an interop risk: the spec does not say)."""
        return self.condition(condition).basis_text()

    @property
    def own(self) -> Condition:
        """The rule's own words as its default condition (id "")."""
        return Condition("", self.title, self.basis, self.decision, self.quote, self.because)

    def condition(self, condition_id: str = "") -> Condition:
        """The condition ``condition_id`` of this rule ("" : the rule's own words). An id the
        catalogue does not give is a bug of the check that found it: KeyError."""
        if not condition_id:
            return self.own
        for c in self.conditions:
            if c.id == condition_id:
                return c
        raise KeyError(f"{self.id} has no condition {condition_id!r}")

    def decided(self, condition_id: str = "") -> bool:
        """Whether a finding of ``condition_id`` stands on this suite's decision only; a
        condition this catalogue does not know (a report of another version) is the rule's
        own words."""
        found = next((c for c in self.conditions if c.id == condition_id), None)
        return (found.basis if found is not None else self.basis) is Basis.DECIDED


def _load(text: str) -> tuple[Rule, ...]:
    """The rules of a catalogue file (``rules.toml``), in its order."""
    out = []
    for entry in tomllib.loads(text)["rule"]:
        conditions = tuple(
            Condition(c["id"], c["title"], Basis(c.get("basis", "decided")),
                      c.get("decision", ""), c.get("quote", ""), c.get("because", ""))
            for c in entry.get("condition", ()))
        assert len({c.id for c in conditions}) == len(conditions), entry["id"]
        assert all(c.id for c in conditions), f"{entry['id']}: a condition without its id"
        out.append(Rule(entry["id"], entry["title"], entry["section"],
                        Severity(entry["severity"]), Level(entry["level"]), Mode(entry["mode"]),
                        entry.get("decision", ""), Side(entry.get("side", "unit")),
                        Basis(entry.get("basis", "stated")), entry.get("quote", ""),
                        entry.get("because", ""), entry.get("note", ""), conditions))
    return tuple(out)


_CATALOGUE: tuple[Rule, ...] = _load(
    (resources.files("conformance") / "rules.toml").read_text(encoding="utf-8"))
"""The catalogue, as data: ``conformance/rules.toml`` (one ``[[rule]]`` per rule)."""

CATALOGUE: dict[str, Rule] = {rule.id: rule for rule in _CATALOGUE}
assert len(CATALOGUE) == len(_CATALOGUE), "duplicate rule id"


def get(rule_id: str) -> Rule:
    """The rule with this id; KeyError names close matches."""
    try:
        return CATALOGUE[rule_id]
    except KeyError:
        import difflib

        close = difflib.get_close_matches(rule_id, CATALOGUE, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise KeyError(f"unknown rule id {rule_id!r}{hint}") from None


def basis_counts() -> dict[str, int]:
    """How many rules stand on each basis (``stated``, ``implied``, ``decided``)."""
    return {b.value: sum(r.basis is b for r in _CATALOGUE) for b in Basis}


def condition_counts() -> dict[str, int]:
    """How many conditions (each rule's own words and its further conditions) stand on each
    basis."""
    every = [c for r in _CATALOGUE for c in (r.own, *r.conditions)]
    return {b.value: sum(c.basis is b for c in every) for b in Basis}


def reading(strict: bool) -> str:
    """How a run reads the catalogue: the counts by basis and what a decided rule does
    (docs/ARCHITECTURE.md 'What a rule stands on'); every output's header says it."""
    counts = basis_counts()
    said = f"{counts['stated']} stated, {counts['implied']} implied, {counts['decided']} decided"
    if strict:
        return f"{said}; strict: decided rules fail (--strict-rules, lint --strict, strict: true)"
    return (f"{said}; decided rules warn as interop risks (the spec does not say; "
            f"--strict-rules makes them fail)")


def rules(*, level: Level | None = None, mode: Mode | None = None) -> list[Rule]:
    """The catalogue in id order, optionally filtered by level and mode."""
    return [
        r for r in _CATALOGUE
        if (level is None or r.level is level) and (mode is None or r.mode is mode)
    ]

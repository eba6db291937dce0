"""Violations and verdicts: what every check yields and every report renders."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from datetime import UTC, datetime

from conformance.display import shorten


class Verdict(str, enum.Enum):
    """The outcome of one rule for one unit (docs/ARCHITECTURE.md 'Verdicts'), worst last."""

    PASS = "pass"
    SKIP = "skip"                      # not claimed by the unit or profile (reason given)
    COULD_NOT_TEST = "could-not-test"  # a precondition was missing (e.g. no reboot command)
    WARN = "warn"                      # an erratum reading or a recommended practice
    FAIL = "fail"

    @property
    def rank(self) -> int:
        return _RANK[self]

    @classmethod
    def worst(cls, verdicts: list[Verdict] | tuple[Verdict, ...]) -> Verdict:
        """The headline of several verdicts. A skip is 'not applicable', not a grade: passes
        with some skips read 'pass'; only when nothing was judged is the headline 'skip'."""
        judged = [v for v in verdicts if v is not cls.SKIP]
        if judged:
            return max(judged, key=lambda v: v.rank)
        return cls.SKIP if verdicts else cls.PASS


class Observed(str, enum.Enum):
    """What a scenario saw of a rule besides its violations: evidence the judge reads
    (``judge.judge_rule``), never a verdict of its own."""

    EXAMINED = "examined"
    """The stimulus was answered as the rule asks (the judge: pass, unless a violation)."""
    NOT_APPLICABLE = "not-applicable"
    """The unit's own declarations leave the rule out (the judge: skip, with the reason)."""
    UNTESTABLE = "untestable"
    """A precondition was missing (the judge: could-not-test, with the reason)."""


_RANK = {Verdict.PASS: 0, Verdict.SKIP: 1, Verdict.COULD_NOT_TEST: 2, Verdict.WARN: 3,
         Verdict.FAIL: 4}

EXCERPT_CHARS = 200


def clock(t: float) -> str:
    """A Unix time as a person reads it in a finding: ``15:26:04.465 UTC`` (the finding's
    own ``time`` carries the date); a time out of range stays a number."""
    try:
        return datetime.fromtimestamp(t, UTC).strftime("%H:%M:%S.%f")[:-3] + " UTC"
    except (OverflowError, OSError, ValueError):
        return repr(t)


def excerpt(payload: bytes | str | None, limit: int = EXCERPT_CHARS) -> str:
    """A short printable excerpt of a payload for evidence (never the whole 10 MB)."""
    if payload is None:
        return ""
    if isinstance(payload, bytes):
        text = payload[: limit * 4].decode("utf-8", errors="backslashreplace")
    else:
        text = payload[: limit * 4]
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def head(payload: bytes | memoryview, limit: int) -> bytes:
    """The first ``limit`` bytes of a payload kept as evidence (bounded memory), with '…'
    when that cut it: an excerpt shown later says it is one (``excerpt``)."""
    kept = bytes(payload[:limit])
    return kept + "…".encode() if len(payload) > limit else kept


@dataclass(frozen=True)
class Violation:
    """One broken rule, with the evidence a person needs to find and fix it.

    ``path`` is a JSON path into the payload (``$.params.speed``), empty when the rule is about
    the whole message or the topic. ``time`` is the arrival time (Unix seconds) of the message
    that shows it, when there is one.
    """

    rule: str
    expected: str
    observed: str
    topic: str = ""
    path: str = ""
    time: float | None = None
    excerpt: str = ""
    detail: str = ""
    """Free text: a fix hint, the window a rate was measured over, and so on."""
    unit: str = ""
    """The unit's address (``waraps/unit/air/simulation/dji0``) when known."""
    condition: str = ""
    """Which condition of the rule was found (``rules.Condition``): "" for the rule's own
    words, else one of its ``[[rule.condition]]`` ids (``late``, ``tolerance``, ...), each
    with its own basis."""
    command: str = ""
    """The com-uuid of the command a finding of no answer is about."""
    supersedes: str = ""
    """A com-uuid: this finding takes the place of the findings of this rule that the command
    was not answered (it was answered late after all: only late)."""

    @classmethod
    def of(cls, rule: str, *, expected: str, observed: str, topic: str = "", path: str = "",
           time: float | None = None, payload: bytes | str | None = None, detail: str = "",
           unit: str = "", condition: str = "", command: str = "",
           supersedes: str = "") -> Violation:
        # Kept per unit and rule (evidence): what came from the wire is bounded.
        return cls(rule=rule, expected=shorten(expected), observed=shorten(observed),
                   topic=topic, path=path, time=time, excerpt=excerpt(payload),
                   detail=shorten(detail), unit=unit, condition=condition,
                   command=command, supersedes=supersedes)

    def to_dict(self) -> dict[str, object]:
        return {k: v for k, v in self.__dict__.items() if v not in ("", None)}


@dataclass
class RuleResult:
    """The verdict of one rule for one unit, with every violation that led to it."""

    rule: str
    verdict: Verdict
    reason: str = ""
    violations: list[Violation] = field(default_factory=list)
    failing: int = -1
    """How many of a failed rule's ``violations``, from the first, fail it (the judge puts
    them first); those after only warn (a decided condition the run does not adopt). -1:
    every one (a strict run, a rule not failed)."""

    def shown_as(self, index: int) -> Verdict:
        """The verdict the ``index``-th violation is shown with: the rule's, or 'warn' for one
        that alone would only warn (its own basis says why)."""
        alone = 0 <= self.failing <= index
        return Verdict.WARN if self.verdict is Verdict.FAIL and alone else self.verdict

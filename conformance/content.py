"""Content rules a schema cannot state, checked in code on one decoded JSON object (stateless):
a stamp near the arrival time (MSG-005), a name that is the topic's (MSG-006), the heartbeat's
agent-type (HB-004), a response's own com-uuid (EXEC-005, TST-002), feedback statuses
(EXEC-FB-002), a start-tst tree's structure (TST-014).

``CONTENT_CHECKS`` holds the check of each topic kind and which rules it examines when; the
validator runs them after the schema (``Validator.validate``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Protocol

from conformance import schema, taskspec
from conformance.topics import AGENT_TYPES, ParsedTopic, TopicKind
from conformance.tst import read_tree
from conformance.violation import Violation, clock


class Limits(Protocol):
    """What the content checks read from the validator's profile."""

    @property
    def clock_tolerance(self) -> float:
        """MSG-005: seconds a stamp may differ from the arrival time."""

    @property
    def feedback_statuses(self) -> frozenset[str]:
        """EXEC-FB-002: statuses that are no violation."""


@dataclass(frozen=True)
class ContentCheck:
    """A content rule a schema cannot state, checked in code on the decoded JSON object of a
    topic kind. ``examines`` says which rule is examined when, as (rule, field, types): on a
    message whose ``field`` has one of ``types`` (exact types: a bool is no number)."""

    run: Callable[[Limits, ParsedTopic, dict[str, Any], bytes, float | None],
                  list[Violation] | None]
    examines: tuple[tuple[str, str, tuple[type, ...]], ...]

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(f for _, f, _ in self.examines))


def info_checks(limits: Limits, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                 time: float | None) -> list[Violation] | None:
    """MSG-005 (stamp in seconds near the arrival time), MSG-006 (name is the topic's unit),
    and for the heartbeat HB-004 (agent-type is the topic's type). None when all hold
    (the usual case: no list is made)."""
    found: list[Violation] | None = None
    unit = parsed.unit
    name = message.get("name")
    if unit is not None and isinstance(name, str) and name and name != unit.name:
        found = [Violation.of(
            "MSG-006", expected=f"'{unit.name}' (the UNIT of the topic)", observed=repr(name),
            topic=parsed.topic, path="$.name", time=time, payload=raw, unit=unit.base,
            detail="5: a unit publishes its heartbeat/info under its own name")]
    stamp = message.get("stamp")
    if time is not None and (type(stamp) is float or type(stamp) is int) and not (
            -limits.clock_tolerance <= stamp - time <= limits.clock_tolerance):
        found = (found or []) + stamp_violations(limits, parsed, stamp, raw, time)
    if unit is not None and parsed.kind is TopicKind.HEARTBEAT:
        agent_type = message.get("agent-type")
        if agent_type != unit.agent_type and agent_type in AGENT_TYPES:
            found = (found or []) + [Violation.of(
                "HB-004", expected=f"'{unit.agent_type}' (the type in the topic)",
                observed=repr(agent_type), topic=parsed.topic, path="$.agent-type",
                time=time, payload=raw, unit=unit.base,
                detail="5.1 agent-type and 3.1 PREFIX3 name the same thing")]
    return found

PLAUSIBLE_CLOCK = 365 * 86400.0
"""Seconds a clock may be off and still be read as one (a stamp in another unit, MSG-008;
``validate`` without an arrival time judges a stamp within it)."""


def _seconds(s: float) -> str:
    return f"{s / 86400:g} days" if s >= 86400 else f"{s:g} s"


def stamp_violations(limits: Limits, parsed: ParsedTopic, stamp: float, raw: bytes,
                      time: float) -> list[Violation]:
    tolerance = limits.clock_tolerance
    off = stamp - time
    if abs(off) <= tolerance:
        return []
    detail = "5.1: stamp is time.time(), seconds since the Unix epoch as a double"
    rule = "MSG-005"  # the unit's clock (decided), unless the stamp is in another unit (5.1)
    for scale, unit_name in ((1e3, "milliseconds"), (1e6, "microseconds"),
                             (1e9, "nanoseconds")):
        # In another unit when it reads as a plausible clock in it (within a year, as
        # `validate` without an arrival time): one explanation of one stamp, whatever the
        # clock tolerance and however far the unit's clock is off besides.
        if abs(stamp / scale - time) <= max(tolerance, PLAUSIBLE_CLOCK):
            detail = f"looks like {unit_name}: divide by {scale:.0e} ({detail})"
            rule = "MSG-008"
            break
    else:
        detail = (f"{abs(off):.1f} s {'ahead of' if off > 0 else 'behind'} the arrival "
                  f"time: is the unit's clock set? ({detail})")
    return [Violation.of(
        rule, expected=f"Unix seconds within {_seconds(tolerance)} of its arrival at "
                            f"{clock(time)} ({time:.3f})",
        observed=repr(stamp), topic=parsed.topic, path="$.stamp", time=time, payload=raw,
        unit=unit_of(parsed), detail=detail)]

def response_checks(limits: Limits, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                     time: float | None) -> list[Violation]:
    """EXEC-005 / TST-002: a response has a com-uuid of its own, not the command's."""
    com_uuid = message.get("com-uuid")
    if isinstance(com_uuid, str) and com_uuid and com_uuid == message.get("response-to"):
        rule = "EXEC-005" if parsed.kind is TopicKind.EXEC_RESPONSE else "TST-002"
        return [Violation.of(
            rule, expected="a fresh com-uuid, different from response-to",
            observed=f"com-uuid == response-to == {com_uuid!r}", topic=parsed.topic,
            path="$.com-uuid", time=time, payload=raw, unit=unit_of(parsed),
            detail="2: a UUID identifies each message; reusing the command's breaks resend "
                   "detection")]
    return []

def feedback_checks(limits: Limits, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                     time: float | None) -> list[Violation]:
    """EXEC-FB-002: a standard status, a task-specific one this unit declares, or
    look-at-position's; a near miss of a standard status is a typo, anything else may be
    task-specific (12.4 allows those) and is reported with 'task-specific?'."""
    status = message.get("status")
    if not isinstance(status, str) or not status or status in limits.feedback_statuses:
        return []
    standard = standard_statuses()
    near = _near_miss(status, standard)
    if near is not None:
        detail = f"a near miss of the standard status '{near}' (12.4): fix the spelling"
    else:
        detail = ("task-specific? 12.4 allows task-specific strings: declare it in the "
                  "profile's task-specific-statuses")
    return [Violation.of(
        "EXEC-FB-002", expected="one of " + " | ".join(standard) + " or a declared "
        "task-specific status", observed=repr(status), topic=parsed.topic, path="$.status",
        time=time, payload=raw, unit=unit_of(parsed), detail=detail)]

def tst_command_checks(limits: Limits, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                        time: float | None) -> list[Violation] | None:
    """TST-014: a start-tst tree's structure beyond its schema (``conformance.tst``):
    node-uuids used twice, children where only seq and conc have them, a seq or conc
    without children, common_params and common-params that disagree."""
    if message.get("command") != "start-tst" or not isinstance(message.get("tst"), dict):
        return None
    _root, problems = read_tree(message["tst"])
    return [Violation.of(p.rule, expected=p.expected, observed=p.observed,
                         topic=parsed.topic, path=p.path, time=time, payload=raw,
                         unit=unit_of(parsed), detail="14.3.4, 11: a fully instantiated tree")
            for p in problems if not p.in_schema] or None


_INFO = ContentCheck(info_checks, (
    ("MSG-006", "name", (str,)), ("MSG-005", "stamp", (float, int)),
    ("MSG-008", "stamp", (float, int))))
CONTENT_CHECKS: dict[TopicKind, ContentCheck] = {
    TopicKind.HEARTBEAT: ContentCheck(info_checks,
                                      _INFO.examines + (("HB-004", "agent-type", (str,)),)),
    TopicKind.SENSOR_INFO: _INFO,
    TopicKind.DIRECT_EXECUTION_INFO: _INFO,
    TopicKind.TST_EXECUTION_INFO: _INFO,
    TopicKind.EXEC_RESPONSE: ContentCheck(response_checks,
                                          (("EXEC-005", "com-uuid", (str,)),)),
    TopicKind.TST_RESPONSE: ContentCheck(response_checks,
                                         (("TST-002", "com-uuid", (str,)),)),
    TopicKind.EXEC_FEEDBACK: ContentCheck(feedback_checks,
                                          (("EXEC-FB-002", "status", (str,)),)),
    # TST-014 on a start-tst's tree (the only tst/command with a 'tst' object).
    TopicKind.TST_COMMAND: ContentCheck(tst_command_checks,
                                        (("TST-014", "tst", (dict,)),)),
}
"""The content check of each topic kind, and what it examines."""


def statuses_allowed(task_specific: tuple[str, ...]) -> frozenset[str]:
    """Feedback statuses that are no violation: 12.4's standard ones, those of the tasks'
    specification files (look-at-position's in-view...) and the profile's task-specific ones."""
    return frozenset(standard_statuses()) | task_feedback_statuses() | frozenset(task_specific)


@lru_cache(maxsize=1)
def standard_statuses() -> tuple[str, ...]:
    node = schema.load("messages/exec-feedback.json")["properties"]["status"]
    return tuple(node["x-standard-statuses"])


@lru_cache(maxsize=1)
def task_feedback_statuses() -> frozenset[str]:
    return frozenset(s for t in taskspec.task_specs() for s in t.feedback_statuses)


def _edit_distance(a: str, b: str, limit: int) -> int:
    """Levenshtein distance, giving up (limit + 1) once it exceeds ``limit``."""
    if abs(len(a) - len(b)) > limit:
        return limit + 1
    previous = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        current = [i]
        for j, cb in enumerate(b, 1):
            current.append(min(previous[j] + 1, current[j - 1] + 1, previous[j - 1] + (ca != cb)))
        if min(current) > limit:
            return limit + 1
        previous = current
    return previous[-1]


def _near_miss(status: str, vocabulary: tuple[str, ...]) -> str | None:
    """The standard status ``status`` nearly is (same up to case/whitespace, or within edit
    distance 2), if any."""
    folded = status.strip().lower()
    for word in vocabulary:
        if folded == word:
            return word
    for word in vocabulary:
        if _edit_distance(folded, word, 2) <= 2:
            return word
    return None


def unit_of(parsed: ParsedTopic) -> str:
    return parsed.unit.base if parsed.unit is not None else ""

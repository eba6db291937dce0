"""The validator: given a topic and a raw payload, the message kind and every violation.

The one place a message is parsed. It never raises on hostile input: non-UTF-8 bytes, invalid
JSON, NaN literals, a 10 MB payload or JSON nested 100,000 deep each become a violation of the
rule that names the problem (MSG-001..MSG-004).

Then the message is checked against the JSON Schema of its kind (``conformance.schema``:
jsonschema-rs, compiled once per process, ``is_valid`` first; errors are collected only when it
fails, docs/FIELD-NOTES.md 'Validation cost'). Each schema error becomes a violation of the rule
named by the nearest ``x-rule`` along its evaluation path (``conformance/schema_errors.py``), with
the JSON path of the offending value (``$.task.params.waypoints[2].latitude``), what was expected
and what was observed; one violation per rule and spot. An erratum reading (ERR-*) yields only its
ERR violation: the profile, not the validator, decides whether it warns or fails. Last come the
content rules a schema cannot state: MSG-005 (stamp near arrival), MSG-006 and HB-004 (name and
agent-type against the topic), EXEC-005 (a response's own com-uuid) and EXEC-FB-002 (feedback
status).

One path for every message: what depends on the topic alone is worked out once per topic,
and the checks that cannot fail on a short ASCII payload are not run on one (``_decode``).

``Validator.examined`` says which rules were examined on a message, so that each can pass where
no violation was found: the topic's naming rules, the decoding rules, the schema rules the
message reached (``schema.reach``, from jsonschema-rs's evaluation) and the content rules
whose fields it has (``ContentCheck.examines``).

Stateless: one message at a time. What needs history (rates, agent-uuid stability, responses
matching commands) is in ``conformance.checks``.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from functools import cached_property, partial
from typing import Any, NamedTuple

import orjson
from orjson import JSONDecodeError as _JSONDecodeError
from orjson import loads as _loads

from conformance import schema
from conformance.content import CONTENT_CHECKS, statuses_allowed, unit_of
from conformance.jsontext import shallow_members
from conformance.profile import Profile
from conformance.schema_errors import expects_object, json_type, schema_violations, short
from conformance.topics import (
    ParsedTopic,
    TopicKind,
    naming_rules,
    naming_violations,
    parse_topic,
)
from conformance.violation import Violation

MAX_PAYLOAD_BYTES = 1 << 20  # MSG-004
MAX_DEPTH = 64  # MSG-004


class Validation(NamedTuple):
    """The result of validating one message (an immutable record: made for every message,
    a NamedTuple costs 0.2 us less to make than a frozen dataclass).

    ``kind`` names the message: the topic kind (``heartbeat``, ``sensor_info``, ...), refined
    by content where the topic carries several messages: ``sensor/position``,
    ``exec/command/ping``, ``exec/command/start-task``, ``exec/response``, ``exec/feedback``,
    ``tst/command/start-tst``, ... ``message`` is the decoded JSON value, or None when the
    payload could not be decoded.
    """

    topic: ParsedTopic
    kind: str
    message: Any
    violations: tuple[Violation, ...]

    @property
    def ok(self) -> bool:
        return not self.violations

    @property
    def decoded(self) -> bool:
        return self.message is not None


def read_in_part(v: Validation) -> bool:
    """Whether ``v``'s message holds only the top-level fields of a payload nested past
    MSG-004's bound (its schema and content rules were not examined)."""
    return bool(v.violations) and v.violations[-1].rule == "MSG-004" and v.message is not None


_validation = partial(tuple.__new__, Validation)
"""``Validation(...)`` without the NamedTuple's Python-level ``__new__``: made for every message
(bench/bench_lint.py)."""


class Examined:
    """The rules the validator examined on one message (``Validator.examined``): each passes
    where the message showed no violation of it. ``decided_by`` names the top-level fields
    whose values chose among the schema's branches (``""``: the message's own value); two
    messages of one kind, shape and values there were examined alike (the Monitor's cache).

    Made once per distinct set and shared, so that counting messages per set hashes by
    identity. Iterating gives the rule ids.
    """

    __slots__ = ("rules", "decided_by")

    def __init__(self, rules: tuple[str, ...], decided_by: tuple[str, ...]) -> None:
        self.rules = rules
        self.decided_by = decided_by

    def __iter__(self) -> Iterator[str]:
        return iter(self.rules)

    def __repr__(self) -> str:
        return f"Examined({self.rules!r}, decided_by={self.decided_by!r})"


MAX_EXAMINED_SETS = 4096
"""Distinct examined sets shared; further ones are made for each message (still correct)."""
_examined_sets: dict[tuple[tuple[str, ...], tuple[str, ...]], Examined] = {}


def _examined(rules: set[str], decided_by: frozenset[str] = frozenset()) -> Examined:
    key = (tuple(sorted(rules)), tuple(sorted(decided_by)))
    found = _examined_sets.get(key)
    if found is None:
        found = Examined(*key)
        if len(_examined_sets) < MAX_EXAMINED_SETS:
            _examined_sets[key] = found
    return found


DECODING_RULES = ("MSG-001", "MSG-002")
"""Examined on every message that could be read (MSG-004, its size, on every message)."""


class _TopicPlan:
    """What validating a message needs from its topic alone, worked out once per topic: the
    parsed topic, its naming violations, the message kind, schema and content check (kind
    and schema None where the kind depends on the content: commands)."""

    __slots__ = ("parsed", "naming", "kind", "path", "schema", "content", "unit", "messages")

    def __init__(self, topic: str) -> None:
        parsed = self.parsed = parse_topic(topic)
        self.naming = tuple(naming_violations(topic))
        self.unit = unit_of(parsed)
        self.messages = 0
        self.content = CONTENT_CHECKS.get(parsed.kind)
        kind: str | None
        if parsed.kind is TopicKind.SENSOR:
            kind = sys.intern(f"sensor/{parsed.sensor}")  # interned: compared by identity first
        elif parsed.kind in (TopicKind.EXEC_COMMAND, TopicKind.TST_COMMAND):
            kind = None  # exec/command/<command>: read off each message
        else:
            kind = parsed.kind.value
        self.kind = kind
        self.path = schema.schema_path_for_kind(kind) if kind is not None else None
        self.schema = schema.compiled(self.path) if self.path is not None else None


_SHALLOW_BYTES = 2 * MAX_DEPTH + 1
"""A payload this short cannot nest deeper than MAX_DEPTH (each level takes two brackets)."""
MAX_TOPIC_PLANS = 65536
"""Topics whose plan is kept; further ones are worked out for each message (still correct)."""

class Unreadable(Exception):
    """A payload that cannot be read as JSON: the rule it breaks, with what was expected,
    what was observed and a detail for a person."""

    def __init__(self, rule: str, expected: str, observed: str, detail: str = "") -> None:
        super().__init__(rule, expected, observed, detail)
        self.rule, self.expected, self.observed, self.detail = rule, expected, observed, detail


def _depth_exceeds(payload: bytes, limit: int) -> bool:
    """Whether brackets nest deeper than ``limit`` (a cheap scan; strings may hold brackets,
    which only makes this err towards examining less)."""
    if payload.count(b"[") + payload.count(b"{") <= limit:
        return False
    depth = 0
    for byte in payload:
        if byte in (0x5B, 0x7B):
            depth += 1
            if depth > limit:
                return True
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return False


_DEEPER = "deeper"


def _shallow(raw: bytes) -> tuple[dict[str, Any], int] | None:
    """The top-level fields of an object nested deeper than MAX_DEPTH that nest less, and how
    many fields were left out; None when it is no object of readable fields. Only what can be
    read safely is judged: a field nested 65 deep must not hide the rest of a message (a rate,
    a stamp) from the rules."""
    found = shallow_members(raw, MAX_DEPTH)
    return found if found is not None and found[0] else None


NAMES_CHECKED = 64
NAMES_SAMPLED = 16
"""Member names counted on a topic's first 64 messages, then on every 16th: a serializer
that names a member twice does it in every message of a shape, and counting costs a tenth of
lint's speed (bench/bench_lint.py) where sampling costs nothing measurable."""


def _names_lost(raw: bytes, message: Any) -> bool:
    """Whether reading ``raw`` lost member names: an object naming a member twice keeps one
    (RFC 8259 4). Counted, not parsed: names in the text (a closing quote before a colon, or
    one space and a colon) against names in orjson's compact writing of what was read (a quote
    inside a string is escaped, and written alike by both); names written with other
    whitespace before their colon are not counted. Four C scans and a write (sampled:
    ``NAMES_SAMPLED``)."""
    found = raw.count(b'":') + raw.count(b'" :')
    if found < 2:
        return False
    written = orjson.dumps(message)
    return found > written.count(b'":') + written.count(b'" :')


def _twice(raw: bytes) -> str:
    """The member names an object of ``raw`` holds twice, for a person (at most five)."""
    import json

    twice: list[str] = []

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        seen: set[str] = set()
        for name, _ in items:
            if name in seen and name not in twice:
                twice.append(name)
            seen.add(name)
        return dict(items)

    json.loads(raw, object_pairs_hook=pairs)  # nesting at most MAX_DEPTH: no deep recursion
    shown = ", ".join(short(name, 40) for name in twice[:5])
    return f"named twice: {shown}" + (f" and {len(twice) - 5} more" if len(twice) > 5 else "")


def _named_twice(plan: _TopicPlan, topic: str, raw: bytes, time: float | None) -> Violation:
    """MSG-002's duplicate-names condition: an object of ``raw`` names a member twice."""
    return Violation.of(
        "MSG-002", condition="duplicate-names", expected="each member name once in "
        "an object (RFC 8259 4: names SHOULD be unique)", observed=_twice(raw),
        topic=topic, time=time, payload=raw, unit=plan.unit,
        detail="this suite read the last value; another reader may take the first")


def _decode(raw: bytes) -> Any:
    """The JSON value of a payload; ``Unreadable`` names the first rule that keeps it from
    being read: MSG-004 (size), MSG-001 (UTF-8), MSG-004 (depth), MSG-002 (JSON). The checks
    that cannot fail on a short ASCII payload are not run on one (the usual case)."""
    if len(raw) > MAX_PAYLOAD_BYTES:
        raise Unreadable("MSG-004", f"at most {MAX_PAYLOAD_BYTES} bytes", f"{len(raw)} bytes")
    if not raw.isascii():
        try:
            raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise Unreadable("MSG-001", "UTF-8 text",
                             f"byte 0x{raw[e.start]:02x} at offset {e.start}",
                             "JSON messages are UTF-8 text; binary payloads belong "
                             "elsewhere") from None
    if len(raw) > _SHALLOW_BYTES and _depth_exceeds(raw, MAX_DEPTH):
        raise Unreadable("MSG-004", f"nesting depth at most {MAX_DEPTH}", _DEEPER,
                         "what nests deeper was not examined: the message is judged on its "
                         "shallower top-level fields alone")
    try:
        return _loads(raw)
    except _JSONDecodeError as e:
        raise Unreadable("MSG-002", "valid JSON (RFC 8259)", str(e),
                         "NaN/Infinity, trailing commas, single quotes and unquoted strings "
                         "are not JSON (see ERR-002)") from None


def decode(raw: bytes) -> Any:
    """The JSON value of a payload read within MSG-004's bounds (1 MiB, 64 levels), as UTF-8
    and as JSON with finite numbers (1 followed by 400 zeros is refused, not an int Python
    cannot turn into a float); ``Unreadable`` says why not. Every reader of a payload outside
    the validator (the profile drafter) reads through this."""
    return _decode(raw)


class Validator:
    """Validates messages against the topic grammar and the schemas, under a profile."""

    def __init__(self, profile: Profile | None = None) -> None:
        self.profile = profile or Profile()
        self._plans: dict[str, _TopicPlan] = {}
        self.clock_tolerance = self.profile.clock_tolerance
        """MSG-005: seconds a stamp may differ from the arrival time (``content.Limits``)."""

    def _plan(self, topic: str) -> _TopicPlan:
        plan = self._plans.get(topic)
        if plan is None:
            plan = _TopicPlan(topic)
            # A long topic (MQTT allows 64 KiB) is planned each time: the plans stay small.
            if len(self._plans) < MAX_TOPIC_PLANS and len(topic) <= 1024:
                self._plans[topic] = plan
        return plan

    def validate(self, topic: str, payload: bytes | str, time: float | None = None) -> Validation:
        """Validate one message; ``time`` is its arrival time (Unix seconds) for MSG-005."""
        plan = self._plans.get(topic) or self._plan(topic)
        parsed = plan.parsed
        raw = payload.encode("utf-8", "surrogatepass") if isinstance(payload, str) else payload
        try:
            message = _decode(raw)
        except Unreadable as e:
            return self._unreadable(plan, topic, raw, time, e)
        plan.messages += 1
        if type(message) is dict and (plan.messages <= NAMES_CHECKED or not plan.messages
                                      % NAMES_SAMPLED) and _names_lost(raw, message):
            plan_naming = plan.naming + (_named_twice(plan, topic, raw, time),)
        else:
            plan_naming = plan.naming
        kind = self._kind(parsed, message) if plan.kind is None else plan.kind
        if plan.kind is None:  # a command: its kind and schema follow its 'command'
            path = schema.schema_path_for_kind(kind)
            validator = schema.compiled(path) if path is not None else None
        else:
            path, validator = plan.path, plan.schema
        if path is None or validator is None:  # an optional sensor, an unknown subtopic
            return _validation((parsed, kind, message, plan_naming))
        found: list[Violation] | None
        if type(message) is not dict and expects_object(path):
            found = [Violation.of(
                "MSG-003", expected=f"a JSON object ({kind})",
                observed=f"{json_type(message)} {short(message)}", topic=topic, path="$",
                time=time, payload=raw, unit=plan.unit)]
        else:
            found = None
            if not validator.is_valid(message):  # docs/FIELD-NOTES.md 'Validation cost'
                found = schema_violations(path, validator, message, topic, raw, time,
                                           plan.unit)
            content = plan.content
            if content is not None and type(message) is dict:
                out = content.run(self, parsed, message, raw, time)
                if out:
                    found = out if found is None else found + out
        return _validation((parsed, kind, message,
                            plan_naming + tuple(found) if found else plan_naming))

    def _unreadable(self, plan: _TopicPlan, topic: str, raw: bytes, time: float | None,
                    e: Unreadable) -> Validation:
        """A payload that could not be read whole: the rule it breaks; one nested too deep is
        judged on its shallower top-level fields (``_shallow``)."""
        parsed = plan.parsed
        shallow = _shallow(raw) if e.observed == _DEEPER else None
        observed = e.observed if shallow is None else (
            f"deeper in {shallow[1]} top-level field(s); judged on the other "
            f"{len(shallow[0])}")
        kind = (parsed.kind.value if shallow is None
                else plan.kind or self._kind(parsed, shallow[0]))
        return _validation((parsed, kind, shallow and shallow[0], plan.naming + (Violation.of(
            e.rule, expected=e.expected, observed=observed, topic=topic, time=time,
            payload=raw, detail=e.detail, unit=plan.unit),)))

    def examined(self, v: Validation) -> Examined:
        """The rules examined in validating ``v``: the topic's naming rules and MSG-004 on
        every message; MSG-001 and MSG-002 on one that could be read; MSG-003 where an object
        is due; the schema rules the message reached (``schema.reach``, from jsonschema-rs's
        evaluation: whatever keyword led there); the content rules whose fields it has.

        The schema part costs 10-100 times validating (bench/bench_validate.py): call it once
        per message shape (``Monitor.feed`` caches it by shape and ``decided_by`` values).
        """
        rules = {*naming_rules(v.topic), "MSG-004"}
        message = v.message
        if message is None or read_in_part(v):
            return _examined(rules)  # what was read in part was not examined as a message
        rules.update(DECODING_RULES)
        path = schema.schema_path_for_kind(v.kind)
        if path is None:
            return _examined(rules)
        is_object = type(message) is dict
        if is_object or expects_object(path):
            rules.add("MSG-003")
        if not is_object and expects_object(path):
            return _examined(rules)  # not an object: the schema was not applied
        reach = schema.reach(path, message)
        rules |= reach.rules
        content = CONTENT_CHECKS.get(v.topic.kind)
        if content is not None and is_object:
            rules.update(rule for rule, field, types in content.examines
                         if type(message.get(field)) in types)
        return _examined(rules, reach.decided_by)

    @staticmethod
    def content_fields(kind: TopicKind) -> tuple[str, ...]:
        """The fields whose types decide which content rules are examined on a message of
        topic kind ``kind`` (part of a message's shape for ``examined``)."""
        content = CONTENT_CHECKS.get(kind)
        return content.fields if content is not None else ()

    @cached_property
    def feedback_statuses(self) -> frozenset[str]:
        """EXEC-FB-002: feedback statuses that are no violation (``content.Limits``)."""
        return statuses_allowed(self.profile.task_specific_statuses)

    def _kind(self, parsed: ParsedTopic, message: Any) -> str:
        if parsed.kind in (TopicKind.EXEC_COMMAND, TopicKind.TST_COMMAND) and isinstance(
                message, dict) and isinstance(message.get("command"), str):
            return f"{parsed.kind.value}/{message['command']}"
        return parsed.kind.value


_default: Validator | None = None


def validate(topic: str, payload: bytes | str, time: float | None = None) -> Validation:
    """Validate one message under the default profile (a shared, reused validator)."""
    global _default
    if _default is None:
        _default = Validator()
    return _default.validate(topic, payload, time)

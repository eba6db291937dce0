"""The validator: given a topic and a raw payload, the message kind and every violation.

The one place a message is parsed. It never raises on hostile input: non-UTF-8 bytes, invalid
JSON, NaN literals, a 10 MB payload or JSON nested 100,000 deep each become a violation of the
rule that names the problem (MSG-001..MSG-004).

Then the message is checked against the JSON Schema of its kind (``conformance.schema``:
jsonschema-rs, compiled once per process, ``is_valid`` first; errors are collected only when it
fails, FIELD-NOTES). Each schema error becomes a violation of the rule named by the nearest
``x-rule`` along its evaluation path, with the JSON path of the offending value
(``$.task.params.waypoints[2].latitude``), what was expected and what was observed; one
violation per rule and spot. An erratum reading (ERR-*) yields only its ERR violation: the
profile, not the validator, decides whether it warns or fails. Last come the content rules a
schema cannot state: MSG-005 (stamp near arrival), MSG-006 and HB-004 (name and agent-type
against the topic), EXEC-005 (a response's own com-uuid) and EXEC-FB-002 (feedback status).

Stateless: one message at a time. What needs history (rates, agent-uuid stability, responses
matching commands) is in ``conformance.checks``.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from functools import cache, cached_property, lru_cache
from typing import Any

import jsonschema_rs
import orjson
from orjson import JSONDecodeError as _JSONDecodeError
from orjson import loads as _loads

from conformance import schema
from conformance.profile import Profile
from conformance.topics import AGENT_TYPES, ParsedTopic, TopicKind, naming_violations, parse_topic
from conformance.tst import read_tree
from conformance.violation import Violation

MAX_PAYLOAD_BYTES = 1 << 20  # MSG-004
MAX_DEPTH = 64  # MSG-004


@dataclass(frozen=True)
class Validation:
    """The result of validating one message.

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


_new_object = object.__new__


def _validation(topic: ParsedTopic, kind: str, message: Any,
                violations: tuple[Violation, ...]) -> Validation:
    """``Validation(topic, kind, message, violations)`` without the frozen dataclass's
    ``__init__`` (four ``object.__setattr__`` calls): made once per message. The instance is
    the same (same fields, equality, hash, ``dataclasses.replace``)."""
    v = _new_object(Validation)
    d = v.__dict__
    d["topic"] = topic
    d["kind"] = kind
    d["message"] = message
    d["violations"] = violations
    return v


class _TopicPlan:
    """What validating a message needs from its topic alone, worked out once per topic: the
    parsed topic, its naming violations, the message kind, schema and content check (None
    where the kind depends on the content: commands)."""

    __slots__ = ("parsed", "naming", "kind", "path", "schema", "expects_object", "content",
                 "unit")

    def __init__(self, topic: str) -> None:
        parsed = self.parsed = parse_topic(topic)
        self.naming = tuple(naming_violations(topic))
        self.unit = _unit(parsed)
        self.content = _CONTENT_CHECKS.get(parsed.kind)
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
        self.expects_object = _expects_object(self.path) if self.path is not None else False


_SHALLOW_BYTES = 2 * MAX_DEPTH + 1
"""A payload this short cannot nest deeper than MAX_DEPTH (each level takes two brackets)."""
MAX_TOPIC_PLANS = 65536
"""Topics whose plan is kept; further ones are worked out for each message (still correct)."""
_EMPTY: tuple[Violation, ...] = ()


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


class Validator:
    """Validates messages against the topic grammar and the schemas, under a profile."""

    def __init__(self, profile: Profile | None = None) -> None:
        self.profile = profile or Profile()
        self._plans: dict[str, _TopicPlan] = {}
        self._tolerance = self.profile.clock_tolerance

    def validate(self, topic: str, payload: bytes | str, time: float | None = None) -> Validation:
        """Validate one message; ``time`` is its arrival time (Unix seconds) for MSG-005."""
        # The fast path: a well-formed payload of a topic seen before (nearly every message of
        # a fleet). Anything unusual goes the careful way below, which decides the same.
        plan = self._plans.get(topic)
        if plan is None:
            plan = _TopicPlan(topic)
            if len(self._plans) < MAX_TOPIC_PLANS:
                self._plans[topic] = plan
        if (type(payload) is not bytes or len(payload) > MAX_PAYLOAD_BYTES
                or not payload.isascii()
                or (len(payload) > _SHALLOW_BYTES
                    and payload.count(b"[") + payload.count(b"{") > MAX_DEPTH)):
            return self._validate(topic, payload, time)
        try:
            message = _loads(payload)
        except _JSONDecodeError:
            return self._validate(topic, payload, time)
        kind = plan.kind
        parsed = plan.parsed
        if kind is None:  # a command: its kind and schema follow its 'command'
            kind = self._kind(parsed, message)
            path = schema.schema_path_for_kind(kind)
            if path is None:
                return _validation(parsed, kind, message, plan.naming)
            validator = schema.compiled(path)
            expects_object = _expects_object(path)
        else:
            path = plan.path
            if path is None:  # an optional sensor or unknown subtopic: no content defined
                return _validation(parsed, kind, message, plan.naming)
            validator = plan.schema
            expects_object = plan.expects_object
        if type(message) is not dict:
            if expects_object:
                return _validation(parsed, kind, message, plan.naming + (Violation.of(
                    "MSG-003", expected=f"a JSON object ({kind})",
                    observed=f"{_json_type(message)} {_short(message)}", topic=topic, path="$",
                    time=time, payload=payload, unit=plan.unit),))
            if validator.is_valid(message):  # a sensor value: _validation(...), inline
                v = _new_object(Validation)
                d = v.__dict__
                d["topic"] = parsed
                d["kind"] = kind
                d["message"] = message
                d["violations"] = plan.naming
                return v
            return _validation(parsed, kind, message, plan.naming + tuple(_schema_violations(
                path, validator, message, topic, payload, time, plan.unit)))
        found: list[Violation] | None = None
        if not validator.is_valid(message):  # FIELD-NOTES: the fast path; errors on failure
            found = _schema_violations(path, validator, message, topic, payload, time,
                                       plan.unit)
        check = plan.content
        if check is not None:
            out = check(self, parsed, message, payload, time)
            if out:
                if found is None:
                    found = out
                else:
                    found.extend(out)
        if found is None:  # nothing wrong (the usual case): _validation(...), inline
            v = _new_object(Validation)
            d = v.__dict__
            d["topic"] = parsed
            d["kind"] = kind
            d["message"] = message
            d["violations"] = plan.naming
            return v
        return _validation(parsed, kind, message, plan.naming + tuple(found))

    def _validate(self, topic: str, payload: bytes | str, time: float | None) -> Validation:
        """The careful path, one check after another (module docstring)."""
        parsed = parse_topic(topic)
        found = naming_violations(topic)
        raw = payload.encode("utf-8", "surrogatepass") if isinstance(payload, str) else payload

        def fail(rule: str, expected: str, observed: str, detail: str = "") -> Validation:
            found.append(Violation.of(rule, expected=expected, observed=observed, topic=topic,
                                      time=time, payload=raw, detail=detail,
                                      unit=_unit(parsed)))
            return Validation(parsed, parsed.kind.value, None, tuple(found))

        if len(raw) > MAX_PAYLOAD_BYTES:
            return fail("MSG-004", f"at most {MAX_PAYLOAD_BYTES} bytes", f"{len(raw)} bytes")
        try:
            raw.decode("utf-8")
        except UnicodeDecodeError as e:
            return fail("MSG-001", "UTF-8 text", f"byte 0x{raw[e.start]:02x} at offset {e.start}",
                        "JSON messages are UTF-8 text; binary payloads belong elsewhere")
        if _depth_exceeds(raw, MAX_DEPTH):
            return fail("MSG-004", f"nesting depth at most {MAX_DEPTH}", "deeper")
        try:
            message = orjson.loads(raw)
        except orjson.JSONDecodeError as e:
            return fail("MSG-002", "valid JSON (RFC 8259)", str(e),
                        "NaN/Infinity, trailing commas, single quotes and unquoted strings "
                        "are not JSON (see ERR-002)")
        kind = self._kind(parsed, message)
        found.extend(self._message_violations(parsed, kind, message, raw, time))
        return Validation(parsed, kind, message, tuple(found))

    def _kind(self, parsed: ParsedTopic, message: Any) -> str:
        if parsed.kind is TopicKind.SENSOR:
            return f"sensor/{parsed.sensor}"
        if parsed.kind in (TopicKind.EXEC_COMMAND, TopicKind.TST_COMMAND) and isinstance(
                message, dict) and isinstance(message.get("command"), str):
            return f"{parsed.kind.value}/{message['command']}"
        return parsed.kind.value

    def _message_violations(self, parsed: ParsedTopic, kind: str, message: Any, raw: bytes,
                            time: float | None) -> list[Violation]:
        """Schema rules (each error mapped to its rule by ``x-rule``), then the content rules a
        schema cannot state: MSG-005, MSG-006, HB-004 against the topic, EXEC-005, EXEC-FB-002."""
        path = schema.schema_path_for_kind(kind)
        if path is None:
            return []  # an optional sensor or unknown subtopic: the spec defines no content
        found: list[Violation] = []
        topic = parsed.topic
        if not isinstance(message, dict):
            if _expects_object(path):
                return [Violation.of(
                    "MSG-003", expected=f"a JSON object ({kind})",
                    observed=f"{_json_type(message)} {_short(message)}", topic=topic, path="$",
                    time=time, payload=raw, unit=_unit(parsed))]
        validator = schema.compiled(path)
        if not validator.is_valid(message):  # FIELD-NOTES: the fast path; errors only on failure
            found.extend(_schema_violations(path, validator, message, topic, raw, time,
                                            _unit(parsed)))
        if isinstance(message, dict):
            check = _CONTENT_CHECKS.get(parsed.kind)
            if check is not None:
                out = check(self, parsed, message, raw, time)
                if out:
                    found.extend(out)
        return found

    # --- content rules (stateless, one message) ----------------------------------------------

    def _info_checks(self, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
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
                -self._tolerance <= stamp - time <= self._tolerance):
            found = (found or []) + self._stamp_violations(parsed, stamp, raw, time)
        if unit is not None and parsed.kind is TopicKind.HEARTBEAT:
            agent_type = message.get("agent-type")
            if agent_type != unit.agent_type and agent_type in AGENT_TYPES:
                found = (found or []) + [Violation.of(
                    "HB-004", expected=f"'{unit.agent_type}' (the type in the topic)",
                    observed=repr(agent_type), topic=parsed.topic, path="$.agent-type",
                    time=time, payload=raw, unit=unit.base,
                    detail="5.1 agent-type and 3.1 PREFIX3 name the same thing")]
        return found

    def _stamp_violations(self, parsed: ParsedTopic, stamp: float, raw: bytes,
                          time: float) -> list[Violation]:
        tolerance = self.profile.clock_tolerance
        off = stamp - time
        if abs(off) <= tolerance:
            return []
        detail = "5.1: stamp is time.time(), seconds since the Unix epoch as a double"
        for scale, unit_name in ((1e3, "milliseconds"), (1e6, "microseconds"),
                                 (1e9, "nanoseconds")):
            if abs(stamp / scale - time) <= tolerance:
                detail = f"looks like {unit_name}: divide by {scale:.0e} ({detail})"
                break
        else:
            detail = (f"{abs(off):.1f} s {'ahead of' if off > 0 else 'behind'} the arrival "
                      f"time: is the unit's clock set? ({detail})")
        return [Violation.of(
            "MSG-005", expected=f"Unix seconds within {tolerance:g} s of arrival {time:.3f}",
            observed=repr(stamp), topic=parsed.topic, path="$.stamp", time=time, payload=raw,
            unit=_unit(parsed), detail=detail)]

    def _response_checks(self, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                         time: float | None) -> list[Violation]:
        """EXEC-005 / TST-002: a response has a com-uuid of its own, not the command's."""
        com_uuid = message.get("com-uuid")
        if isinstance(com_uuid, str) and com_uuid and com_uuid == message.get("response-to"):
            rule = "EXEC-005" if parsed.kind is TopicKind.EXEC_RESPONSE else "TST-002"
            return [Violation.of(
                rule, expected="a fresh com-uuid, different from response-to",
                observed=f"com-uuid == response-to == {com_uuid!r}", topic=parsed.topic,
                path="$.com-uuid", time=time, payload=raw, unit=_unit(parsed),
                detail="2: a UUID identifies each message; reusing the command's breaks resend "
                       "detection")]
        return []

    def _feedback_checks(self, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                         time: float | None) -> list[Violation]:
        """EXEC-FB-002: a standard status, a task-specific one this unit declares, or
        look-at-position's; a near miss of a standard status is a typo, anything else may be
        task-specific (12.4 allows those) and is reported with 'task-specific?'."""
        status = message.get("status")
        if not isinstance(status, str) or not status or status in self._statuses:
            return []
        standard = _standard_statuses()
        near = _near_miss(status, standard)
        if near is not None:
            detail = f"a near miss of the standard status '{near}' (12.4): fix the spelling"
        else:
            detail = ("task-specific? 12.4 allows task-specific strings: declare it in the "
                      "profile's task-specific-statuses")
        return [Violation.of(
            "EXEC-FB-002", expected="one of " + " | ".join(standard) + " or a declared "
            "task-specific status", observed=repr(status), topic=parsed.topic, path="$.status",
            time=time, payload=raw, unit=_unit(parsed), detail=detail)]

    def _tst_command_checks(self, parsed: ParsedTopic, message: dict[str, Any], raw: bytes,
                            time: float | None) -> list[Violation] | None:
        """TST-014: a start-tst tree's structure beyond its schema (``conformance.tst``):
        node-uuids used twice, children where only seq and conc have them, a seq or conc
        without children, common_params and common-params that disagree."""
        if message.get("command") != "start-tst" or not isinstance(message.get("tst"), dict):
            return None
        _root, problems = read_tree(message["tst"])
        return [Violation.of(p.rule, expected=p.expected, observed=p.observed,
                             topic=parsed.topic, path=p.path, time=time, payload=raw,
                             unit=_unit(parsed), detail="14.3.4, 11: a fully instantiated tree")
                for p in problems if not p.in_schema] or None

    @cached_property
    def _statuses(self) -> frozenset[str]:
        """Feedback statuses that are no violation: 12.4's standard ones, those of the tasks'
        specification files (look-at-position's in-view...) and the profile's."""
        return (frozenset(_standard_statuses()) | _task_feedback_statuses()
                | frozenset(self.profile.task_specific_statuses))


_CONTENT_CHECKS = {
    TopicKind.HEARTBEAT: Validator._info_checks,
    TopicKind.SENSOR_INFO: Validator._info_checks,
    TopicKind.DIRECT_EXECUTION_INFO: Validator._info_checks,
    TopicKind.TST_EXECUTION_INFO: Validator._info_checks,
    TopicKind.EXEC_RESPONSE: Validator._response_checks,
    TopicKind.TST_RESPONSE: Validator._response_checks,
    TopicKind.EXEC_FEEDBACK: Validator._feedback_checks,
    TopicKind.TST_COMMAND: Validator._tst_command_checks,
}


# --- schema errors -> violations ---------------------------------------------------------------

@cache
def _expects_object(path: str) -> bool:
    return schema.load(path).get("type") == "object"


@lru_cache(maxsize=1)
def _standard_statuses() -> tuple[str, ...]:
    node = schema.load("messages/exec-feedback.json")["properties"]["status"]
    return tuple(node["x-standard-statuses"])


@lru_cache(maxsize=1)
def _task_feedback_statuses() -> frozenset[str]:
    return frozenset(s for t in schema.task_specs() for s in t.feedback_statuses)


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


_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*$")


def json_path(parts: Any) -> str:
    """``$.params.waypoints[2].latitude`` from instance-path parts (names and indices)."""
    out = ["$"]
    for part in parts:
        if isinstance(part, int):
            out.append(f"[{part}]")
        elif _IDENTIFIER.match(part):
            out.append(f".{part}")
        else:
            out.append("[" + orjson.dumps(part).decode() + "]")
    return "".join(out)


def _json_type(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, (int, float)):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    return "object"


def _short(value: Any, limit: int = 80) -> str:
    try:
        text = orjson.dumps(value).decode()
    except (TypeError, orjson.JSONEncodeError):
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _unit(parsed: ParsedTopic) -> str:
    return parsed.unit.base if parsed.unit is not None else ""


def _words(kind: Any, instance: Any, message: str) -> tuple[str, str]:
    """Expected and observed, for a person, from a jsonschema-rs error kind."""
    name = type(kind).__name__
    observed = _short(instance)
    if name == "Required":
        return f"property '{kind.property}'", "missing"
    if name == "Type":
        return " or ".join(kind.types), f"{_json_type(instance)} {observed}"
    if name == "Enum":
        return "one of " + " | ".join(str(o) for o in kind.options), observed
    if name == "Constant":
        return _short(kind.expected_value), observed
    limits = {"Minimum": ">=", "Maximum": "<=", "ExclusiveMinimum": ">",
              "ExclusiveMaximum": "<"}
    if name in limits:
        return f"{limits[name]} {kind.limit}", observed
    if name in ("MinItems", "MaxItems"):
        bound = "at least" if name == "MinItems" else "at most"
        return f"{bound} {kind.limit} items", f"{len(instance)} items"
    if name in ("MinLength", "MaxLength"):
        bound = "at least" if name == "MinLength" else "at most"
        return f"{bound} {kind.limit} characters", observed
    if name == "Pattern":
        return f"a string matching {kind.pattern}", observed
    if name == "UniqueItems":
        return "unique items", observed
    return message, observed


def _schema_violations(path: str, validator: jsonschema_rs.Validator, message: Any, topic: str,
                       raw: bytes, time: float | None, unit: str) -> list[Violation]:
    """Every schema error as a violation of its rule, one per rule and spot."""
    found: dict[tuple[str, str], Violation] = {}
    for error in validator.iter_errors(message):
        notes = schema.rule_annotations(path, tuple(error.evaluation_path))
        rule = notes.rule or "MSG-003"
        kind = error.kind
        spots: list[tuple[list[Any], str, str]]
        if type(kind).__name__ == "AdditionalProperties":
            spots = [([*error.instance_path, key], f"no parameter '{key}'",
                      _short(error.instance.get(key))) for key in kind.unexpected]
        else:
            where = list(error.instance_path)
            if type(kind).__name__ == "Required":
                where.append(kind.property)
            expected, observed = _words(kind, error.instance, error.message)
            spots = [(where, expected, observed)]
        for where, expected, observed in spots:
            spot = json_path(where)
            if (rule, spot) in found:
                continue
            if notes.expected:
                expected = notes.expected
            found[(rule, spot)] = Violation.of(
                rule, expected=expected, observed=observed, topic=topic, path=spot, time=time,
                payload=raw, unit=unit, detail=notes.detail or "")
    return list(found.values())


_default: Validator | None = None


def validate(topic: str, payload: bytes | str, time: float | None = None) -> Validation:
    """Validate one message under the default profile (a shared, reused validator)."""
    global _default
    if _default is None:
        _default = Validator()
    return _default.validate(topic, payload, time)

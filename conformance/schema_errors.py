"""A schema error as a violation, in words a person reads: the rule named by the nearest
``x-rule`` along its evaluation path (``schema.rule_annotations``), the JSON path of the
offending value (``$.task.params.waypoints[2].latitude``), what was expected and what was
observed; one violation per rule and spot. Used by ``conformance/validator.py``, which asks
jsonschema-rs for the errors only when a message is not valid."""

from __future__ import annotations

import re
from functools import cache
from typing import Any

import jsonschema_rs
import orjson
from jsonschema_rs import ValidationErrorKind as _Kind

from conformance import schema
from conformance.violation import Violation


@cache
def expects_object(path: str) -> bool:
    """Whether the schema at ``path`` is an object's (MSG-003 where anything else came)."""
    return schema.load(path).get("type") == "object"


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


def json_type(value: Any) -> str:
    """The JSON type of a decoded value, in JSON's words."""
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


def short(value: Any, limit: int = 80) -> str:
    """A value as compact JSON, cut at ``limit`` characters with an ellipsis."""
    try:
        text = orjson.dumps(value).decode()
    except (TypeError, orjson.JSONEncodeError):
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _words(kind: Any, instance: Any, message: str) -> tuple[str, str]:
    """Expected and observed, for a person, from a jsonschema-rs error kind."""
    name = type(kind).__name__
    observed = short(instance)
    if name == "Required":
        return f"property '{kind.property}'", "missing"
    if name == "Type":
        return " or ".join(kind.types), f"{json_type(instance)} {observed}"
    if name == "Enum":
        return "one of " + " | ".join(str(o) for o in kind.options), observed
    if name == "Constant":
        return short(kind.expected_value), observed
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


def schema_violations(path: str, validator: jsonschema_rs.Validator, message: Any, topic: str,
                       raw: bytes, time: float | None, unit: str) -> list[Violation]:
    """Every schema error as a violation of its rule, one per rule and spot."""
    found: dict[tuple[str, str], Violation] = {}
    for error in validator.iter_errors(message):
        notes = schema.rule_annotations(path, tuple(error.evaluation_path))
        rule = notes.rule or "MSG-003"
        kind = error.kind
        spots: list[tuple[list[Any], str, str]]
        if isinstance(kind, _Kind.AdditionalProperties):
            instance = error.instance if isinstance(error.instance, dict) else {}
            spots = [([*error.instance_path, key], f"no parameter '{key}'",
                      short(instance.get(key))) for key in kind.unexpected]
        else:
            where = list(error.instance_path)
            if isinstance(kind, _Kind.Required):
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
                payload=raw, unit=unit, detail=notes.detail or "", condition=notes.condition)
    return list(found.values())

"""Task parameters for start-task: generated from the task's params schema, seeded, made safe.

Valid parameters are drawn with hypothesis-jsonschema from the JSON Schema of the task
(``conformance.schema``), with a seed so a run can be repeated (``--seed``). Then every GeoPoint
is moved near the unit's own reported position (inside the profile's safe radius), distances
and speeds are bounded, and loops and named positions are left out (DESIGN 'Safety').
Invalid parameters are the valid ones with one parameter of the wrong type.
"""

from __future__ import annotations

import copy
import math
import random
import warnings
from functools import lru_cache
from typing import Any

import orjson

from conformance.scenarios.safety import Position, Safety

# Parameters of section 9 that are distances in metres, bounded to the safe area.
DISTANCE_PARAMS = frozenset({"radius", "distance", "height", "height-above-takeoff",
                             "target-size", "z"})
# 9.14: commanded speeds in m/s: keep them gentle.
SPEED_LIMIT = 5.0
# Flags that would make a task run on forever, or somewhere else than near the unit.
FORCED = {"loop-flag": False, "hold-flag": False, "continue-flag": False,
          "land-at-current-position-flag": True}
DROPPED = frozenset({"named-position", "named-positions", "image-input-ros-topic",
                     "detections-sensor-topic", "salient-points-topic"})
EXAMPLES = 4
MAX_DURATION = 30  # 9.8 observe-position: seconds; the suite ends it with $enough anyway


def task_schema(task: str) -> dict[str, Any] | None:
    """The JSON Schema of ``task``'s params (GeoPoint inlined), or None for a task that is not
    in section 9 (5.3 lets units offer others: they are started with empty params)."""
    from conformance import taskspec

    try:
        return taskspec.params_schema(task)
    except KeyError:
        return None


def task_moves(task: str) -> bool | None:
    """Whether a section-9 task moves the unit (its tags include 'vehicle'); None: unknown."""
    from conformance import taskspec

    try:
        return taskspec.task_spec(task).moves_unit
    except KeyError:
        return None


def draw(schema: dict[str, Any], seed: int) -> Any:
    """One value valid under ``schema``, the same for the same seed (hypothesis-jsonschema);
    a simple walk of the schema when hypothesis-jsonschema cannot handle it."""
    try:
        from hypothesis import HealthCheck, Phase, given, settings
        from hypothesis import seed as hseed
        from hypothesis.errors import NonInteractiveExampleWarning
        from hypothesis_jsonschema import from_schema

        drawn: list[Any] = []

        # The first example hypothesis generates is the simplest; the last of a few is richer.
        @hseed(seed)
        @settings(max_examples=EXAMPLES, database=None, phases=[Phase.generate], deadline=None,
                  suppress_health_check=list(HealthCheck))
        @given(from_schema(schema))
        def _one(value: Any) -> None:
            drawn.append(value)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NonInteractiveExampleWarning)
            _one()
        if drawn:
            return drawn[-1]
        why = "it drew no example"
    except Exception as exc:  # noqa: BLE001 - fall back to the simple walk below, and say so
        why = f"{type(exc).__name__}: {exc}"
    # Said, not silent: the parameters are then plainer than the schema allows.
    warnings.warn(f"hypothesis-jsonschema could not draw from the schema "
                  f"{schema.get('title') or schema.get('$id') or '(untitled)'} ({why}); "
                  f"using a simple walk of the schema instead", RuntimeWarning, stacklevel=2)
    return _walk(schema, random.Random(seed), schema)


def _walk(node: Any, rng: random.Random, root: dict[str, Any], depth: int = 0) -> Any:
    """A small valid value for the common keywords (type, enum, const, properties, items)."""
    if not isinstance(node, dict) or depth > 8:
        return None
    if "$ref" in node and isinstance(node["$ref"], str) and node["$ref"].startswith("#/"):
        target: Any = root
        for part in node["$ref"][2:].split("/"):
            target = target.get(part, {}) if isinstance(target, dict) else {}
        return _walk(target, rng, root, depth + 1)
    if "const" in node:
        return node["const"]
    if "enum" in node and node["enum"]:
        return rng.choice(node["enum"])
    for key in ("allOf", "anyOf", "oneOf"):
        if node.get(key):
            return _walk(node[key][0], rng, root, depth + 1)
    kind = node.get("type")
    if isinstance(kind, list):
        kind = kind[0] if kind else None
    if kind == "object" or "properties" in node:
        props = node.get("properties", {})
        required = set(node.get("required", ()))
        return {k: _walk(v, rng, root, depth + 1) for k, v in sorted(props.items())
                if k in required or rng.random() < 0.7}
    if kind == "array":
        n = max(int(node.get("minItems", 1)), 1)
        return [_walk(node.get("items", {}), rng, root, depth + 1) for _ in range(n)]
    if kind == "boolean":
        return rng.random() < 0.5
    if kind in ("number", "integer"):
        low = node.get("minimum", node.get("exclusiveMinimum", 0))
        high = node.get("maximum", node.get("exclusiveMaximum", low + 10))
        value = rng.uniform(float(low), float(high))
        return int(value) if kind == "integer" else value
    if kind == "string":
        return "waraps-conformance"
    return None


def is_geopoint(value: Any) -> bool:
    return isinstance(value, dict) and "latitude" in value and "longitude" in value


def make_safe(params: Any, origin: Position, safety: Safety, rng: random.Random, *,
              radius: float | None = None) -> Any:
    """``params`` with every GeoPoint near ``origin`` (within ``radius`` metres, at most half
    the safe radius) and distances, speeds, durations and flags bounded (module docstring).
    Pure: returns a new value."""
    limit = min(radius or safety.target_radius(), safety.target_radius())

    def fix(value: Any, key: str = "") -> Any:
        if is_geopoint(value):
            return safety.near(origin, rng, radius).geopoint()
        if isinstance(value, dict):
            out = {}
            for k, v in value.items():
                if k in DROPPED:
                    continue
                out[k] = FORCED[k] if k in FORCED and isinstance(v, bool) else fix(v, k)
            return out
        if isinstance(value, list):
            return [fix(v, key) for v in value]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return value
        if isinstance(value, float) and not math.isfinite(value):
            return 0.0
        if key in DISTANCE_PARAMS:
            return type(value)(min(abs(value), limit))
        if key == "commanded-speed":
            return min(abs(float(value)), SPEED_LIMIT)
        if key == "duration":
            return int(min(value, MAX_DURATION))
        return value

    return fix(copy.deepcopy(params))


# Every GeoPoint is replaced near the unit afterwards: generate a trivial one (generating the
# full GeoPoint schema inside arrays of arrays costs hypothesis-jsonschema seconds per task).
GEOPOINT_STUB: dict[str, Any] = {
    "type": "object", "additionalProperties": False,
    "required": ["latitude", "longitude", "altitude", "rostype"],
    "properties": {"latitude": {"const": 0.0}, "longitude": {"const": 0.0},
                   "altitude": {"const": 0.0}, "rostype": {"const": "GeoPoint"}},
}
TAME_NUMBER = 360
"""The magnitude of a generated number that its schema leaves unbounded."""
WORD = "^[a-z][a-z0-9-]{0,11}$"
"""Free-text parameters get plain words: a real unit should not be sent control characters
because a schema allows any string."""


def for_generation(node: Any) -> Any:
    """A copy of a params schema that generates quickly and tamely: GeoPoints as stubs, free
    strings as words or one of the spec's own examples."""
    if isinstance(node, list):
        return [for_generation(x) for x in node]
    if not isinstance(node, dict):
        return node
    props = node.get("properties")
    if isinstance(props, dict) and "latitude" in props and "longitude" in props:
        return dict(GEOPOINT_STUB)
    out = {k: for_generation(v) for k, v in node.items()
           if k not in ("examples", "description", "$comment")}
    if node.get("type") in ("number", "integer") and not {"enum", "const"} & set(node):
        # Numbers a schema leaves unbounded get the magnitudes of the spec's examples (degrees,
        # counts): conservative in what is sent, a strict unit would refuse 1e19 degrees.
        # (int32 bounds of a typed parameter are no guide either: 9's float64 and int32.)
        low = node.get("minimum", node.get("exclusiveMinimum"))
        high = node.get("maximum", node.get("exclusiveMaximum"))
        tame_low = -TAME_NUMBER if low is None else max(low, -TAME_NUMBER)
        tame_high = TAME_NUMBER if high is None else min(high, TAME_NUMBER)
        if tame_low >= tame_high:  # a range far from zero: its own start, and a little more
            tame_low, tame_high = (low, low + TAME_NUMBER) if low is not None else (
                high - TAME_NUMBER, high)
        if low is None or tame_low != low:
            out.pop("exclusiveMinimum", None)
            out["minimum"] = tame_low if low is None or tame_low > low else low
        if high is None or tame_high != high:
            out.pop("exclusiveMaximum", None)
            out["maximum"] = tame_high if high is None or tame_high < high else high
    if node.get("type") == "string" and not {"enum", "const", "pattern", "format"} & set(node):
        examples = [e for e in node.get("examples") or () if isinstance(e, str)]
        if examples:
            out["enum"] = examples
        else:
            out["pattern"] = WORD
    return out


@lru_cache(maxsize=256)
def drawn(task: str, seed: int) -> bytes:
    """Parameters of ``task`` drawn from its schema with ``seed``, as JSON (cached: a
    certification draws the same ones again; tests warm the cache before a unit runs)."""
    schema = task_schema(task)
    raw = draw(for_generation(schema), seed) if schema else {}
    return orjson.dumps(raw if isinstance(raw, dict) else {})


def valid_params(task: str, origin: Position, safety: Safety, seed: int, *,
                 radius: float | None = None) -> dict[str, Any]:
    """Parameters for ``task``, valid under its schema, safe for the unit at ``origin``;
    positions within ``radius`` metres of it (default: half the profile's safe radius).

    Making them safe can make them invalid (a look-at-position that named another unit's
    position has nothing left to look at): then the spec's own example, made safe, is used.
    """
    params = make_safe(orjson.loads(drawn(task, seed)), origin, safety, random.Random(seed),
                       radius=radius)
    if _is_valid(task, params):
        return params
    schema = task_schema(task) or {}
    for example in schema.get("examples") or ():
        candidate = make_safe(example, origin, safety, random.Random(seed), radius=radius)
        if _is_valid(task, candidate):
            return candidate
    return params


def _is_valid(task: str, params: Any) -> bool:
    """Whether ``params`` is valid under the task's params schema (True: no schema)."""
    from conformance import schema, taskspec

    try:
        return bool(schema.compiled(taskspec.params_schema_path(task)).is_valid(params))
    except KeyError:
        return True


WRONG_TYPE: dict[str, Any] = {
    "number": "not-a-number", "integer": "not-an-integer", "string": {"not": "a string"},
    "boolean": "not-a-boolean", "array": 42, "object": "58.4,15.6",
}


def invalid_params(task: str, origin: Position, safety: Safety, seed: int
                   ) -> tuple[dict[str, Any], str] | None:
    """(params, what is wrong) with one parameter of the wrong type, or None when the task's
    schema names no typed parameter. A GeoPoint parameter is preferred (written as a string:
    a mistake found in practice)."""
    schema = task_schema(task)
    if not schema:
        return None
    props = schema.get("properties") or {}
    required = set(schema.get("required") or ())
    candidates = []
    for name, node in sorted(props.items()):
        kind = _type_of(node, schema)
        if kind in WRONG_TYPE:
            candidates.append((kind != "object", name not in required, name, kind))
    if not candidates:
        return None
    *_, name, kind = min(candidates)
    params = valid_params(task, origin, safety, seed)
    params[name] = WRONG_TYPE[kind]
    return params, f"parameter '{name}' is {WRONG_TYPE[kind]!r} where the schema wants {kind}"


def _type_of(node: Any, root: dict[str, Any], depth: int = 0) -> str | None:
    if not isinstance(node, dict) or depth > 5:
        return None
    ref = node.get("$ref")
    if isinstance(ref, str) and ref.startswith("#/"):
        target: Any = root
        for part in ref[2:].split("/"):
            target = target.get(part, {}) if isinstance(target, dict) else {}
        return _type_of(target, root, depth + 1)
    kind = node.get("type")
    if isinstance(kind, str):
        return kind
    if "properties" in node:
        return "object"
    for part in node.get("allOf") or ():
        if (kind := _type_of(part, root, depth + 1)) is not None:
            return kind
    return None

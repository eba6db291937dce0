"""Task parameters for start-task: never invented (docs/ARCHITECTURE.md 'Safety').

A task is started with the parameters the profile gives it, else, for a section 9 task, with
the parameters of the spec's own example (``schemas/tasks/<task>.yaml``); a task with neither
is not started. Then every GeoPoint is moved near the unit's own reported position (inside the
profile's safe radius, placed with ``--seed`` so a run can be repeated), distances and speeds
are bounded, and loops and named positions are left out. Invalid parameters (EXEC-START-004)
are the valid ones with one parameter of the wrong type.
"""

from __future__ import annotations

import copy
import math
import random
from typing import Any

from conformance import schema, taskspec
from conformance.scenarios.safety import DROPPED, NoParams, Position, Safety, no_params_reason

# Parameters of section 9 that are distances in metres, bounded to the safe area.
DISTANCE_PARAMS = frozenset({"radius", "distance", "height", "height-above-takeoff",
                             "target-size", "z"})
# 9.14: commanded speeds in m/s: keep them gentle.
SPEED_LIMIT = 5.0
# Flags that would make a task run on forever, or somewhere else than near the unit.
FORCED = {"loop-flag": False, "hold-flag": False, "continue-flag": False,
          "land-at-current-position-flag": True}
EXAMPLES = 4
MAX_DURATION = 30  # 9.8 observe-position: seconds; the suite ends it with $enough anyway


def task_schema(task: str) -> dict[str, Any] | None:
    """The JSON Schema of ``task``'s params (GeoPoint inlined), or None for a task that is not
    in section 9 (5.3 lets units offer others: they are started only with the profile's
    parameters)."""
    try:
        return taskspec.params_schema(task)
    except KeyError:
        return None


def task_moves(task: str) -> bool | None:
    """Whether a section-9 task moves the unit (its tags include 'vehicle'); None: unknown."""
    try:
        return taskspec.task_spec(task).moves_unit
    except KeyError:
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


def valid_params(task: str, origin: Position, safety: Safety, seed: int, *,
                 radius: float | None = None) -> dict[str, Any]:
    """Parameters for ``task``, never invented: the profile's for it, else the example of
    the section 9 task (the first valid under its schema once made safe); positions moved
    within ``radius`` metres of ``origin`` (default: half the profile's safe radius) and
    distances, speeds and flags bounded (``make_safe``), with ``seed``. Raises ``NoParams``
    for a task with neither."""
    rng = random.Random(seed)
    given = safety.profile.task_params.get(task)
    if given is not None:
        return make_safe(given, origin, safety, rng, radius=radius)
    examples = [e for e in (task_schema(task) or {}).get("examples") or ()
                if isinstance(e, dict)]
    if not examples:
        raise NoParams(no_params_reason(task))
    made = [make_safe(e, origin, safety, random.Random(seed), radius=radius) for e in examples]
    return next((p for p in made if _is_valid(task, p)), made[0])


def _is_valid(task: str, params: Any) -> bool:
    """Whether ``params`` is valid under the task's params schema (True: no schema)."""
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

"""Profiles: what a unit claims and how to test it safely (its conformance statement plus test
parameters). Built-in profiles live in ``profiles/`` (package ``conformance.profiles``); a user
passes a YAML file of the same form. Every key is checked: a typo is an error naming the key,
the file and the valid keys.
"""

from __future__ import annotations

import difflib
import fnmatch
import json
from dataclasses import dataclass, field, fields
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from conformance.rules import CATALOGUE, Severity

DOCS = "schemas/generated/PROFILE.md"
"""Where the profile format is documented (rendered from the schema)."""


class ProfileError(ValueError):
    """A profile that cannot be used; the message says where and how to fix it."""


@dataclass(frozen=True)
class Profile:
    """A unit's declared conformance statement and the suite's test parameters.

    Times are in seconds, rates in Hz, distances in metres, tolerances as fractions (0.2 = 20 %).
    """

    name: str = "default"
    description: str = ""
    severity: dict[str, str] = field(default_factory=dict)
    """Rule id or glob (``ERR-*``) -> ``error`` | ``warning``: strict turns errata into errors."""
    levels: tuple[str, ...] = ()
    """Levels the unit must declare (empty: whatever it declares is tested)."""
    sensors: tuple[str, ...] = ()
    """Sensors beyond the mandatory four that the unit must publish."""
    tasks: tuple[str, ...] = ()
    """Tasks the suite may start (empty: every task in tasks-available that does not move the
    unit; moving ones only with ``allow_motion``)."""
    motion_tasks: tuple[str, ...] = ()
    """Tasks allowed to move a ``real`` unit, and only with --allow-motion (DESIGN: safety)."""
    safe_radius: float = 50.0
    """Motion targets stay within this distance of the unit's own reported position."""
    rate_tolerance: float = 0.2
    min_intervals: int = 10
    """A rate is judged over at least this many intervals (FIELD-NOTES timing jitter)."""
    max_gap_periods: float = 1.5
    clock_tolerance: float = 30.0
    """How far a message's stamp may be from its arrival time (MSG-005)."""
    response_timeout: float = 5.0
    """Deadline for a response to a command, before --timing-scale."""
    feedback_timeout: float = 30.0
    """Deadline for a started task to reach a final status, before --timing-scale."""
    alive_timeout: float = 0.0
    """Deadline for the first heartbeat; 0 means three declared periods, at least 5 s."""
    reboot_timeout: float = 30.0
    info_wait: float = 30.0
    """How long a declared level may go without its info message before HB-008 fails: at least
    this many seconds (and 3 declared heartbeat periods). Spec 5: info messages may come at a
    lower rate than the heartbeat."""
    task_specific_statuses: tuple[str, ...] = ()
    """Feedback statuses this unit's tasks use beyond 12.4's standard ones (EXEC-FB-002)."""
    strict: bool = False
    """The run adopts this suite's decisions as conventions: a decided rule (the spec is silent
    or contradicts itself) fails instead of warning (``--strict`` sets it too)."""
    source: str = "<built-in>"

    def severity_of(self, rule_id: str) -> Severity:
        """The severity of a rule under this profile (its own, unless overridden)."""
        for pattern, sev in self.severity.items():
            if fnmatch.fnmatchcase(rule_id, pattern):
                return Severity(sev)
        return CATALOGUE[rule_id].severity if rule_id in CATALOGUE else Severity.ERROR

    @property
    def is_strict(self) -> bool:
        return self.strict


_FIELDS = {f.name: f for f in fields(Profile)}
_TUPLE_KEYS = {"levels", "sensors", "tasks", "motion_tasks", "task_specific_statuses"}
_FLOAT_KEYS = {"safe_radius", "rate_tolerance", "max_gap_periods", "clock_tolerance",
               "response_timeout", "feedback_timeout", "alive_timeout", "reboot_timeout",
               "info_wait"}
SCHEMA_FILE = "profile.schema.json"
"""The profile format as a JSON Schema (package ``conformance.profiles``): the one statement of
every key, its type and its meaning; ``load`` checks files against it and the docs
(``schemas/generated/PROFILE.md``) are rendered from it."""


@cache
def schema() -> dict[str, Any]:
    """The JSON Schema of a profile file (keys in their canonical '-' spelling)."""
    return json.loads((resources.files("conformance.profiles") / SCHEMA_FILE).read_text("utf-8"))


def builtin_names() -> list[str]:
    root = resources.files("conformance.profiles")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".yaml"))


def load(name_or_path: str | Path | None) -> Profile:
    """A built-in profile by name (``default``, ``strict``, ...) or a YAML file by path."""
    if name_or_path is None:
        name_or_path = "default"
    text_path = str(name_or_path)
    if text_path in builtin_names():
        source = f"<built-in {text_path}>"
        text = (resources.files("conformance.profiles") / f"{text_path}.yaml").read_text("utf-8")
    else:
        path = Path(text_path)
        if not path.is_file():
            close = difflib.get_close_matches(text_path, builtin_names(), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ProfileError(
                f"profile {text_path!r} is neither a built-in profile ({', '.join(builtin_names())}) "
                f"nor a file{hint}")
        source = str(path)
        text = path.read_text("utf-8")
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as e:
        raise ProfileError(f"{source}: not valid YAML: {e}") from None
    return from_dict(data, source)


def from_dict(data: Any, source: str = "<dict>") -> Profile:
    """Build a profile from parsed YAML, naming every bad key and value."""
    if not isinstance(data, dict):
        raise ProfileError(f"{source}: a profile is a mapping of keys to values, got "
                           f"{type(data).__name__}")
    base: dict[str, Any] = {}
    if "extends" in data:
        parent = load(data["extends"])
        base = {f: getattr(parent, f) for f in _FIELDS if f != "source"}
        base["severity"] = dict(parent.severity)
    kwargs: dict[str, Any] = dict(base)
    properties = schema()["properties"]
    for key, value in data.items():
        if key == "extends":
            continue
        canonical = str(key).replace("_", "-")
        if canonical not in properties:
            close = difflib.get_close_matches(canonical, list(properties), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ProfileError(f"{source}: unknown key {key!r}{hint}; valid keys: "
                               f"{', '.join(properties)} (see {DOCS})")
        _check(canonical, value, properties[canonical], source)
        attr = canonical.replace("-", "_")
        kwargs[attr] = _coerce(attr, value, source)
    if "severity" in data:
        kwargs["severity"] = {**base.get("severity", {}), **kwargs["severity"]}
    kwargs["source"] = source
    return Profile(**kwargs)


def _check(key: str, value: Any, prop: dict[str, Any], source: str) -> None:
    """Raise ProfileError when ``value`` does not fit the schema of ``key``, saying what the
    key takes (from the schema) and, for a word out of a closed set, the nearest one."""
    from jsonschema import Draft202012Validator  # only when a profile is read (cheap plugin)

    error = next(iter(Draft202012Validator(prop).iter_errors(value)), None)
    if error is None:
        return
    if error.validator == "enum":
        choices = [str(c) for c in error.validator_value]
        close = difflib.get_close_matches(str(error.instance), choices, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        where = "".join(f"[{p!r}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path)
        raise ProfileError(f"{source}: {key}{where}: {error.instance!r} is not one of "
                           f"{', '.join(map(repr, choices))}{hint}")
    raise ProfileError(f"{source}: {key} must be {describe(prop)}, got {value!r}")


def describe(prop: dict[str, Any]) -> str:
    """What a profile key takes, in words (its schema's type and bounds)."""
    kind = prop.get("type")
    if kind == "number":
        return "a non-negative number" if prop.get("minimum") == 0 else "a number"
    if kind == "integer":
        low = prop.get("minimum")
        return f"a whole number >= {low}" if low is not None else "a whole number"
    if kind == "array":
        items = prop.get("items", {})
        if "enum" in items:
            return "a list of " + ", ".join(map(repr, items["enum"]))
        return "a list of strings"
    if kind == "boolean":
        return "true or false"
    if kind == "object":
        return "a mapping of rule ids (or globs like ERR-*) to error|warning"
    return "a string"


def _coerce(attr: str, value: Any, source: str) -> Any:
    where = f"{source}: {attr.replace('_', '-')}"
    if attr in _TUPLE_KEYS:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ProfileError(f"{where} must be a list of strings, got {value!r}")
        return tuple(value)
    if attr in _FLOAT_KEYS:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise ProfileError(f"{where} must be a non-negative number, got {value!r}")
        return float(value)
    if attr == "strict":
        if not isinstance(value, bool):
            raise ProfileError(f"{where} must be true or false, got {value!r}")
        return value
    if attr == "min_intervals":
        if isinstance(value, bool) or not isinstance(value, int) or value < 2:
            raise ProfileError(f"{where} must be a whole number >= 2, got {value!r}")
        return value
    if attr == "severity":
        if not isinstance(value, dict):
            raise ProfileError(f"{where} must map rule ids (or globs like ERR-*) to error|warning")
        out = {}
        for pattern, sev in value.items():
            if sev not in ("error", "warning"):
                raise ProfileError(f"{where}.{pattern}: {sev!r} is not error or warning")
            if not any(fnmatch.fnmatchcase(r, str(pattern)) for r in CATALOGUE):
                close = difflib.get_close_matches(str(pattern), CATALOGUE, n=1)
                hint = f" (did you mean {close[0]}?)" if close else ""
                raise ProfileError(f"{where}: {pattern!r} matches no rule id{hint}")
            out[str(pattern)] = sev
        return out
    if not isinstance(value, str):
        raise ProfileError(f"{where} must be a string, got {value!r}")
    return value


def markdown() -> str:
    """The profile format as a page (``schemas/generated/PROFILE.md``), rendered from the
    schema so that the documentation cannot drift from what ``load`` accepts."""
    s = schema()
    lines = ["# Profile files", "", "<!-- generated from profiles/profile.schema.json by "
             "`waraps-conformance schemas generate`; do not edit -->", "", s["description"], "",
             "Pass one with `pytest --unit ADDRESS --profile my-unit.yaml` (or `lint --profile`); "
             "`waraps-conformance profile --unit ADDRESS -o my-unit.yaml` writes a starting one "
             "from what the unit declares and publishes. Commented examples per kind of unit: "
             "`docs/profiles/`. Built-in profiles: " + ", ".join(f"`{n}`" for n in builtin_names())
             + ".", "", "| key | takes | default | meaning |", "|---|---|---|---|"]
    for key, prop in s["properties"].items():
        default = json.dumps(prop["default"]) if "default" in prop else "-"
        meaning = prop["description"].replace("|", "\\|")
        takes = describe(prop).replace("|", "\\|")
        lines.append(f"| `{key}` | {takes} | `{default}` | {meaning} |")
    return "\n".join(lines) + "\n"

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

from conformance import profile_yaml
from conformance.display import printable, shorten
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
    task_params: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Task name -> the parameters to start it with (the profile's ``tasks`` as a mapping)."""
    task_scenarios: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """Task name -> the scenarios that may start it (absent: every scenario)."""
    task_feedback_timeouts: dict[str, float] = field(default_factory=dict)
    """Task name -> its own feedback deadline in seconds, before --timing-scale (absent: the
    profile's ``feedback_timeout``): how long it may take to end on its own, or to send the
    final status a signal implies (a unit moving at its real speed)."""
    motion_tasks: tuple[str, ...] = ()
    """Tasks allowed to move a real unit, and only with --allow-motion (docs/ARCHITECTURE.md
    'Safety')."""
    simulated_roles: tuple[str, ...] = ()
    """Roles besides ``simulation`` that are simulations; every other role is real
    (docs/ARCHITECTURE.md 'Safety': fail closed)."""
    robustness: bool = False
    """Hostile and malformed payloads may be sent to a real unit (as --allow-hostile)."""
    safe_radius: float = 50.0
    """Motion targets stay within this distance of the unit's own reported position."""
    rate_tolerance: float = 0.2
    min_intervals: int = 10
    """A rate is judged over at least this many intervals (docs/FIELD-NOTES.md 'Timing jitter')."""
    max_gap_periods: float = 1.5
    clock_tolerance: float = 30.0
    """How far a message's stamp may be from its arrival time (MSG-005)."""
    response_timeout: float = 5.0
    """Deadline for a response to a command, before --timing-scale."""
    feedback_timeout: float = 30.0
    """Deadline for a started task to reach a final status, before --timing-scale."""
    alive_timeout: float = 0.0
    """Deadline for the first heartbeat; 0 means 5 s (``Certification.alive_timeout``)."""
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

    def is_simulation(self, role: str) -> bool:
        """Whether a unit of ``role`` (3.1) is a simulation: ``simulation`` or one of the
        ``simulated_roles``; every other role, known or not, is real (docs/ARCHITECTURE.md
        'Safety')."""
        return role == "simulation" or role in self.simulated_roles

    @property
    def is_strict(self) -> bool:
        return self.strict

    def adopts(self, rule_id: str) -> bool:
        """Whether a decided rule fails under this profile: a strict profile adopts every
        decision, and ``severity: {RULE: error}`` adopts that rule's (the arena's own words)."""
        if self.strict:
            return True
        for pattern, sev in self.severity.items():
            if fnmatch.fnmatchcase(rule_id, pattern):
                return sev == Severity.ERROR.value
        return False


_FIELDS = {f.name: f for f in fields(Profile)}
_TUPLE_KEYS = {"levels", "sensors", "motion_tasks", "task_specific_statuses",
               "simulated_roles"}
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


MAX_EXTENDS = 8
"""How many profiles an ``extends`` chain may hold (the built-ins need 3)."""


def load(name_or_path: str | Path | None, _chain: tuple[str, ...] = ()) -> Profile:
    """A built-in profile by name (``default``, ``strict``, ...) or a YAML file by path, read
    as a YAML subset (``profile_yaml``: no anchors, aliases or tags, bounded size and depth,
    finite numbers, UTF-8); an ``extends`` cycle is refused with its chain."""
    if name_or_path is None:
        name_or_path = "default"
    text_path = str(name_or_path)
    if text_path in builtin_names():
        source = key = f"<built-in {text_path}>"
        data = (resources.files("conformance.profiles") / f"{text_path}.yaml").read_bytes()
    else:
        path = Path(text_path)
        if not path.is_file():
            close = difflib.get_close_matches(text_path, builtin_names(), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ProfileError(
                f"profile {text_path!r} is neither a built-in profile ({', '.join(builtin_names())}) "
                f"nor a file{hint}")
        source, key = str(path), str(path.resolve())
        with path.open("rb") as f:
            data = f.read(profile_yaml.MAX_BYTES + 1)
    chain = (*_chain, key)
    if key in _chain or len(chain) > MAX_EXTENDS:
        shown = " -> ".join(chain)
        why = "extends itself" if key in _chain else f"extends more than {MAX_EXTENDS} deep"
        raise ProfileError(f"{source}: the profile {why} ({shown}); remove an extends")
    try:
        parsed = profile_yaml.read(profile_yaml.decode(data)) or {}
    except profile_yaml.YamlRefused as e:
        raise ProfileError(f"{source}: {e}") from None
    except yaml.YAMLError as e:
        raise ProfileError(f"{source}: not valid YAML: {' '.join(str(e).split())}") from None
    return from_dict(parsed, source, _chain=chain)


def from_dict(data: Any, source: str = "<dict>", *, _chain: tuple[str, ...] = ()) -> Profile:
    """Build a profile from parsed YAML, naming every bad key and value."""
    if not isinstance(data, dict):
        raise ProfileError(f"{source}: a profile is a mapping of keys to values, got "
                           f"{type(data).__name__}")
    base: dict[str, Any] = {}
    if "extends" in data:
        if not isinstance(data["extends"], str):
            raise ProfileError(f"{source}: extends must be a built-in profile's name or a "
                               f"file, got {data['extends']!r}")
        parent = load(data["extends"], _chain)
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
            raise ProfileError(f"{source}: unknown key {printable(shorten(repr(key), 80))}{hint}; "
                               f"valid keys: {', '.join(properties)} (see {DOCS})")
        if canonical == "tasks" and value is None:
            value = {}  # 'tasks:' with every entry still commented out (a fresh draft)
        _check(canonical, value, properties[canonical], source)
        attr = canonical.replace("-", "_")
        if attr == "tasks":
            kwargs.update(_tasks(value))
            continue
        kwargs[attr] = _coerce(attr, value, source)
    if "severity" in data:
        kwargs["severity"] = {**base.get("severity", {}), **kwargs["severity"]}
    kwargs["source"] = source
    return Profile(**kwargs)


def downgrades(profile: Profile) -> str:
    """The profile's ``severity`` entries that turn rules the catalogue makes errors into
    warnings, as ``'*': warning (95 rules)``; "" when there are none. A run header says it:
    a downgrade (forged or not) is never silent."""
    out = []
    for pattern, sev in profile.severity.items():
        if sev != "warning":
            continue
        hit = [r for r, rule in CATALOGUE.items() if fnmatch.fnmatchcase(r, pattern)
               and rule.severity is Severity.ERROR]
        if hit:
            out.append(f"{pattern!r}: warning ({len(hit)} rule{'s' if len(hit) != 1 else ''})")
    return ", ".join(out)


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
    if "x-takes" in prop:
        return str(prop["x-takes"])
    kind = prop.get("type")
    if kind == "boolean":
        return "true or false"
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
    if kind == "object":
        return "a mapping of rule ids (or globs like ERR-*) to error|warning"
    return "a string"


def _tasks(value: Any) -> dict[str, Any]:
    """``tasks`` (checked against the schema already): a list of names, or a mapping of names
    to ``{params, scenarios, feedback-timeout}``, as the Profile's ``tasks``, ``task_params``,
    ``task_scenarios``, ``task_feedback_timeouts``."""
    if isinstance(value, list):
        return {"tasks": tuple(value), "task_params": {}, "task_scenarios": {},
                "task_feedback_timeouts": {}}
    params = {str(k): v["params"] for k, v in value.items() if v and "params" in v}
    scenarios = {str(k): tuple(v["scenarios"]) for k, v in value.items()
                 if v and "scenarios" in v}
    timeouts = {str(k): float(v["feedback-timeout"]) for k, v in value.items()
                if v and "feedback-timeout" in v}
    return {"tasks": tuple(str(k) for k in value), "task_params": params,
            "task_scenarios": scenarios, "task_feedback_timeouts": timeouts}


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
    if attr in ("robustness", "strict"):
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

"""The task specification files of spec section 9 (``schemas/tasks/*.yaml``), read and checked."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import yaml

from conformance.schema import PACKAGE, SchemaError, files, inline_refs, load

# The spec's parameter types (section 9); specgen gives each its JSON Schema (GeoPoint by $ref).
SPEC_TYPES = ("string", "strings", "bool", "int32", "float64", "float64s", "geopoint",
              "geopoints", "geopointarrays")

_TASK_KEYS = {"name", "section", "group", "description", "spec-tags", "tags", "tags-why",
              "required", "required-why", "requires-one-of", "required-unless",
              "feedback-statuses", "parameters", "aliases", "example"}
_PARAM_KEYS = {"type", "description", "enum", "item-enum", "minimum", "maximum",
               "exclusive-minimum", "item-minimum", "min-items", "max-items", "item-min-items",
               "examples", "default", "constraint-why", "erratum"}
_NAME = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")


@dataclass(frozen=True)
class Parameter:
    """One task parameter: its spec type (``float64``, ``geopoints``, ...), the prose, and the
    constraints the prose states (JSON-Schema-like keys from the task file)."""

    name: str
    type: str
    description: str
    required: bool
    constraints: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TaskSpec:
    """A task of spec section 9 as its specification file states it.

    ``tags`` are the suite's tags: ``vehicle`` means the task moves the unit (docs/ARCHITECTURE.md
    'Safety'), also where the spec gives no tag (``spec_tags`` keeps the spec's own, and the file
    says why they differ).
    """

    name: str
    section: str
    group: str
    description: str
    tags: tuple[str, ...]
    spec_tags: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    required: tuple[str, ...]
    required_why: str
    feedback_statuses: tuple[str, ...]
    example: dict[str, Any]
    raw: dict[str, Any] = field(repr=False, compare=False, default_factory=dict)

    @property
    def moves_unit(self) -> bool:
        """Whether starting this task may move the unit (tag ``vehicle``)."""
        return "vehicle" in self.tags

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"task {self.name!r} has no parameter {name!r}; it has "
                       f"{', '.join(p.name for p in self.parameters)}")


def parse_task(data: Any, source: str) -> TaskSpec:
    """A task specification from a parsed YAML file; every key is checked (typos name the file)."""

    def bad(msg: str) -> SchemaError:
        return SchemaError(f"{source}: {msg}")

    if not isinstance(data, dict):
        raise bad("a task specification is a mapping")
    unknown = set(data) - _TASK_KEYS
    if unknown:
        raise bad(f"unknown keys {sorted(unknown)}; valid: {sorted(_TASK_KEYS)}")
    for key in ("name", "section", "group", "description", "required-why", "parameters"):
        if key not in data:
            raise bad(f"missing key {key!r}")
    name = data["name"]
    if not isinstance(name, str) or not _NAME.match(name):
        raise bad(f"name {name!r} is not a lowercase-hyphenated task name")
    if data["group"] not in ("general", "vehicle-specific"):
        raise bad(f"group {data['group']!r} is not general or vehicle-specific")
    params_in = data["parameters"] or {}
    required = tuple(data.get("required") or ())
    _check_requirements(data, params_in, required, bad)
    params = [_parameter(pname, p, pname in required, bad) for pname, p in params_in.items()]
    for alias, a in (data.get("aliases") or {}).items():
        if a.get("canonical") not in params_in or not str(a.get("rule", "")).startswith("ERR-"):
            raise bad(f"alias {alias!r} needs canonical (a parameter) and rule (an ERR-* id)")
    return TaskSpec(
        name=name, section=str(data["section"]), group=data["group"],
        description=" ".join(data["description"].split()),
        tags=tuple(data.get("tags") or ()), spec_tags=tuple(data.get("spec-tags") or ()),
        parameters=tuple(params), required=required,
        required_why=" ".join(data["required-why"].split()),
        feedback_statuses=tuple(data.get("feedback-statuses") or ()),
        example=dict(data.get("example") or {}), raw=data)


def _check_requirements(data: dict[str, Any], params_in: dict[str, Any],
                        required: tuple[str, ...], bad: Callable[[str], SchemaError]) -> None:
    """Every parameter named by ``required``, ``requires-one-of`` and ``required-unless`` is
    one of the task's."""
    for r in required:
        if r not in params_in:
            raise bad(f"required parameter {r!r} is not among the parameters")
    for group in data.get("requires-one-of") or ():
        for r in group:
            if r not in params_in:
                raise bad(f"requires-one-of names {r!r}, not a parameter")
    for r, cond in (data.get("required-unless") or {}).items():
        if r not in params_in or not all(k in params_in for k in cond):
            raise bad(f"required-unless {r!r}: {cond!r} names an unknown parameter")


def _parameter(pname: str, p: Any, required: bool,
               bad: Callable[[str], SchemaError]) -> Parameter:
    """One parameter of a task file, its keys checked (spec 9's types)."""
    if not isinstance(p, dict):
        raise bad(f"parameter {pname!r} must be a mapping")
    unknown = set(p) - _PARAM_KEYS
    if unknown:
        raise bad(f"parameter {pname!r}: unknown keys {sorted(unknown)}; valid: "
                  f"{sorted(_PARAM_KEYS)}")
    if p.get("type") not in SPEC_TYPES:
        raise bad(f"parameter {pname!r}: type {p.get('type')!r} is not one of "
                  f"{', '.join(SPEC_TYPES)} (spec 9)")
    if not p.get("description"):
        raise bad(f"parameter {pname!r} has no description")
    constraints = {k: v for k, v in p.items() if k not in ("type", "description")}
    return Parameter(pname, p["type"], " ".join(p["description"].split()), required,
                     constraints)


@lru_cache(maxsize=1)
def _task_specs() -> tuple[TaskSpec, ...]:
    specs = []
    for name, data in files().items():
        if name.startswith("tasks/") and name.endswith(".yaml"):
            spec = parse_task(yaml.safe_load(data), f"{PACKAGE}/{name}")
            if name != f"tasks/{spec.name}.yaml":
                raise SchemaError(f"{PACKAGE}/{name}: file name does not match task name "
                                  f"{spec.name!r}")
            specs.append(spec)
    return tuple(sorted(specs, key=lambda s: s.name))


def task_specs() -> list[TaskSpec]:
    """Every task of section 9, sorted by name."""
    return list(_task_specs())


def task_names() -> list[str]:
    return [s.name for s in _task_specs()]


def task_spec(name: str) -> TaskSpec:
    """The task called ``name``; KeyError names close matches."""
    for spec in _task_specs():
        if spec.name == name:
            return spec
    import difflib

    close = difflib.get_close_matches(name, task_names(), n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    raise KeyError(f"no task {name!r} in section 9{hint}")


def params_schema_path(task: str) -> str:
    task_spec(task)  # a KeyError with hints for an unknown name
    return f"generated/params/{task}.json"


def params_schema(task: str, *, bundled: bool = True) -> dict[str, Any]:
    """The JSON Schema (Draft 2020-12) of a task's ``params``.

    ``bundled`` (default) returns a self-contained copy with the GeoPoint inlined (no
    ``$ref``), ready for hypothesis-jsonschema or any validator; otherwise the file as shipped.
    """
    schema = load(params_schema_path(task))
    return inline_refs(schema) if bundled else schema

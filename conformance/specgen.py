"""The schema generator: task specification files -> JSON Schemas (Draft 2020-12) and task docs.

    waraps-conformance schemas generate [--out DIR] [--check]

From ``schemas/tasks/*.yaml`` it writes ``schemas/generated/``: ``geopoint.json`` (the GeoPoint
shared by all), ``params/<task>.json`` (one per task), ``start-task.json`` (the exec command,
12.2.3) and ``start-tst.json`` (the TST command with its recursive ``children``, 14.3.4), which
pick a task's params schema by task name with ``if``/``then`` (not ``oneOf``:
docs/FIELD-NOTES.md 'Validation cost', so
every validator reports the exact failing field), and ``TASKS.md``. Output is deterministic:
sorted keys, indent 2, a final newline. The output is committed; a test regenerates it into a
temporary folder and fails when the committed copy is stale.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

from conformance import profile
from conformance.schema import BASE_URI, PACKAGE
from conformance.taskspec import Parameter, TaskSpec, task_specs
from conformance.tst import COMPOSITES

DRAFT = "https://json-schema.org/draft/2020-12/schema"
GENERATED = "generated"
COMMON = "../messages/common.json"
GEOPOINT_REF = "geopoint.json"

_LIST_TYPES = ("strings", "float64s", "geopoints", "geopointarrays")
INT32 = {"minimum": -(2**31), "maximum": 2**31 - 1}

# Constraint keys of a task file and the JSON Schema keyword each becomes.
_DIRECT = {"enum": "enum", "minimum": "minimum", "maximum": "maximum",
           "exclusive-minimum": "exclusiveMinimum", "min-items": "minItems",
           "max-items": "maxItems", "examples": "examples", "default": "default"}
_ITEM = {"item-enum": "enum", "item-minimum": "minimum", "item-min-items": "minItems"}


def dumps(obj: Any) -> str:
    """The one serialisation of generated JSON: sorted keys, indent 2, final newline."""
    return json.dumps(obj, indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def geopoint_schema() -> dict[str, Any]:
    """GeoPoint (6.1 geographic_msgs/GeoPoint): degrees WGS 84 and metres; tagged rostype in
    task parameters, as every example of sections 10 and 11 is. ``$defs/untagged`` is the
    GeoPoint without that tag requirement: sensor/position's (6.1 says only 'GeoPoint' and
    has no example, so no tag is asked of it)."""
    untagged = {
        "type": "object",
        "required": ["altitude", "latitude", "longitude"],
        "properties": {
            "latitude": {"type": "number", "minimum": -90, "maximum": 90,
                         "description": "degrees north, -90..90"},
            "longitude": {"type": "number", "minimum": -180, "maximum": 180,
                          "description": "degrees east, -180..180"},
            "altitude": {"type": "number", "description": "metres"},
            "rostype": {"const": "GeoPoint"},
            "type": {"const": "GeoPoint"},
        },
    }
    return {
        "$schema": DRAFT,
        "$id": BASE_URI + f"{GENERATED}/geopoint.json",
        "title": "GeoPoint",
        "description": "A position (spec 6.1: geographic_msgs/GeoPoint): latitude and longitude "
                       "in degrees (WGS 84), altitude in metres. Every example of the spec "
                       "(task parameters, sections 10 and 11) tags it \"rostype\": "
                       "\"GeoPoint\"; there a 'type' tag or no tag is an erratum reading "
                       "(ERR-010), a tag with another value is an error. sensor/position (6.1, "
                       "no example) uses $defs/untagged: no tag is asked of it.",
        **untagged,
        "allOf": [{
            "x-rule": "ERR-010",
            "x-expected": "a GeoPoint tagged \"rostype\": \"GeoPoint\"",
            "x-detail": "every spec example of a task's GeoPoint tags rostype; 'type' or no "
                        "tag is accepted with a warning (strict: fail)",
            "required": ["rostype"],
        }],
        "$defs": {"untagged": untagged},
    }


def _type_schema(spec_type: str, ref: str) -> dict[str, Any]:
    """The JSON Schema of a spec type (section 9); ``ref`` is the GeoPoint's relative URI."""
    geopoint = {"$ref": ref}
    schemas: dict[str, dict[str, Any]] = {
        "string": {"type": "string"},
        "strings": {"type": "array", "items": {"type": "string"}},
        "bool": {"type": "boolean"},
        "int32": {"type": "integer", **INT32},
        "float64": {"type": "number"},
        "float64s": {"type": "array", "items": {"type": "number"}},
        "geopoint": geopoint,
        "geopoints": {"type": "array", "items": geopoint},
        "geopointarrays": {"type": "array", "items": {"type": "array", "items": geopoint}},
    }
    return schemas[spec_type]


def _constrained(spec_type: str, constraints: dict[str, Any], ref: str) -> dict[str, Any]:
    schema = _type_schema(spec_type, ref)
    for key, keyword in _DIRECT.items():
        if key in constraints:
            schema[keyword] = constraints[key]
    for key, keyword in _ITEM.items():
        if key in constraints:
            schema["items"] = {**schema["items"], keyword: constraints[key]}
    return schema


def parameter_schema(task: TaskSpec, p: Parameter, ref: str = "../" + GEOPOINT_REF) -> dict:
    """The schema of one parameter, with its erratum reading (if any) told apart by if/then."""
    schema = _constrained(p.type, p.constraints, ref)
    erratum = p.constraints.get("erratum")
    if erratum:
        if schema.get("type") == "array" or erratum.get("type") not in _LIST_TYPES:
            raise ValueError(f"{task.name}.{p.name}: an erratum reading must be a list form of "
                             f"a non-list parameter")
        reading = _constrained(erratum["type"], {k: v for k, v in erratum.items()
                                                 if k not in ("rule", "reading", "type")}, ref)
        schema = {
            "if": {"type": "array"},
            "then": {"allOf": [{
                "x-rule": erratum["rule"],
                "x-expected": f"a {p.type} as spec {task.section} types it, not a list",
                "x-detail": f"{erratum['reading']}; accepted with a warning (strict: fail)",
                "not": {},
            }, reading]},
            "else": schema,
        }
    schema["description"] = p.description
    if "constraint-why" in p.constraints:
        schema["$comment"] = " ".join(str(p.constraints["constraint-why"]).split())
    return schema


def params_schema(task: TaskSpec) -> dict[str, Any]:
    """The JSON Schema of a task's ``params`` (errors: TASK-001, unknown parameter TASK-003)."""
    raw = task.raw
    properties = {p.name: parameter_schema(task, p) for p in task.parameters}
    for alias, a in (raw.get("aliases") or {}).items():
        canonical = task.parameter(a["canonical"])
        properties[alias] = {"allOf": [{
            "x-rule": a["rule"],
            "x-expected": f"parameter '{canonical.name}' (spec {task.section})",
            "x-detail": f"{' '.join(a['reading'].split())}; accepted with a warning "
                        f"(strict: fail)",
            "not": {},
        }, _constrained(canonical.type, canonical.constraints, "../" + GEOPOINT_REF)]}
    schema: dict[str, Any] = {
        "$schema": DRAFT,
        "$id": BASE_URI + f"{GENERATED}/params/{task.name}.json",
        "title": f"{task.name} parameters (spec {task.section})",
        "description": task.description,
        "x-rule": "TASK-001",
        "x-tags": list(task.tags),
        "x-spec-tags": list(task.spec_tags),
        "x-required-why": task.required_why,
        "type": "object",
        "properties": properties,
        "required": list(task.required),
        "allOf": _params_constraints(task, properties),
    }
    if task.example:
        schema["examples"] = [task.example]
    if task.feedback_statuses:
        schema["x-feedback-statuses"] = list(task.feedback_statuses)
    return schema


def _params_constraints(task: TaskSpec, properties: dict[str, Any]) -> list[dict[str, Any]]:
    """What a task's params must hold beyond each parameter: only its parameters (TASK-003),
    one of each ``requires-one-of`` group, each ``required-unless`` parameter."""
    raw = task.raw
    names = [p.name for p in task.parameters]
    all_of: list[dict[str, Any]] = [{
        "x-rule": "TASK-003",
        "x-expected": f"only the parameters of {task.section}: {', '.join(names)}",
        "properties": {name: True for name in properties},
        "additionalProperties": False,
    }]
    for group in raw.get("requires-one-of") or ():
        all_of.append({
            "x-expected": f"one of the parameters {' or '.join(group)}",
            "anyOf": [{"required": [name]} for name in group],
        })
    for name, condition in (raw.get("required-unless") or {}).items():
        all_of.append({
            "x-expected": f"parameter '{name}' unless "
                          + " and ".join(f"{k} is {json.dumps(v)}" for k, v in condition.items()),
            "if": {"required": sorted(condition),
                   "properties": {k: {"const": v} for k, v in condition.items()}},
            "else": {"required": [name]},
        })
    return all_of


def _dispatch_by_name(specs: list[TaskSpec], generic_params: dict[str, Any]) -> list[dict]:
    """if/then per task name (docs/FIELD-NOTES.md 'Validation cost': not oneOf), and the generic
    params check otherwise."""
    names = [s.name for s in specs]
    out: list[dict[str, Any]] = [{
        "if": {"required": ["name"], "properties": {"name": {"const": s.name}}},
        "then": {"required": ["params"],
                 "properties": {"params": {"$ref": f"params/{s.name}.json"}}},
    } for s in specs]
    out.append({
        "if": {"required": ["name"], "properties": {"name": {"enum": names}}},
        "else": {"properties": {"params": generic_params}},
    })
    return out


def start_task_schema(specs: list[TaskSpec]) -> dict[str, Any]:
    """start-task (12.2.3, examples 10.1): the task's params schema chosen by task name."""
    names = [s.name for s in specs]
    return _command_schema("start-task", {
            "sender": {"type": "string"},
            "execution-unit": {"type": "string"},
            "task-uuid": {"$ref": f"{COMMON}#/$defs/task-uuid"},
            "task": {"$ref": "#/$defs/task"},
        }, {
            "task": {
                "type": "object",
                "required": ["name", "params"],
                "properties": {
                    "name": {"type": "string", "allOf": [{
                        "x-rule": "TASK-002",
                        "x-expected": "a task of section 9: " + ", ".join(names),
                        "x-detail": "a unit may offer other tasks (5.3); their parameters are "
                                    "not checked",
                        "enum": names,
                    }]},
                },
                "allOf": _dispatch_by_name(specs, {"type": "object"}),
            },
        })


_STARTS = {
    # command: (the field it starts, where the spec says so, its rule, the description)
    "start-task": ("task", "spec 12.2.3, examples 10.1", "EXEC-001",
                   "Starts a task of section 9 on the unit. task-uuid is optional (12.1: a "
                   "generated one is returned when absent). execution-unit and sender appear "
                   "in every example but no prose requires them."),
    "start-tst": ("tst", "spec 14.3.4, examples 11", "TST-001",
                  "Starts a fully instantiated TST tree. Each node names a task of section 9 "
                  "(its params are checked against the task's schema) or a composite node, seq "
                  "or conc (TST-010), and lists its children; the tree is recursive. Its "
                  "structure beyond a schema (unique node-uuids, children only under seq and "
                  "conc) is conformance.tst's (TST-014)."),
}


def _command_schema(command: str, properties: dict[str, Any],
                    defs: dict[str, Any]) -> dict[str, Any]:
    """The schema of a command that starts something (``_STARTS``): its com-uuid, its
    ``command`` const and the field it starts (required), with its other ``properties`` and
    ``defs``."""
    field, where, rule, description = _STARTS[command]
    return {
        "$schema": DRAFT,
        "$id": BASE_URI + f"{GENERATED}/{command}.json",
        "title": f"{command} command ({where})",
        "description": description,
        "x-rule": rule,
        "type": "object",
        "required": ["com-uuid", "command", field],
        "properties": {
            "com-uuid": {"$ref": f"{COMMON}#/$defs/com-uuid"},
            "command": {"const": command},
            **properties,
        },
        "$defs": defs,
    }


def _common_params_schema() -> dict[str, Any]:
    """A TST node's common parameters (11): the executing unit and the node's uuid."""
    return {
        "type": "object",
        "description": "The node's common parameters (11): the executing unit and the node's "
                       "uuid (14.3.4: best set, at least for the top node).",
        "properties": {
            "execunit": {"type": "string", "allOf": [{
                "x-rule": "ERR-017",
                "x-expected": "'/NAME' (11's execunit '/op0', 14.3.3's '/dji21')",
                "x-detail": "a bare unit name is accepted with a warning (strict: fail)",
                "pattern": "^/",
            }]},
            "node-uuid": {"$ref": f"{COMMON}#/$defs/node-uuid"},
        },
    }


def _node_name_schema(names: list[str]) -> dict[str, Any]:
    """A TST node's name: seq, conc or a task of section 9 (TASK-002), never 11.1.1's
    look-at-angle (ERR-005)."""
    return {
        "type": "string",
        # A prohibition is a node of its own, applied to every name, so that
        # its rule is examined (and passes) on every other name too.
        "allOf": [{
            "x-rule": "ERR-005",
            "x-expected": "a task of section 9 (look-at-bearing is the closest)",
            "x-detail": "11.1.1's look-at-angle with pan parameters is not a "
                        "task of section 9; its params are not checked",
            "not": {"const": "look-at-angle"},
        }],
        "if": {"const": "look-at-angle"},
        "else": {
            "x-rule": "TASK-002",
            "x-expected": "seq, conc or a task of section 9: " + ", ".join(names),
            "x-detail": "a unit may offer other tasks (5.3); their parameters "
                        "are not checked",
            "enum": list(COMPOSITES) + names,
        },
    }


def start_tst_schema(specs: list[TaskSpec]) -> dict[str, Any]:
    """start-tst (14.3.4, examples 11): a TST tree of nodes with recursive ``children``."""
    return _command_schema("start-tst", {
            "receiver": {"type": "string"},
            "sender": {"type": "string"},
            "tst": {"$ref": "#/$defs/node"},
        }, {
            "common_params": _common_params_schema(),
            "node": {
                "type": "object",
                "required": ["name"],
                "properties": {
                    "name": _node_name_schema([s.name for s in specs]),
                    "children": {"type": "array", "items": {"$ref": "#/$defs/node"}},
                    "common_params": {"$ref": "#/$defs/common_params"},
                    "common-params": {"allOf": [{"$ref": "#/$defs/common_params"}, {
                        "x-rule": "ERR-009",
                        "x-expected": "common_params (as every example of 11 writes it)",
                        "x-detail": "'common-params' is accepted with a warning (strict: fail)",
                        "not": {},
                    }]},
                },
                "allOf": _dispatch_by_name(specs, {"type": "object"}),
            },
        })


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _constraint_text(p: Parameter) -> str:
    c = p.constraints
    parts = []
    if "enum" in c:
        parts.append("one of " + ", ".join(f"`{v}`" for v in c["enum"]))
    if "item-enum" in c:
        parts.append("each one of " + ", ".join(f"`{v}`" for v in c["item-enum"]))
    for key, word in (("minimum", ">="), ("exclusive-minimum", ">"), ("maximum", "<="),
                      ("item-minimum", "each >=")):
        if key in c:
            parts.append(f"{word} {c[key]}")
    if "min-items" in c:
        parts.append(f"at least {c['min-items']} items")
    if "max-items" in c:
        parts.append(f"at most {c['max-items']} items")
    if "item-min-items" in c:
        parts.append(f"each at least {c['item-min-items']} points")
    if "default" in c:
        parts.append(f"default {c['default']}")
    if "examples" in c:
        parts.append("e.g. " + ", ".join(f"`{v}`" for v in c["examples"]))
    if "constraint-why" in c:
        parts.append("(" + " ".join(str(c["constraint-why"]).split()) + ")")
    if "erratum" in c:
        e = c["erratum"]
        parts.append(f"{e['rule']}: {e['reading']} (warn)")
    return "; ".join(parts)


def tasks_markdown(specs: list[TaskSpec]) -> str:
    """The task reference (as spec section 8 says the spec's own was made: from the files)."""
    lines = [
        "# Tasks (WARA-PS Core System API v0.7, section 9)",
        "",
        "Generated by `waraps-conformance schemas generate` from `schemas/tasks/*.yaml`; "
        "do not edit.",
        "Tag `vehicle` means the task may move the unit: the suite never starts it on a real "
        "unit (every role but `simulation` and the profile's simulated-roles) without "
        "`--allow-motion` and the profile's consent. Each task is started with the profile's "
        "parameters for it, else the example of its specification (positions moved near the "
        "unit).",
        "",
        "| task | section | tags | required parameters |",
        "|---|---|---|---|",
    ]
    for s in specs:
        req = ", ".join(s.required) or "-"
        for group in s.raw.get("requires-one-of") or ():
            req = (req if req != "-" else "") + " or ".join(group)
        for name in s.raw.get("required-unless") or {}:
            req = (req if req != "-" else "") + f"{name} (conditional)"
        lines.append(f"| [{s.name}](#{s.name}) | {s.section} | {', '.join(s.tags) or '-'} | "
                     f"{req} |")
    for s in specs:
        lines += ["", f"## {s.name}", "", f"Spec {s.section} ({s.group}). {s.description}", ""]
        tag_line = f"Tags: {', '.join(s.tags) or 'none'}"
        if s.tags != s.spec_tags:
            tag_line += (f" (spec: {', '.join(s.spec_tags) or 'none'}; "
                         f"{' '.join(str(s.raw.get('tags-why', '')).split())})")
        lines += [tag_line, "", f"Required: {s.required_why}", ""]
        lines += ["| parameter | type | required | constraints | description |",
                  "|---|---|---|---|---|"]
        for p in s.parameters:
            lines.append(f"| `{p.name}` | {p.type} | {'yes' if p.required else ''} | "
                         f"{_md_escape(_constraint_text(p))} | {_md_escape(p.description)} |")
        if s.feedback_statuses:
            lines += ["", "Task-specific feedback statuses: "
                      + ", ".join(f"`{v}`" for v in s.feedback_statuses)]
        for alias, a in (s.raw.get("aliases") or {}).items():
            lines += ["", f"Erratum {a['rule']}: `{alias}` is read as `{a['canonical']}` "
                      f"({' '.join(a['reading'].split())}); it warns."]
    return "\n".join(lines) + "\n"


def generate_files() -> dict[str, str]:
    """Every generated file, by path relative to ``schemas/generated/``."""
    specs = task_specs()
    out = {"geopoint.json": dumps(geopoint_schema()),
           "start-task.json": dumps(start_task_schema(specs)),
           "start-tst.json": dumps(start_tst_schema(specs)),
           "TASKS.md": tasks_markdown(specs),
           "PROFILE.md": profile.markdown()}
    for s in specs:
        out[f"params/{s.name}.json"] = dumps(params_schema(s))
    return dict(sorted(out.items()))


def default_out_dir() -> Path:
    """``schemas/generated`` of the source tree (the package data folder when editable)."""
    return Path(str(resources.files(PACKAGE))) / GENERATED


def write(out_dir: Path) -> list[Path]:
    """Write the generated files into ``out_dir`` (stale ones are removed); the paths written."""
    generated = generate_files()
    written = []
    for old in sorted(out_dir.rglob("*")) if out_dir.exists() else []:
        if old.is_file() and old.relative_to(out_dir).as_posix() not in generated:
            old.unlink()
    for rel, text in generated.items():
        path = out_dir / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists() or path.read_text("utf-8") != text:
            path.write_text(text, "utf-8")
        written.append(path)
    return written


def stale_files(out_dir: Path) -> list[str]:
    """Generated files that are missing, different or extra in ``out_dir``."""
    generated = generate_files()
    stale = [rel for rel, text in generated.items()
             if not (out_dir / rel).is_file() or (out_dir / rel).read_text("utf-8") != text]
    if out_dir.exists():
        stale += [p.relative_to(out_dir).as_posix() for p in sorted(out_dir.rglob("*"))
                  if p.is_file() and p.relative_to(out_dir).as_posix() not in generated]
    return sorted(stale)


REGENERATE = "waraps-conformance schemas generate"

"""Schemas as data: the JSON Schemas, loaded once, and the rules a message reached.

Everything is read with ``importlib.resources`` from package ``conformance.schemas`` (the
top-level ``schemas/`` folder), so it works after a non-editable install:

- ``tasks/<task>.yaml``: one task specification file per task of spec section 9 (the source,
  read by ``conformance.taskspec``);
- ``generated/``: what ``waraps-conformance schemas generate`` makes from them (the GeoPoint,
  one params schema per task, the composed ``start-task`` and ``start-tst`` commands, TASKS.md);
- ``messages/``: the message schemas of sections 5, 6, 12 and 14 (written by hand).

Schema nodes carry the custom keyword ``"x-rule": "<rule id>"``: a schema error belongs to the
nearest ``x-rule`` along its evaluation path (``rule_annotations``), and to the condition of
that rule named by the nearest ``"x-condition"`` below it (or, for one keyword of a node,
``"x-conditions": {"uniqueItems": "unique"}``): a keyword the rule's quote does not state is a
condition of its own, with its own basis in ``rules.toml``. ``"x-expected"`` and
``"x-detail"`` give the words a person reads when the standard error text would say less.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from functools import cache, lru_cache
from importlib import resources
from typing import Any
from urllib.parse import urldefrag, urljoin

import jsonschema_rs

PACKAGE = "conformance.schemas"
BASE_URI = "https://waraps-conformance.invalid/schemas/"
"""Base of every schema's ``$id``. The ``.invalid`` domain is never fetched: refs resolve
from the files shipped in the package."""

UUID_PATTERN = "^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}$"

# Which schema validates which message kind (``Validation.kind``; see validator.py).
KIND_SCHEMAS: dict[str, str] = {
    "heartbeat": "messages/heartbeat.json",
    "sensor_info": "messages/sensor_info.json",
    "direct_execution_info": "messages/direct_execution_info.json",
    "tst_execution_info": "messages/tst_execution_info.json",
    "sensor/position": "messages/sensor-position.json",
    "sensor/heading": "messages/sensor-angle.json",
    "sensor/course": "messages/sensor-angle.json",
    "sensor/speed": "messages/sensor-speed.json",
    "exec/command": "messages/exec-command.json",
    "exec/response": "messages/exec-response.json",
    "exec/feedback": "messages/exec-feedback.json",
    "tst/command": "messages/tst-command.json",
    "tst/response": "messages/tst-response.json",
    "tst/feedback": "messages/tst-feedback.json",
}
URL_SENSOR_SCHEMA = "messages/sensor-url.json"  # 6.2: camera_url, videoserver_url, *_url


class SchemaError(ValueError):
    """A task specification or schema file that cannot be used; says which file and why."""


@lru_cache(maxsize=4096)
def schema_path_for_kind(kind: str) -> str | None:
    """The schema file (relative to ``schemas/``) for a message kind, or None when the spec
    defines no content for it (an optional sensor such as battery_state, an unknown topic).

    Commands are validated by their topic's dispatcher schema, which picks the command's own
    schema by ``command`` with ``if``/``then``.
    """
    for prefix in ("exec/command", "tst/command"):
        if kind == prefix or kind.startswith(prefix + "/"):
            return KIND_SCHEMAS[prefix]
    path = KIND_SCHEMAS.get(kind)
    if path is None and kind.startswith("sensor/") and kind.endswith("_url"):
        return URL_SENSOR_SCHEMA
    return path


# --- files ------------------------------------------------------------------------------------

def _walk(node: Any, prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for child in node.iterdir():
        name = prefix + child.name
        if child.is_dir():
            if child.name != "__pycache__":
                out += _walk(child, name + "/")
        elif child.name.endswith((".json", ".yaml", ".md")):
            out.append((name, child))
    return out


@lru_cache(maxsize=1)
def files() -> dict[str, bytes]:
    """Every schema data file (json, yaml, md) by path relative to ``schemas/``, sorted."""
    return {name: ref.read_bytes() for name, ref in sorted(_walk(resources.files(PACKAGE)))}


def schemas_hash() -> str:
    """sha256 (hex) over the names and bytes of the shipped schema files: which spec data a
    report was made with (the certification report puts it in JUnit properties)."""
    digest = hashlib.sha256()
    for name, data in files().items():
        digest.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    return digest.hexdigest()


@cache
def load(path: str) -> dict[str, Any]:
    """A JSON Schema by path relative to ``schemas/`` (``messages/heartbeat.json``)."""
    try:
        data = files()[path]
    except KeyError:
        raise SchemaError(f"no schema file {path!r} in {PACKAGE}; have you run "
                          f"`waraps-conformance schemas generate`?") from None
    try:
        return json.loads(data)
    except ValueError as e:
        raise SchemaError(f"{PACKAGE}/{path}: not valid JSON: {e}") from None


def all_schemas() -> dict[str, dict[str, Any]]:
    """Every JSON Schema file, by ``$id``."""
    out = {}
    for name in files():
        if name.endswith(".json"):
            schema = load(name)
            out[schema.get("$id", BASE_URI + name)] = schema
    return out


def uri_of(path: str) -> str:
    return BASE_URI + path


def _refuse_retrieval(uri: str) -> Any:
    raise SchemaError(f"schema reference {uri!r} is not a file in {PACKAGE}: schemas are never "
                      f"fetched from the network; fix the $ref")


@lru_cache(maxsize=1)
def rs_registry() -> jsonschema_rs.Registry:
    """A jsonschema-rs registry of every shipped schema (built once)."""
    return jsonschema_rs.Registry(list(all_schemas().items()), retriever=_refuse_retrieval)


def referencing_registry() -> Any:
    """The same schemas as a ``referencing.Registry`` for the pure-Python ``jsonschema``
    (the benchmark's baseline and hypothesis-jsonschema's bundling)."""
    from referencing import Registry, Resource

    return Registry().with_resources(
        (uri, Resource.from_contents(schema)) for uri, schema in all_schemas().items())


@cache
def compiled(path: str) -> jsonschema_rs.Validator:
    """A jsonschema-rs validator for one schema file, compiled once per process."""
    return jsonschema_rs.validator_for(load(path), registry=rs_registry())


# --- following an error's evaluation path ------------------------------------------------------

def resolve(base_uri: str, ref: str) -> tuple[dict[str, Any], str]:
    """The schema node ``ref`` points to from a resource at ``base_uri``, and its base URI."""
    uri, fragment = urldefrag(urljoin(base_uri, ref))
    node: Any = _by_uri(uri)
    for part in filter(None, fragment.split("/")):
        part = part.replace("~1", "/").replace("~0", "~")
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node, uri


@cache
def _by_uri_cached(uri: str) -> dict[str, Any]:
    schema = all_schemas().get(uri)
    if schema is None:
        raise SchemaError(f"no schema with $id {uri!r} in {PACKAGE}")
    return schema


def _by_uri(uri: str) -> dict[str, Any]:
    return _by_uri_cached(uri)


@dataclass(frozen=True)
class Annotations:
    """What the schema says about an error: the rule it belongs to, and optional words."""

    rule: str | None
    expected: str | None = None
    detail: str | None = None
    condition: str = ""
    """The condition of ``rule`` the error found ("": the rule's own words)."""


@lru_cache(maxsize=4096)
def rule_annotations(path: str, evaluation_path: tuple[str | int, ...]) -> Annotations:
    """Walk ``evaluation_path`` (keywords and names, ``$ref`` followed) from the root of schema
    file ``path``; the nearest ``x-rule`` wins. ``x-expected``/``x-detail`` count only on the
    node holding the failing keyword (they describe that keyword's test)."""
    node: Any = load(path)
    base = node.get("$id", uri_of(path))
    rule = node.get("x-rule")
    condition = node.get("x-condition", "")
    for step in evaluation_path[:-1]:
        if step == "$ref" and isinstance(node, dict):
            node, base = resolve(base, node["$ref"])
        elif isinstance(node, dict):
            node = node.get(step) if isinstance(step, str) else None
        elif isinstance(node, list) and isinstance(step, int) and step < len(node):
            node = node[step]
        else:
            node = None
        if node is None:
            break
        if isinstance(node, dict):
            if "$id" in node:
                base = node["$id"]
            if "x-rule" in node:  # a rule of its own: its own words, unless it says
                rule, condition = node["x-rule"], ""
            condition = node.get("x-condition", condition)
    if isinstance(node, dict):
        # ``x-conditions`` names the condition of one keyword of this node (``uniqueItems``:
        # a keyword the rule's quote does not state is a condition of its own, decided).
        keyword = evaluation_path[-1] if evaluation_path else ""
        named = node.get("x-conditions", {})
        if isinstance(keyword, str) and keyword in named:
            condition = named[keyword]
        return Annotations(rule, node.get("x-expected"), node.get("x-detail"), condition)
    return Annotations(rule, condition=condition)


# --- which rules a message reached (jsonschema-rs's evaluation) ----------------------------------

_CONDITIONS = frozenset({"if", "not", "contains"})
"""Keywords whose subschema is a test, not a requirement: nothing under them is examined."""
_BRANCHES = frozenset({"anyOf", "oneOf"})
"""Keywords whose branches count only where they hold (the alternative that applied)."""
_NAMING = frozenset({"properties", "patternProperties", "dependentSchemas", "prefixItems",
                     "allOf", "anyOf", "oneOf", "$defs", "definitions"})
"""Keywords followed, in an evaluation path, by a name or index rather than a keyword."""
_TO_CHILDREN = frozenset({"items", "additionalProperties", "unevaluatedItems",
                          "unevaluatedProperties", "propertyNames"})
"""Keywords applying one schema to each child: their own unit, at the parent's location, is
the keyword (reached on an empty array too), not the schema applied to a child."""
_VALUE_TESTS = frozenset({"const", "enum", "pattern", "format", "minimum", "maximum",
                          "exclusiveMinimum", "exclusiveMaximum", "multipleOf", "minLength",
                          "maxLength", "minItems", "maxItems", "uniqueItems"})
"""Keywords that read a value beyond its type and keys (a test at the message's own level
makes the message's value decide)."""


@dataclass(frozen=True)
class Reach:
    """What evaluating one message against a schema reached.

    ``rules``: the ``x-rule`` of every schema node applied to the message as a requirement
    (JSON Schema's annotation semantics: ``then``/``else`` where they applied, every ``allOf``
    part, the ``anyOf``/``oneOf`` branches that held; not the insides of ``if``, ``not`` and
    ``contains``, which are tests). A node that failed counts too: its rule was examined and
    the violation fails it. ``decided_by``: the top-level fields of the message whose values
    chose among branches (``""``: the message's own value), so that a message of the same shape
    and the same values there reaches the same rules.
    """

    rules: frozenset[str]
    decided_by: frozenset[str]


def _tokens(pointer: str) -> list[str]:
    return [t.replace("~1", "/").replace("~0", "~") for t in pointer.split("/")[1:]]


@lru_cache(maxsize=16384)
def _rule_at(location: str) -> str | None:
    """The ``x-rule`` of the schema node at an absolute schema location (URI#pointer)."""
    uri, fragment = urldefrag(location)
    try:
        node: Any = _by_uri(uri)
        for part in _tokens(fragment):
            node = node[int(part)] if isinstance(node, list) else node[part]
    except (SchemaError, KeyError, IndexError, ValueError, TypeError):
        return None
    rule = node.get("x-rule") if isinstance(node, dict) else None
    return rule if isinstance(rule, str) else None


def _held(valid: dict[tuple[str, str], bool], branch: str, at: str) -> bool:
    """Whether the branch at evaluation path ``branch`` held where it was applied: at the
    longest prefix of instance location ``at`` it was evaluated at."""
    while True:
        found = valid.get((branch, at))
        if found is not None:
            return found
        if not at:
            return False
        at = at.rsplit("/", 1)[0]


def reach(path: str, message: Any) -> Reach:
    """The rules of schema file ``path`` that ``message`` reached (``Reach``), read off
    jsonschema-rs's evaluation of it (its list output: every evaluated node, with its
    evaluation path, schema location, instance location and validity).

    It costs 10-100 times ``is_valid`` (bench/bench_validate.py): call it once per message
    shape, not per message (the Monitor caches it by shape).
    """
    units = compiled(path).evaluate(message).list()["details"]
    valid = {(u["evaluationPath"], u["instanceLocation"]): u["valid"] for u in units}
    rules: set[str] = set()
    decided: set[str] = set()
    for unit in units:
        counts, chosen = True, False
        path_of_unit = unit["evaluationPath"]
        token = path_of_unit.rsplit("/", 1)[-1]
        at = unit["instanceLocation"]
        if token in _TO_CHILDREN and (path_of_unit[: -len(token) - 1], at) in valid:
            continue  # the keyword itself (at its parent's location), not a child's schema
        prefix = ""
        naming = False
        branch = False
        for token in _tokens(path_of_unit):
            prefix += "/" + token.replace("~", "~0").replace("/", "~1")
            if naming:  # a property name or an index
                naming = False
                if branch:
                    branch = False
                    chosen = True
                    if not _held(valid, prefix, at):
                        counts = False
                continue
            if token in _CONDITIONS:
                counts = False
                chosen = chosen or token == "if"
            naming = token in _NAMING
            branch = token in _BRANCHES
        if chosen:
            location = _tokens(unit["instanceLocation"])
            if location:
                decided.add(location[0])
            elif token in _VALUE_TESTS:  # keys and types are the shape; a value is not
                decided.add("")
        if counts:
            rule = _rule_at(unit["schemaLocation"])
            if rule is not None:
                rules.add(rule)
    return Reach(frozenset(rules), frozenset(decided))


# --- bundling: a schema without $ref ---------------------------------------------------------

def inline_refs(schema: dict[str, Any], *, max_depth: int = 3) -> dict[str, Any]:
    """A copy of ``schema`` with every ``$ref`` replaced by its target (recursive refs are cut
    after ``max_depth`` expansions by an empty-array/false schema, for generators that cannot
    follow recursion). ``$id``s are dropped from the copy."""

    def go(node: Any, base: str, depth: dict[str, int]) -> Any:
        if isinstance(node, list):
            return [go(x, base, depth) for x in node]
        if not isinstance(node, dict):
            return node
        base = node.get("$id", base)
        out: dict[str, Any] = {}
        for k, v in node.items():
            if k in ("$id", "$schema", "$defs", "$ref"):
                continue
            out[k] = go(v, base, depth)
        if "$ref" in node:
            target, target_base = resolve(base, node["$ref"])
            key = urljoin(base, node["$ref"])
            if depth.get(key, 0) >= max_depth:
                return False
            inner = go(target, target_base, {**depth, key: depth.get(key, 0) + 1})
            if inner is False:
                return False
            if out:
                return {"allOf": [inner], **out}
            return inner
        return out

    root_base = schema.get("$id", BASE_URI)
    return go(schema, root_base, {})

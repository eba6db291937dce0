"""Which stateless rules the validator examined on one message, so that they can pass.

A rule passes only when it was examined (DESIGN 'Semantics'). The validator reports
violations, not what it looked at; until it says so itself (``Validation.examined``, which the
Monitor prefers when present), this module derives it, erring towards *not* examined:

- the topic rules and MSG-001/002/004 on every message (the validator always runs them);
- for a decoded message with a schema: every ``x-rule`` of the schema nodes that the message
  reaches. ``$ref``, ``allOf``, ``anyOf``, ``oneOf``, ``not``, ``properties`` (present ones) and
  ``items`` (non-empty arrays) are followed; an ``if``/``then``/``else`` only when its ``if`` is
  a ``const`` test on a property that can be read off the message (the command dispatch of
  exec/command, the task dispatch of start-task, ``response: failed``); any other conditional
  branch is not followed, so its rules stay unexamined;
- the content rules the validator checks in code (MSG-005, MSG-006, HB-004, EXEC-005, TST-002,
  EXEC-FB-002), when the field they look at is present.

Results are cached per (schema, values read at the dispatch points): a few entries per kind.
"""

from __future__ import annotations

import re
from functools import lru_cache
from typing import Any

from conformance.topics import TopicKind
from conformance.validator import Validation

Path = tuple[str, ...]

TOPIC_ANY = ("TOPIC-001", "TOPIC-002", "TOPIC-008", "MSG-004")
TOPIC_UNIT = TOPIC_ANY + ("TOPIC-003", "TOPIC-004", "TOPIC-005", "TOPIC-006", "TOPIC-007")
DECODED_ANY = TOPIC_ANY + ("MSG-001", "MSG-002")
DECODED_UNIT = TOPIC_UNIT + ("MSG-001", "MSG-002")
SENSOR_INFO_TOPIC = ("ERR-001",)  # naming_violations checks sensor.info vs sensor_info

_SENSOR_INFO = TopicKind.SENSOR_INFO
_INFO = (TopicKind.HEARTBEAT, TopicKind.SENSOR_INFO, TopicKind.DIRECT_EXECUTION_INFO,
         TopicKind.TST_EXECUTION_INFO)
_MAX_CACHE = 4096
_UNREADABLE = object()


def _schema_path(kind: str) -> str | None:
    try:
        from conformance import schema
    except Exception:  # no schema module: only what is always examined
        return None
    return schema.schema_path_for_kind(kind)


def _node(base: str, ref: str) -> tuple[Any, str]:
    from conformance import schema

    return schema.resolve(base, ref)


def _root(path: str) -> tuple[Any, str]:
    from conformance import schema

    node = schema.load(path)
    return node, node.get("$id", schema.uri_of(path))


def _const_test(cond: Any) -> tuple[str, Any] | None:
    """(property, value) when an ``if`` is ``{"properties": {P: {"const": V}}, ...}``."""
    if not isinstance(cond, dict):
        return None
    props = cond.get("properties")
    if not isinstance(props, dict) or len(props) != 1:
        return None
    (name, test), = props.items()
    if not isinstance(test, dict) or "const" not in test:
        return None
    if set(cond) - {"properties", "required"}:
        return None
    return name, test["const"]


def _pattern_test(cond: Any) -> re.Pattern[str] | None:
    """The regex when an ``if`` is only ``{"pattern": P}``."""
    if isinstance(cond, dict) and set(cond) == {"pattern"} and isinstance(cond["pattern"], str):
        try:
            return re.compile(cond["pattern"])
        except re.error:
            return None
    return None


def _walk(node: Any, base: str, instance: Any, rules: set[str] | None, dispatch: set[Path],
          at: Path, seen: set[tuple[int, Path]]) -> None:
    """Collect the x-rules of the schema nodes ``instance`` reaches. ``rules`` None: collect
    only the dispatch points (instance paths tested by const-ifs), following every branch."""
    if not isinstance(node, dict) or (id(node), at) in seen or len(at) > 12:
        return
    seen.add((id(node), at))
    if "$id" in node and isinstance(node["$id"], str):
        base = node["$id"]
    followed = False
    ref = node.get("$ref")
    if isinstance(ref, str):
        try:
            target, target_base = _node(base, ref)
        except Exception:  # a dangling ref: the validator reports it; nothing examined here
            target = None
        if target is not None:
            _walk(target, target_base, instance, rules, dispatch, at, seen)
    for key in ("allOf", "anyOf", "oneOf"):
        for sub in node.get(key) or ():
            _walk(sub, base, instance, rules, dispatch, at, seen)
    if isinstance(node.get("not"), dict):
        _walk(node["not"], base, instance, rules, dispatch, at, seen)
    if "if" in node:
        test = _const_test(node["if"])
        pattern = _pattern_test(node["if"])
        branches: list[Any] = []
        if pattern is not None:  # {"if": {"pattern": ...}} on a string (DEI-003's '$' signals)
            dispatch.add(at)
            if rules is None:
                branches = [node.get("then"), node.get("else")]
            elif isinstance(instance, str):
                branches = [node.get("then") if pattern.search(instance) else node.get("else")]
        elif test is not None:
            dispatch.add(at + (test[0],))
            if rules is None:
                branches = [node.get("then"), node.get("else")]
            elif isinstance(instance, dict) and test[0] in instance:
                value = instance[test[0]]
                branches = [node.get("then") if value == test[1] else node.get("else")]
            elif isinstance(instance, dict):  # property absent: the if's properties pass
                branches = [node.get("then") if test[0] not in node["if"].get("required", ())
                            else node.get("else")]
        for sub in branches:
            if isinstance(sub, dict):
                followed = True
                _walk(sub, base, instance, rules, dispatch, at, seen)
    props = node.get("properties")
    if isinstance(props, dict):
        for name, sub in props.items():
            if rules is None:
                _walk(sub, base, _ANY, rules, dispatch, at + (name,), seen)
            elif isinstance(instance, dict) and name in instance:
                _walk(sub, base, instance[name], rules, dispatch, at + (name,), seen)
    items = node.get("items")
    if isinstance(items, dict):
        if rules is None:
            _walk(items, base, _ANY, rules, dispatch, at + ("[]",), seen)
        elif isinstance(instance, list):
            for i, item in enumerate(instance[:8]):  # the first few show every shape in use
                _walk(items, base, item, rules, dispatch, at + (str(i),), seen)
    rule = node.get("x-rule")
    if rules is not None and isinstance(rule, str):
        # A node that is only a condition examines its rule only when a branch applied
        # (EXEC-007 'a failed response carries a fail-reason' is not examined on a pong).
        if followed or not set(node) <= _CONDITIONAL_KEYS:
            rules.add(rule)


_ANY = object()
_CONDITIONAL_KEYS = {"if", "then", "else", "x-rule", "x-expected", "x-detail", "description",
                     "$comment", "title"}


@lru_cache(maxsize=64)
def _dispatch_points(path: str) -> tuple[Path, ...]:
    dispatch: set[Path] = set()
    node, base = _root(path)
    _walk(node, base, _ANY, None, dispatch, (), set())
    return tuple(sorted(dispatch))


def _read(message: Any, at: Path) -> Any:
    """The value at an instance path as a cache key; ``[]`` steps read the first 8 items (the
    walk looks at those), giving a tuple."""
    node = message
    for i, step in enumerate(at):
        if step == "[]":
            if not isinstance(node, list):
                return _ABSENT
            return tuple(_read(item, at[i + 1:]) for item in node[:8])
        if not isinstance(node, dict) or step not in node:
            return _ABSENT
        node = node[step]
    return _key_value(node)


_ABSENT = object()


def _key_value(x: Any) -> Any:
    """A dispatch value as a cache key: short scalars as they are, the rest unreadable."""
    if x is _ABSENT or isinstance(x, (bool, int, float)) or (isinstance(x, str) and len(x) <= 64):
        return x
    return _UNREADABLE


class RuleGroup:
    """The rules examined together on messages of one shape. The Monitor counts messages per
    group (a hash by identity: one per shape, shared) and expands them into per-rule counts
    only at report time. Iterating a group gives its rule ids."""

    __slots__ = ("rules",)

    def __init__(self, rules: tuple[str, ...]) -> None:
        self.rules = rules

    def __iter__(self) -> Any:
        return iter(self.rules)

    def __repr__(self) -> str:
        return f"RuleGroup{self.rules!r}"


_groups: dict[tuple[str, ...], RuleGroup] = {}


def _group(rules: tuple[str, ...]) -> RuleGroup:
    """The one group of these rules (interned: equal rule sets share one group)."""
    g = _groups.get(rules)
    if g is None:
        g = RuleGroup(rules)
        if len(_groups) < _MAX_CACHE:
            _groups[rules] = g
    return g


_NOT_DECODED = {True: _group(TOPIC_UNIT), False: _group(TOPIC_ANY)}
_DECODED = {(True, False): _group(DECODED_UNIT), (False, False): _group(DECODED_ANY),
            (True, True): _group(DECODED_UNIT + SENSOR_INFO_TOPIC),
            (False, True): _group(DECODED_ANY + SENSOR_INFO_TOPIC)}

# The fields the validator's content checks look at, by topic kind (``_content_rules``): their
# types are part of the cache key.
_CONTENT_FIELDS: dict[TopicKind, tuple[str, ...]] = {
    **{k: ("name", "stamp") for k in _INFO},
    TopicKind.EXEC_RESPONSE: ("com-uuid",),
    TopicKind.TST_RESPONSE: ("com-uuid",),
    TopicKind.EXEC_FEEDBACK: ("status",),
}

_cache: dict[tuple[Any, ...], RuleGroup] = {}


_kinds: dict[str, tuple[str, tuple[Path, ...]] | None] = {}


def _kind_schema(kind: str) -> tuple[str, tuple[Path, ...]] | None:
    """The schema path of a validation kind and its dispatch points (cached per kind)."""
    try:
        return _kinds[kind]
    except KeyError:
        pass
    try:
        path = _schema_path(kind)
        info = (path, _dispatch_points(path)) if path is not None else None
    except Exception:  # schemas unreadable: the validator reports that; claim nothing more
        info = None
    if len(_kinds) < _MAX_CACHE:
        _kinds[kind] = info
    return info


def shape_fields(kind: str, topic_kind: TopicKind) -> tuple[str, ...] | None:
    """For messages of one validation kind on one unit's topic: the fields whose types, with
    the top-level keys and which values are empty, decide ``examined_group`` for a JSON
    object (besides the values under ``dispatch_roots``); None when the kind has no schema."""
    if _kind_schema(kind) is None:
        return None
    return _CONTENT_FIELDS.get(topic_kind, ())


def dispatch_roots(kind: str) -> tuple[str, ...]:
    """The top-level keys under which ``examined_group`` reads dispatch values (the command
    of a command, a response's ``response``, the signals of tasks-available): equal values
    there, and an equal shape, give the same group."""
    info = _kind_schema(kind)
    if info is None:
        return ()
    return tuple(dict.fromkeys(p[0] for p in info[1] if p))


def examined_by_validator(v: Validation) -> tuple[str, ...]:
    """The rules the validator examined on this message (module docstring)."""
    return examined_group(v).rules


def examined_group(v: Validation) -> RuleGroup:
    """``examined_by_validator`` as a shared ``RuleGroup`` (what the Monitor counts: it runs
    on every message, so the common case is a few C-speed tuples and one dict lookup)."""
    topic = v.topic
    unit = topic.unit is not None
    m = v.message
    if m is None:
        return _NOT_DECODED[unit]
    kind_topic = topic.kind
    if not unit:
        return _DECODED[False, kind_topic is _SENSOR_INFO]
    kind = v.kind
    info = _kinds[kind] if kind in _kinds else _kind_schema(kind)
    if info is None:
        return _DECODED[True, kind_topic is _SENSOR_INFO]
    path, points = info
    # The cache key says what the walk depends on: the keys present at the top level and
    # which of their values are empty, the values at the dispatch points, the types of the
    # fields the content rules look at. Nested optional parts are taken to be as in the first
    # message with that key.
    if type(m) is dict:
        if len(m) > 64:
            cache_key: tuple[Any, ...] | None = None
        else:
            fields = _CONTENT_FIELDS.get(kind_topic)
            cache_key = (kind, tuple(m), tuple(map(bool, m.values())),
                         tuple(map(type, map(m.get, fields))) if fields else (),
                         tuple([_read(m, p) for p in points]) if points else ())
    else:
        cache_key = (kind, type(m))
    if cache_key is not None:
        hit = _cache.get(cache_key)
        if hit is not None:
            return hit
    rules = set(_DECODED[True, kind_topic is _SENSOR_INFO].rules)
    node, schema_base = _root(path)
    _walk(node, schema_base, m, rules, set(), (), set())
    if isinstance(m, dict):
        rules.add("MSG-003")
        rules |= _content_rules(kind_topic, m)
    elif _expects_object(path):
        rules.add("MSG-003")
    group = _group(tuple(sorted(rules)))
    if cache_key is not None and len(_cache) < _MAX_CACHE:
        _cache[cache_key] = group
    return group


def _expects_object(path: str) -> bool:
    node, _ = _root(path)
    return node.get("type") == "object"


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _content_rules(kind: TopicKind, m: dict[str, Any]) -> set[str]:
    """The validator's content checks in code (validator._CONTENT_CHECKS), where they look."""
    out: set[str] = set()
    if kind in _INFO:
        if isinstance(m.get("name"), str):
            out.add("MSG-006")
        if _number(m.get("stamp")):
            out.add("MSG-005")
        if kind is TopicKind.HEARTBEAT:
            out.add("HB-004")
    elif kind is TopicKind.EXEC_RESPONSE and isinstance(m.get("com-uuid"), str):
        out.add("EXEC-005")
    elif kind is TopicKind.TST_RESPONSE and isinstance(m.get("com-uuid"), str):
        out.add("TST-002")
    elif kind is TopicKind.EXEC_FEEDBACK and isinstance(m.get("status"), str):
        out.add("EXEC-FB-002")
    return out

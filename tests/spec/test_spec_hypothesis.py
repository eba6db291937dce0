"""Property tests from the schemas themselves (hypothesis-jsonschema): messages generated from
a schema validate; each mutation of one (drop a required key, wrong type, value outside an
enum, extra nesting) is rejected with the rule that covers the field.

Runs under the ``ci`` hypothesis profile (tests/conftest.py); ``HYPOTHESIS_PROFILE=dev``
explores deeper. Each family gets a share of the profile's examples (the ``share`` profile) so
the area stays fast.
"""

from __future__ import annotations

import copy
from functools import cache
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis_jsonschema import from_schema

from conformance import schema, taskspec
from conformance.validator import Validator

UNIT = "waraps/unit/air/simulation/dji0"
# Each family runs once per message kind: the 'share' profile (tests/conftest.py) gives each
# test a share of the active profile's examples.
FAST = settings(settings.get_profile("share"), database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.data_too_large])

# The rule a fault in a top-level field belongs to: the kind's rule unless listed here. This is
# the specification of the mapping, written independently of the schemas' x-rule annotations.
KIND_RULE = {
    "heartbeat": "HB-001", "sensor_info": "SI-001", "direct_execution_info": "DEI-001",
    "tst_execution_info": "TEI-001", "sensor/position": "SENS-001",
    "exec/command": "EXEC-001", "exec/response": "EXEC-002", "exec/feedback": "EXEC-FB-001",
    "tst/command": "TST-001", "tst/response": "TST-002", "tst/feedback": "TST-003",
}
FIELD_RULE = {
    ("heartbeat", "agent-type"): "HB-004", ("heartbeat", "rate"): "HB-009",
    ("heartbeat", "type"): "HB-002", ("exec/response", "response"): "EXEC-003",
    ("exec/feedback", "status"): "EXEC-FB-002",
}
# Enumerated vocabularies: (kind, field) -> rule for a value outside the vocabulary.
ENUM_RULE = {
    ("heartbeat", "agent-type"): "HB-004", ("heartbeat", "type"): "HB-002",
    ("sensor_info", "type"): "SI-001", ("direct_execution_info", "type"): "DEI-001",
    ("exec/response", "response"): "EXEC-003", ("exec/feedback", "status"): "EXEC-FB-002",
    ("exec/command", "command"): "EXEC-001", ("tst/command", "command"): "TST-001",
    ("tst/response", "response"): "TST-002", ("tst/feedback", "status"): "TST-003",
    ("sensor/position", "rostype"): "SENS-001",
}

TOPIC_OF = {
    "heartbeat": "heartbeat", "sensor_info": "sensor_info",
    "direct_execution_info": "direct_execution_info", "tst_execution_info": "tst_execution_info",
    "sensor/position": "sensor/position", "exec/command": "exec/command",
    "exec/response": "exec/response", "exec/feedback": "exec/feedback",
    "tst/command": "tst/command", "tst/response": "tst/response", "tst/feedback": "tst/feedback",
}

# Content the schemas cannot state is pinned for generation: the topic's unit name and type
# (MSG-006, HB-004), a standard feedback status (EXEC-FB-002 judges the open vocabulary), and
# a response's own com-uuid (EXEC-005, filtered below).
PINNED = {
    "heartbeat": {"name": {"const": "dji0"}, "agent-type": {"const": "air"}},
    "sensor_info": {"name": {"const": "dji0"}},
    "direct_execution_info": {"name": {"const": "dji0"}},
    "tst_execution_info": {"name": {"const": "dji0"}},
    "exec/feedback": {"status": {"enum": ["running", "failed", "aborted", "paused", "finished",
                                          "starting"]}},
}


JSON_SAFE = 2**53  # integers a JSON parser reads exactly (orjson refuses beyond 64 bits)


def _plain(node: Any) -> Any:
    """The schema without annotations, for the generator (it only needs assertions), with
    closed objects and JSON-safe numbers: messages may carry extra fields (the schemas allow
    them), but generating megabytes of them tests nothing and costs the time budget."""
    if isinstance(node, list):
        return [_plain(v) for v in node]
    if not isinstance(node, dict):
        return node
    out = {k: _plain(v) for k, v in node.items()
           if not k.startswith("x-") and k not in ("description", "$comment", "title",
                                                   "examples", "default")}
    if out.get("type") == "object" and "properties" in out:
        out.setdefault("additionalProperties", False)
    if out.get("type") in ("number", "integer"):
        if "minimum" not in out and "exclusiveMinimum" not in out:
            out["minimum"] = -JSON_SAFE
        if "maximum" not in out and "exclusiveMaximum" not in out:
            out["maximum"] = JSON_SAFE
    return out


@cache
def _strategy(path: str, pin: tuple[tuple[str, str], ...] = ()) -> st.SearchStrategy[Any]:
    plain = _plain(schema.inline_refs(schema.load(path), max_depth=1))
    for key, value in pin:
        plain = {"allOf": [plain, {"properties": {key: orjson.loads(value)}}]}
    return from_schema(plain)


@cache
def message_strategy(kind: str) -> st.SearchStrategy[Any]:
    pin = tuple((k, orjson.dumps(v).decode()) for k, v in PINNED.get(kind, {}).items())
    if kind == "exec/command":
        return st.one_of(*(_strategy(f"messages/{c}.json") for c in
                           ("ping", "signal-task", "query-status")), start_task())
    if kind == "tst/command":
        return st.one_of(*(_strategy(f"messages/{c}.json") for c in
                           ("signal-tst-node", "signal-tst-tree", "signal-unit")), start_tst())
    strategy = _strategy(schema.KIND_SCHEMAS[kind], pin)
    if kind.endswith("/response"):  # EXEC-005: a response's com-uuid is its own
        strategy = strategy.filter(lambda m: m["com-uuid"] != m["response-to"])
    return strategy


UUID = st.uuids().map(str)


def start_task() -> st.SearchStrategy[dict[str, Any]]:
    """start-task with params generated from a task's own params schema (12.2.3)."""
    return st.sampled_from(taskspec.task_names()).flatmap(lambda name: st.builds(
        lambda com, task_uuid, params: {"com-uuid": com, "command": "start-task",
                                        "sender": "commander", "task-uuid": task_uuid,
                                        "task": {"name": name, "params": params}},
        UUID, UUID, _strategy(taskspec.params_schema_path(name))))


def start_tst() -> st.SearchStrategy[dict[str, Any]]:
    node = st.sampled_from(taskspec.task_names()).flatmap(lambda name: st.builds(
        lambda node_uuid, params: {"name": name, "params": params, "children": [],
                                   "common_params": {"execunit": "/dji0",
                                                     "node-uuid": node_uuid}},
        UUID, _strategy(taskspec.params_schema_path(name))))
    # A task node is a leaf; only the composites seq and conc have children (TST-014).
    composite = st.builds(lambda name, node_uuid, kids: {
        "name": name, "params": {}, "children": kids,
        "common_params": {"execunit": "/dji0", "node-uuid": node_uuid}},
        st.sampled_from(("seq", "conc")), UUID, st.lists(node, min_size=1, max_size=2))
    tree = st.one_of(node, composite)
    return st.builds(lambda com, tst: {"com-uuid": com, "command": "start-tst",
                                       "receiver": "op0", "tst": tst}, UUID, tree)


KINDS = sorted(TOPIC_OF)
VALIDATOR = Validator()


def violations(kind: str, message: Any) -> list[tuple[str, str]]:
    v = VALIDATOR.validate(f"{UNIT}/{TOPIC_OF[kind]}", orjson.dumps(message), None)
    return [(x.rule, x.path) for x in v.violations]




@pytest.mark.parametrize("kind", KINDS)
def test_generated_valid_message_validates(kind: str) -> None:
    @FAST
    @given(message_strategy(kind))
    def check(message: Any) -> None:
        assert violations(kind, message) == []

    check()


def reported_at_or_under(found: list[tuple[str, str]], rule: str, spot: str) -> bool:
    """Whether ``rule`` is reported at ``spot`` or inside it (a wrapped object fails on the
    fields it now lacks)."""
    return any(r == rule and (p == spot or p.startswith((spot + ".", spot + "[")))
               for r, p in found)


def _field_rule(kind: str, field: str) -> str:
    return FIELD_RULE.get((kind, field), KIND_RULE[kind])


def _wrong_type(value: Any) -> Any:
    if isinstance(value, bool):
        return "true"
    if isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, str):
        return 12345
    if isinstance(value, list):
        return {"items": value}
    return [value]


@pytest.mark.parametrize("kind", KINDS)
@FAST
@given(data=st.data())
def test_dropping_a_required_key_is_rejected_with_the_kinds_rule(kind: str, data: st.DataObject) -> None:
    message = data.draw(message_strategy(kind))
    path = schema.schema_path_for_kind(VALIDATOR.validate(
        f"{UNIT}/{TOPIC_OF[kind]}", orjson.dumps(message)).kind)
    required = schema.load(path or "").get("required", [])
    if kind in ("exec/command", "tst/command"):  # the command's own schema lists its keys
        required = ["com-uuid", "command"]
    if kind == "sensor/position":  # the GeoPoint's, by $ref
        required = schema.load("generated/geopoint.json")["required"]
    key = data.draw(st.sampled_from(sorted(required)))
    broken = {k: v for k, v in message.items() if k != key}
    assert (KIND_RULE[kind], f"$.{key}") in violations(kind, broken)


@pytest.mark.parametrize("kind", KINDS)
@FAST
@given(data=st.data())
def test_wrong_type_or_extra_nesting_is_rejected_with_the_fields_rule(kind: str, data: st.DataObject) -> None:
    message = data.draw(message_strategy(kind))
    if not isinstance(message, dict):
        return
    key = data.draw(st.sampled_from(sorted(message)))
    nest = data.draw(st.booleans())
    broken = dict(message)
    broken[key] = {"value": message[key]} if nest else _wrong_type(message[key])
    found = violations(kind, broken)
    assert reported_at_or_under(found, _field_rule(kind, key), f"$.{key}"), found


@pytest.mark.parametrize("kind", KINDS)
@FAST
@given(data=st.data())
def test_value_outside_an_enum_is_rejected_with_the_vocabularys_rule(kind: str, data: st.DataObject) -> None:
    message = data.draw(message_strategy(kind))
    fields = sorted(f for (k, f) in ENUM_RULE if k == kind and f in message)
    if not fields:
        return
    key = data.draw(st.sampled_from(fields))
    bad = data.draw(st.text(alphabet="xyzq-", min_size=1, max_size=12))
    broken = {**message, key: bad}
    assert (ENUM_RULE[(kind, key)], f"$.{key}") in violations(kind, broken)


@FAST
@given(start_task(), st.data())
def test_start_task_param_faults_are_task_rules(message: dict[str, Any],
                                                data: st.DataObject) -> None:
    """Inside params: a dropped required parameter or a wrong type is TASK-001, an unknown
    parameter TASK-003, an unknown task name TASK-002 (and its params are not checked)."""
    name = message["task"]["name"]
    spec = taskspec.task_spec(name)
    params = message["task"]["params"]
    fault = data.draw(st.sampled_from(["drop", "type", "unknown", "name"]))
    broken = copy.deepcopy(message)
    if fault == "drop" and spec.required:
        key = data.draw(st.sampled_from(spec.required))
        del broken["task"]["params"][key]
        expected = ("TASK-001", f"$.task.params.{key}")
    elif fault == "type" and params:
        key = data.draw(st.sampled_from(sorted(params)))
        broken["task"]["params"][key] = {"value": params[key]}
        found = violations("exec/command", broken)
        assert reported_at_or_under(found, "TASK-001", f"$.task.params.{key}"), found
        return
    elif fault == "unknown":
        broken["task"]["params"]["zz-unknown"] = 1
        expected = ("TASK-003", "$.task.params.zz-unknown")
    else:
        broken["task"]["name"] = "zz-" + name
        broken["task"]["params"]["zz-unknown"] = 1  # not checked for an unknown task
        assert violations("exec/command", broken) == [("TASK-002", "$.task.name")]
        return
    assert expected in violations("exec/command", broken)

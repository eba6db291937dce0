"""Every rule the validator can examine on a valid message is reported examined on one: no rule
stays 'skip' because of the schema keyword that leads to it (an ``if``/``then`` on a field's
own value, a ``$ref``, an ``anyOf`` branch) or because it is checked in code.

The valid messages: the spec's own examples (tests/spec/corpus), what the reference unit
publishes and answers (air, with its TST level) to the commands of 12 and 14, and a start-task
of every task's example. The rules expected: every ``x-rule`` of the shipped schemas (read
here from the files, independently of ``schema.reach``), the content rules the validator
checks in code, the naming and decoding rules.
"""

from __future__ import annotations

import json
import random
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson

from conformance import schema, taskspec
from conformance.sim.unit import UnitCore
from conformance.topics import UNIT_NAMING_RULES, UnitAddress
from conformance.validator import Validator

CORPUS = Path(__file__).parent / "corpus"
ADDRESS = UnitAddress("waraps", "air", "simulation", "dji0")
CONTENT_RULES = {
    "MSG-005", "MSG-006", "MSG-008", "HB-004",  # the infos' stamp and name, the heartbeat's agent-type
    "EXEC-005", "TST-002",  # a response's own com-uuid
    "EXEC-FB-002",  # a feedback's status
    "TST-014",  # a start-tst's tree
}
"""The rules the validator checks in code rather than in a schema (written here independently
of the validator, like the ``x-rule``s read from the files)."""


def schema_rules() -> dict[str, list[str]]:
    """Every ``x-rule`` of the shipped schemas -> the nodes (file#pointer) carrying it."""
    found: dict[str, list[str]] = {}

    def walk(node: Any, where: str) -> None:
        if isinstance(node, dict):
            if isinstance(node.get("x-rule"), str):
                found.setdefault(node["x-rule"], []).append(where)
            for key, value in node.items():
                walk(value, f"{where}/{key}")
        elif isinstance(node, list):
            for i, value in enumerate(node):
                walk(value, f"{where}/{i}")

    for name in schema.files():
        if name.endswith(".json"):
            walk(schema.load(name), name + "#")
    return found


def only_when_violated(where: str) -> bool:
    """A part ``{"not": {}}`` of an ``allOf``: it holds for no value, so only a message that
    has what must not be there at all reaches it (a misspelt key, a list where one value is
    due: the ERR reading of those). A value that is prohibited is a ``not`` of that value,
    applied to every value, not a ``then: {"not": {}}`` (which this does not excuse)."""
    name, pointer = where.split("#")
    node: Any = schema.load(name)
    parts = [p for p in pointer.split("/") if p]
    for part in parts:
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node.get("not") == {} and len(parts) >= 2 and parts[-2] == "allOf"


def corpus_messages() -> Iterator[tuple[str, bytes]]:
    """The spec's examples that are judged without a rule broken (a repaired reading of one
    that is not JSON too)."""
    index = json.loads((CORPUS / "index.json").read_text("utf-8"))["examples"]
    for entry in index:
        if entry["valid-json"] and not entry["expected"]["rules"]:
            yield entry["topic"], (CORPUS / entry["raw"]).read_bytes()
        repaired = entry.get("repaired")
        if repaired and not repaired["expected"]["rules"]:
            yield entry["topic"], (CORPUS / repaired["file"]).read_bytes()


def reference_unit_messages() -> Iterator[tuple[str, bytes]]:
    """What the reference unit publishes over a short simulated run, the commands sent to it
    and its answers."""
    sent: list[tuple[str, bytes]] = []
    unit = UnitCore(ADDRESS, lambda topic, payload, retain: sent.append((topic, payload)),
                    tst_execution=True, rng=random.Random(3), task_seconds=0.5,
                    clock=lambda: now)
    now = 1_763_700_000.0
    unit.start(now)

    def run(seconds: float) -> None:
        nonlocal now
        end = now + seconds
        while now < end:
            now += 0.1
            unit.run(now)

    def command(body: dict[str, Any], tst: bool = False) -> None:
        body = {"com-uuid": str(uuid.uuid4()), "sender": "op0", **body}
        topic, payload = unit.topic("tst/command" if tst else "exec/command"), orjson.dumps(body)
        sent.append((topic, payload))
        if tst:
            unit.tst_command(payload, now, topic)
        else:
            unit.command(payload, now)
        run(1.0)

    run(3.0)
    command({"command": "ping"})
    for spec in taskspec.task_specs():
        if spec.name in unit.specs:
            task = str(uuid.uuid4())
            command({"command": "start-task", "execution-unit": "dji0", "task-uuid": task,
                     "task": {"name": spec.name, "params": spec.example.get("params", {})}})
            command({"command": "query-status", "task-uuid": task})
            command({"command": "signal-task", "task-uuid": task, "signal": "$abort"})
    root, leaf = str(uuid.uuid4()), str(uuid.uuid4())
    command({"command": "start-tst", "tst": {
        "name": "seq", "params": {}, "common_params": {"node-uuid": root, "execunit": "/dji0"},
        "children": [{"name": "take-off", "params": {}, "children": [],
                      "common_params": {"node-uuid": leaf, "execunit": "/dji0"}}]}}, tst=True)
    command({"command": "signal-tst-node", "node-uuid": leaf, "signal": "$pause"}, tst=True)
    command({"command": "signal-tst-tree", "node-uuid": root, "signal": "$continue"}, tst=True)
    command({"command": "signal-unit", "unit": "/dji0", "signal": "$abort"}, tst=True)
    run(3.0)
    yield from sent


def task_example_messages() -> Iterator[tuple[str, bytes]]:
    """A start-task of every task of section 9, with the example of its specification."""
    for spec in taskspec.task_specs():
        yield ADDRESS.topic("exec/command"), orjson.dumps({
            "com-uuid": str(uuid.uuid4()), "command": "start-task", "sender": "op0",
            "task-uuid": str(uuid.uuid4()), "execution-unit": "dji0",
            "task": {"name": spec.name, "params": spec.example.get("params", {})}})


def test_every_rule_a_valid_message_can_reach_is_reported_examined() -> None:
    validator = Validator()
    examined: set[str] = set()
    valid = 0
    for topic, payload in [*corpus_messages(), *reference_unit_messages(),
                           *task_example_messages()]:
        v = validator.validate(topic, payload, None)
        if v.ok:
            valid += 1
            examined.update(validator.examined(v))
    nodes = schema_rules()
    expected = {rule for rule, where in nodes.items()
                if not all(only_when_violated(w) for w in where)}
    expected |= CONTENT_RULES
    expected |= {*UNIT_NAMING_RULES, "MSG-001", "MSG-002", "MSG-003", "MSG-004"}
    missing = sorted(expected - examined)
    assert valid > 100
    assert not missing, "reachable by a valid message, yet never examined: " + ", ".join(
        f"{r} ({', '.join(nodes.get(r, ['in code']))})" for r in missing)


def test_a_valid_message_has_the_types_its_content_rules_examine() -> None:
    """The examined cache (``checks/shapes.py``) leaves the content fields' types out of the
    shape of a message with no violation: it relies on this. Every valid message of the
    corpus and the reference unit, its content field set to a value of another JSON type,
    either has the type the content rule examines or is no longer valid."""
    from conformance.content import CONTENT_CHECKS

    other_values: list[Any] = ["text", 1.5, 7, True, None, [1], {"a": 1}]
    validator = Validator()
    tried = set()
    for topic, raw in (*corpus_messages(), *reference_unit_messages()):
        v = validator.validate(topic, raw, None)
        check = CONTENT_CHECKS.get(v.topic.kind)
        if check is None or v.violations or type(v.message) is not dict:
            continue
        for rule, field, types in check.examines:
            if field not in v.message:
                continue
            tried.add(rule)
            for value in other_values:
                if type(value) in types:
                    continue
                changed = orjson.dumps({**v.message, field: value})
                assert validator.validate(topic, changed, None).violations, (
                    f"{topic}: {field}={value!r} is valid, but {rule} examines only "
                    f"{[t.__name__ for t in types]}")
    assert tried == CONTENT_RULES

"""Every schema keyword that its rule's quote does not state is a condition of its own, with
its own basis (``x-condition``/``x-conditions`` in the schema, ``[[rule.condition]]`` in the
catalogue): the schemas are walked, and a bound, a non-empty string or a uniqueness demanded
under a stated or implied rule without a decided condition of its own fails here."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

import orjson

from conformance.judge import violation_verdict
from conformance.rules import CATALOGUE, Severity
from conformance.validator import Validator
from conformance.violation import Verdict

# Keywords that add a bound, a length or a uniqueness: what a quote of the spec rarely states.
BOUNDS = {"uniqueItems", "minLength", "maxLength", "minItems", "maxItems", "minimum", "maximum",
          "exclusiveMinimum", "exclusiveMaximum", "multipleOf", "minProperties",
          "maxProperties"}
# The shared definitions (common.json) carry no rule of their own: each is judged under the
# rule of the node that refers to it, whose words they follow (a name, a positive rate).
SHARED = "common.json"


def schemas() -> dict[str, Any]:
    root = resources.files("conformance.schemas") / "messages"
    return {f.name: json.loads(f.read_text(encoding="utf-8"))
            for f in root.iterdir() if f.name.endswith(".json")}


def walk(node: Any, rule: str | None, condition: str, where: str, out: list) -> None:
    """(where, keyword, rule, condition) of every bound keyword, with the rule and condition
    that govern it as ``conformance.schema.rule_annotations`` reads them."""
    if isinstance(node, list):
        for i, child in enumerate(node):
            walk(child, rule, condition, f"{where}/{i}", out)
        return
    if not isinstance(node, dict):
        return
    if "x-rule" in node:
        rule, condition = node["x-rule"], ""
    condition = node.get("x-condition", condition)
    named = node.get("x-conditions", {})
    for keyword in BOUNDS & set(node):
        out.append((where, keyword, rule, named.get(keyword, condition)))
    for key, child in node.items():
        if key not in ("x-conditions",):
            walk(child, rule, condition, f"{where}/{key}", out)


def test_every_bound_under_a_stated_or_implied_rule_is_a_decided_condition() -> None:
    found, unknown = [], []
    for name, schema in schemas().items():
        if name == SHARED:
            continue
        out: list = []
        walk(schema, None, "", name, out)
        for where, keyword, rule, condition in out:
            r = CATALOGUE.get(rule or "")
            assert r is not None, f"{where}: {keyword} under no rule"
            try:
                decided = r.decided(condition)
            except KeyError:
                unknown.append(f"{where}: {rule} has no condition {condition!r}")
                continue
            if not decided:
                found.append(f"{where}: {keyword} judged as {rule}'s own words ({r.basis.value})")
    assert not unknown, "\n".join(unknown)
    assert not found, "\n".join(found)


def verdicts(topic: str, payload: dict[str, Any]) -> dict[tuple[str, str], Verdict]:
    rules = Validator().validate(topic, orjson.dumps(payload), 1.0).violations
    return {(v.rule, v.condition): violation_verdict(
        CATALOGUE[v.rule], Severity.ERROR, strict=False, condition=v.condition) for v in rules}


COM = "a1587d98-b253-4e8a-bb8c-c937693881c0"
OTHER = "b1587d98-b253-4e8a-bb8c-c937693881c0"


def test_a_tst_response_outside_14_4_s_examples_warns_and_its_empty_fail_reason_too() -> None:
    """14.4 gives examples ('ok', 'started'), no closed list, and no non-empty fail-reason:
    both are TST-002's decided conditions (warn), not its words."""
    topic = "waraps/unit/air/simulation/dji0/tst/response"
    assert verdicts(topic, {"com-uuid": OTHER, "response": "failed", "response-to": COM,
                            "fail-reason": ""}) == {("TST-002", "fail-reason"): Verdict.WARN}
    assert verdicts(topic, {"com-uuid": OTHER, "response": "accepted",
                            "response-to": COM}) == {("TST-002", "vocabulary"): Verdict.WARN}
    assert verdicts(topic, {"com-uuid": OTHER, "response": "ok", "response-to": COM}) == {}
    assert verdicts(topic, {"com-uuid": OTHER, "response-to": COM}) == {
        ("TST-002", ""): Verdict.FAIL}


def test_a_sensor_listed_twice_warns() -> None:
    topic = "waraps/unit/air/simulation/dji0/sensor_info"
    got = verdicts(topic, {"name": "dji0", "rate": 1.0, "agent-uuid": COM,
                           "sensor-data-provided": ["position", "position"], "stamp": 1.0,
                           "type": "SensorInfo"})
    assert got == {("SI-001", "unique"): Verdict.WARN}

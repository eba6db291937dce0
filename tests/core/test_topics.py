"""Topic grammar of spec section 3 (conformance.topics)."""

from __future__ import annotations

import pytest

from conformance.topics import TopicError, TopicKind, UnitAddress, naming_violations, parse_topic

UNIT = "waraps/unit/air/simulation/dji0"


@pytest.mark.parametrize(("sub", "kind"), [
    ("heartbeat", TopicKind.HEARTBEAT), ("sensor_info", TopicKind.SENSOR_INFO),
    ("sensor.info", TopicKind.SENSOR_INFO), ("direct_execution_info", TopicKind.DIRECT_EXECUTION_INFO),
    ("tst_execution_info", TopicKind.TST_EXECUTION_INFO), ("sensor/position", TopicKind.SENSOR),
    ("exec/command", TopicKind.EXEC_COMMAND), ("exec/response", TopicKind.EXEC_RESPONSE),
    ("exec/feedback", TopicKind.EXEC_FEEDBACK), ("tst/command", TopicKind.TST_COMMAND),
    ("tst/response", TopicKind.TST_RESPONSE), ("tst/feedback", TopicKind.TST_FEEDBACK),
    ("status", TopicKind.UNKNOWN), ("sensor", TopicKind.UNKNOWN), ("sensor/a/b", TopicKind.UNKNOWN),
])
def test_every_subtopic_of_section_3_is_classified(sub: str, kind: TopicKind) -> None:
    parsed = parse_topic(f"{UNIT}/{sub}")
    assert parsed.kind is kind
    assert parsed.unit == UnitAddress.parse(UNIT)


def test_section_3_examples_follow_the_naming_conventions() -> None:
    for sub in ("heartbeat", "sensor_info", "direct_execution_info", "tst_execution_info",
                "sensor/position", "sensor/camera_url", "exec/command", "exec/response",
                "exec/feedback"):
        assert naming_violations(f"{UNIT}/{sub}") == []
    # PREFIX1 examples of 3.1 carry '-': exempt from TOPIC-003.
    assert naming_violations("waraps-demo-2021/unit/surface/real/piraya0/heartbeat") == []


@pytest.mark.parametrize(("topic", "rules"), [
    ("/waraps/unit/air/simulation/dji0/heartbeat", {"TOPIC-001"}),
    ("waraps/unit/air/simulation/DJI0/heartbeat", {"TOPIC-002"}),
    ("waraps/unit/air/simulation/dji0/sensor/battery-state", {"TOPIC-003"}),
    ("waraps/unit/air/simulation/dji0/sensor/batteryState", {"TOPIC-002"}),
    ("waraps/unit/air/simulation/heartbeat", {"TOPIC-004"}),
    ("waraps/unit/air//dji0/heartbeat", {"TOPIC-004"}),
    ("waraps/unit/car/simulation/dji0/heartbeat", {"TOPIC-005"}),
    ("waraps/unit/air/test/dji0/heartbeat", {"TOPIC-006"}),
    ("waraps/unit/air/simulation/dji0/status", {"TOPIC-007"}),
    ("waraps/unit/air/simulation/dji0/sensor/pos ition", {"TOPIC-008", "TOPIC-003"}),
    ("waraps/unit/air/simulation/dji0/sensor.info", {"ERR-001"}),
])
def test_each_naming_rule_fails_on_its_fault(topic: str, rules: set[str]) -> None:
    assert {v.rule for v in naming_violations(topic)} == rules


def test_unit_address_round_trip_and_errors() -> None:
    address = UnitAddress.parse("waraps/unit/air/real/dji0")
    assert address.topic("exec/command") == "waraps/unit/air/real/dji0/exec/command"
    assert address.is_real
    with pytest.raises(TopicError, match="PREFIX1/unit/TYPE/ROLE/UNIT"):
        UnitAddress.parse("waraps/dji0")
    with pytest.raises(TopicError, match="agent type 'car'"):
        UnitAddress.parse("waraps/unit/car/real/dji0")


def test_the_levels_of_5_1_are_the_heartbeat_schemas() -> None:
    from conformance import schema
    from conformance.topics import LEVELS

    # The hand-edited schema and the code name the same levels, in 5.1's order.
    assert tuple(schema.load("messages/common.json")["$defs"]["levels"]["enum"]) == LEVELS


@pytest.mark.parametrize(("text", "ok"), [
    ("#", True), ("waraps/#", True), ("+", True), ("+/unit/+/real/#", True), ("a//b", True),
    ("a/+x/b", False), ("a/x+", False), ("a#", False), ("#/a", False), ("a/#/b", False),
    ("", False), ("a/\x00", False), ("a/\ud800", False), ("a" * 65536, False),
])
def test_a_subscription_filter_is_checked_as_mqtt_does(text: str, ok: bool) -> None:
    from conformance.topics import filter_problem

    assert (filter_problem(text) is None) is ok


@pytest.mark.parametrize("text", ["waraps/unit/air/real/a+b", "waraps/unit/air/real/#",
                                  "waraps/unit/air/real/a\x00", "waraps/unit/air/real/\udc80",
                                  "w+/unit/air/real/a"])
def test_a_unit_address_holds_nothing_a_topic_cannot(text: str) -> None:
    with pytest.raises(TopicError):
        UnitAddress.parse(text)


def test_a_name_in_another_script_is_lowercase_words_and_only_topic_008_s_decision():
    """3.2 asks for lowercase words joined by '_' and names no character set: 'båt0' breaks
    no stated naming rule (TOPIC-003 passes); refusing non-ASCII is TOPIC-008's decision."""
    from conformance.judge import violation_verdict
    from conformance.profile import Profile
    from conformance.rules import CATALOGUE
    from conformance.violation import Verdict

    found = naming_violations("waraps/unit/surface/real/båt0/heartbeat")
    assert [v.rule for v in found] == ["TOPIC-008"]
    rule = CATALOGUE["TOPIC-008"]
    default, strict = Profile(), Profile(strict=True)
    assert violation_verdict(rule, default.severity_of(rule.id), strict=False) is Verdict.WARN
    assert violation_verdict(rule, strict.severity_of(rule.id), strict=True) is Verdict.FAIL
    assert [v.rule for v in naming_violations("waraps/unit/surface/real/bat-0/heartbeat")] == [
        "TOPIC-003"]


def test_a_near_miss_of_a_role_or_type_is_told_what_it_may_mean() -> None:
    """The RISE agent's role 'simulated': TOPIC-006 says which of 3.1's roles it may mean;
    nothing is suggested where nothing is close."""
    (role,) = naming_violations("waraps/unit/air/simulated/dss001/heartbeat")
    assert role.rule == "TOPIC-006" and role.detail.endswith("did you mean 'simulation'?")
    (kind,) = naming_violations("waraps/unit/aire/real/dji0/heartbeat")
    assert kind.rule == "TOPIC-005" and kind.detail == "did you mean 'air'?"
    (far,) = naming_violations("waraps/unit/hexacopter/real/dji0/heartbeat")
    assert far.rule == "TOPIC-005" and "did you mean" not in far.detail

"""Rules the validator examined on a message pass (and only those): a skip never becomes a
pass just because a message of some kind went by."""

from __future__ import annotations

import uuid
from collections import Counter

from conformance.checks import Monitor
from conformance.message import Message
from conformance.validator import Examined, Validator
from conformance.violation import Verdict


def examined_by_validator(v):
    return set(Validator().examined(v))


class NothingExamined(Validator):
    """A validator that reports no rule examined on any message."""

    def examined(self, v):
        return Examined((), ())


def examined_counts(m: Monitor) -> Counter[str]:
    """How many times each rule was examined, over every row of the report."""
    return sum((Counter(unit.examined) for unit in m.report().units.values()), Counter())


def rules(m: Monitor, stream):
    return m.report().units[str(stream.address)].rules


def test_schema_rules_pass_on_a_healthy_unit(stream):
    m = Monitor()
    stream.feed(m, stream.alive(3))
    r = rules(m, stream)
    for rid in ("HB-001", "HB-002", "HB-007", "HB-009", "SI-001", "DEI-001", "SENS-001",
                "SENS-002", "SENS-003", "MSG-003", "MSG-005", "MSG-006", "TOPIC-004"):
        assert r[rid].verdict is Verdict.PASS, (rid, r[rid])
    for rid in ("TASK-001", "EXEC-002", "EXEC-FB-001", "TST-001", "SENS-004"):
        assert r[rid].verdict is Verdict.SKIP, (rid, r[rid])


def test_a_conditional_rule_is_examined_only_when_its_condition_holds(stream):
    v = Validator()
    cu = str(uuid.uuid4())
    pong = stream.response(0, cu)
    failed = stream.response(0, cu, response="failed", **{"fail-reason": "busy"})
    assert "EXEC-007" not in examined_by_validator(v.validate(pong.topic, pong.payload, pong.time))
    assert "EXEC-007" in examined_by_validator(v.validate(failed.topic, failed.payload,
                                                          failed.time))


def test_command_dispatch_examines_the_commands_own_rules(stream):
    v = Validator()
    ping = stream.command(0, "ping")
    start = stream.command(0, "start-task", **{"task-uuid": str(uuid.uuid4()), "task": {
        "name": "move-to", "params": {"speed": "fast", "waypoint": {
            "latitude": 58.4, "longitude": 15.6, "altitude": 10.0, "rostype": "GeoPoint"}}}})
    on_ping = examined_by_validator(v.validate(ping.topic, ping.payload, ping.time))
    on_start = examined_by_validator(v.validate(start.topic, start.payload, start.time))
    assert "EXEC-001" in on_ping and "TASK-001" not in on_ping
    assert "TASK-001" in on_start


def test_undecodable_payload_examines_only_what_was_reached(stream):
    v = Validator()
    bad = stream.msg("heartbeat", b"{not json", 0)
    ex = examined_by_validator(v.validate(bad.topic, bad.payload, bad.time))
    assert "HB-001" not in ex and "MSG-004" in ex and "TOPIC-001" in ex


def test_an_empty_list_first_does_not_hide_the_rule_from_later_messages(stream):
    v = Validator()
    empty = stream.heartbeat(0, levels=[])
    full = stream.heartbeat(1)
    assert "HB-007" not in examined_by_validator(v.validate(empty.topic, empty.payload, 0.0))
    assert "HB-007" in examined_by_validator(v.validate(full.topic, full.payload, 1.0))


def test_examined_rules_cached_per_topic_match_the_rules_of_each_message(stream):
    """The Monitor caches examined rules per topic by message shape (and the values that
    decided a branch): over varied messages in shuffled order, its counts equal those of
    asking the validator about each one."""
    import random

    import orjson

    base = [stream.heartbeat(0), stream.sensor_info(0), stream.direct_execution_info(0),
            stream.position(58.4, 15.6, 0), stream.sensor("speed", 1.5, 0),
            stream.sensor("heading", 90, 0), stream.response(0, str(uuid.uuid4())),
            stream.response(0, str(uuid.uuid4()), response="failed",
                            **{"fail-reason": "busy"}),
            stream.feedback(0, str(uuid.uuid4()), "running"), stream.command(0, "ping"),
            stream.command(0, "signal-task", signal="$abort")]
    variants = []  # (topic, message): each message, without each key, each value replaced
    for msg in base:
        m = orjson.loads(msg.payload)
        variants.append((msg.topic, m))
        if isinstance(m, dict):
            for key, value in m.items():
                variants.append((msg.topic, {k: x for k, x in m.items() if k != key}))
                for other in (None, "", 0, [], {}, [value], "x" * 70):
                    variants.append((msg.topic, {**m, key: other}))
        else:
            variants += [(msg.topic, x) for x in ("1.5", None, -1, True)]
    order = random.Random(7).sample(variants, len(variants)) * 3
    monitor, validator = Monitor(), Validator()
    # What the Monitor's own checks examined (rates, conversations...) is counted by a Monitor
    # whose validator examines nothing; the rest of a report's counts is the validator's.
    own_checks = Monitor(validator=NothingExamined())
    expected: Counter[str] = Counter()
    for n, (topic, message) in enumerate(order):
        raw, t = orjson.dumps(message), 1_700_000_000.0 + n
        expected.update(examined_by_validator(validator.validate(topic, raw, t)))
        monitor.feed(Message(t, topic, raw))
        own_checks.feed(Message(t, topic, raw))
    # Every row counts: commands are counted on their commander's (what is wrong in them is
    # its fault).
    got = examined_counts(monitor)
    got.subtract(examined_counts(own_checks))
    assert got == expected and len(order) > 500

"""Monitor: routing per unit, verdict semantics (a skip never becomes a pass), record(), gaps."""

from __future__ import annotations

import pytest

from conformance.checks import Monitor, covered_rules
from conformance.conclusion import conclude
from conformance.message import Message
from conformance.profile import Profile
from conformance.report_meta import RunMeta
from conformance.topics import UnitAddress
from conformance.violation import Observed, Verdict, Violation


def rules_of(monitor: Monitor, address: UnitAddress):
    return monitor.report().units[str(address)].rules


def test_healthy_unit_passes_what_was_examined(stream):
    m = Monitor()
    found = stream.feed(m, stream.alive(15))
    assert [v for v in found if v.rule in covered_rules()] == []
    rules = rules_of(m, stream.address)
    for rid in ("HB-003", "SI-002", "DEI-002", "HB-006", "HB-010", "HB-008", "TOPIC-001"):
        assert rules[rid].verdict is Verdict.PASS, (rid, rules[rid])


def test_never_examined_is_skip_with_a_reason(stream):
    m = Monitor()
    stream.feed(m, [stream.heartbeat(0)])
    rules = rules_of(m, stream.address)
    assert rules["HB-003"].verdict is Verdict.SKIP
    assert "only 0 intervals" in rules["HB-003"].reason
    assert rules["EXEC-QUERY-002"].verdict is Verdict.SKIP
    assert "needs a stimulus: run pytest --unit" in rules["EXEC-QUERY-002"].reason
    # A conversation rule is judged where the traffic holds the command: here it does not.
    assert rules["EXEC-PING-001"].verdict is Verdict.SKIP
    assert "no command to this unit" in rules["EXEC-PING-001"].reason


def test_unclaimed_level_is_skip_not_claimed(stream):
    stream.levels = ["sensor"]
    m = Monitor()
    stream.feed(m, stream.alive(3, info=False, sensors=False))
    rules = rules_of(m, stream.address)
    assert rules["DEI-002"].verdict is Verdict.SKIP
    assert rules["DEI-002"].reason == "not claimed: unit declares no 'direct execution' level"


def test_a_rule_of_an_unclaimed_level_is_not_claimed_in_lint_too(stream):
    """TST rules of a unit without 'tst execution' (the public L2 agents) read 'not claimed'
    in lint, not 'needs a stimulus' or 'no command seen' as if a certification would judge
    them; a claimed level's conversation rule still says what lint lacked."""
    m = Monitor()  # lint
    stream.feed(m, stream.alive(3))
    rules = rules_of(m, stream.address)
    for rid in ("TST-004", "TST-005", "TST-010"):
        assert rules[rid].reason == "not claimed: unit declares no 'tst execution' level", rid
    assert "no command to this unit" in rules["EXEC-PING-001"].reason
    assert "needs a stimulus" in rules["EXEC-QUERY-002"].reason


def test_active_rule_in_certification_is_skip_until_recorded(stream):
    m = Monitor(kind="certification", units=[stream.address])
    stream.feed(m, [stream.heartbeat(0)])
    assert rules_of(m, stream.address)["EXEC-PING-001"].verdict is Verdict.SKIP
    m.record(stream.address, "EXEC-PING-001", seen=Observed.EXAMINED)
    assert rules_of(m, stream.address)["EXEC-PING-001"].verdict is Verdict.PASS
    m.record(stream.address, "REBOOT-001", seen=Observed.UNTESTABLE,
             reason="the profile names no reboot command")
    r = rules_of(m, stream.address)["REBOOT-001"]
    assert (r.verdict, r.reason) == (Verdict.COULD_NOT_TEST, "the profile names no reboot command")
    m.record(stream.address, "EXEC-PING-002", violation=Violation.of(
        "EXEC-PING-002", expected="response-to = com-uuid", observed="other"))
    r = rules_of(m, stream.address)["EXEC-PING-002"]
    assert r.verdict is Verdict.FAIL and r.violations[0].unit == str(stream.address)
    assert conclude(m.report()).exit_code == 1


def test_warning_rule_violation_warns_and_strict_profile_fails(stream):
    msgs = [stream.msg("sensor.info", {"name": "dji0"}, 0)]
    default = Monitor()
    stream.feed(default, msgs)
    assert rules_of(default, stream.address)["ERR-001"].verdict is Verdict.WARN
    strict = Monitor(Profile(severity={"ERR-*": "error"}))
    stream.feed(strict, msgs)
    assert rules_of(strict, stream.address)["ERR-001"].verdict is Verdict.FAIL


def test_units_filter_ignores_other_units(stream):
    other = UnitStream_for(stream, "other0")
    m = Monitor(units=[stream.address])
    assert m.feed(other.heartbeat(0)) == []
    stream.feed(m, [stream.heartbeat(0)])
    assert m.units() == [stream.address]


def UnitStream_for(stream, name):
    return type(stream)(stream.address.with_name(name))


def test_unattributed_topics_are_reported_apart():
    m = Monitor()
    found = m.feed(Message(1.0, "/waraps/unit/air", b"{}"))
    assert {v.rule for v in found} >= {"TOPIC-001"}
    report = m.report()
    assert "(unattributed)" in report.units
    assert report.units["(unattributed)"].rules["TOPIC-001"].verdict is Verdict.FAIL
    assert m.units() == []


def test_state_is_readable_for_the_active_suite(stream):
    m = Monitor()
    stream.feed(m, stream.alive(2))
    s = m.state(stream.address)
    assert s.agent_uuid == stream.agent_uuid
    assert s.levels == ("sensor", "direct execution")
    assert s.declared_rates["heartbeat"] == 1.0
    assert s.tasks_available == {"move-to": ("$abort", "$enough")}
    assert s.sensors_listed == ("position", "heading", "course", "speed")
    assert s.position is not None and s.last_heartbeat is not None
    assert m.state(stream.address.with_name("nobody")).message_count == 0


def test_evidence_is_bounded_but_counted(stream):
    m = Monitor()
    for i in range(100):
        m.feed(stream.msg("Bad_Topic", {}, i))
    u = m.report().units[str(stream.address)]
    assert u.violation_counts["TOPIC-002"] == 100
    assert len(u.rules["TOPIC-002"].violations) == 20


def test_unexamined_and_gaps_reach_the_report(stream):
    m = Monitor()
    m.unexamined(7)
    m.connection_gap(5.0, 6.0)
    r = m.report(RunMeta(source="me"), broker="mqtt://user:secret@127.0.0.1:1883")
    assert r.unexamined == 7 and r.gaps == [(5.0, 6.0)]
    assert r.broker == "mqtt://user@127.0.0.1:1883"
    assert r.meta == RunMeta(source="me")
    with pytest.raises(TypeError, match="operator"):  # meta is a RunMeta's, never a loose key
        m.report(operator="me")

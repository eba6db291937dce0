"""Memory stays bounded for any run length and any traffic: every history is capped."""

from __future__ import annotations

import uuid

import orjson

from conformance.checks import Monitor, base, conversation, routes, rows
from conformance.checks.conversation import CONVERSATIONS
from conformance.message import Message
from conformance.topics import UnitAddress

T0 = 1_700_000_000.0


def test_hostile_variety_is_capped(stream, monkeypatch):
    monkeypatch.setattr(conversation, "COMMANDS_KEPT", 32)
    monkeypatch.setattr(conversation, "TASKS_KEPT", 32)
    monkeypatch.setattr(base, "MAX_SENSORS", 16)
    monkeypatch.setattr(base, "MAX_KIND_COUNTS", 8)
    monkeypatch.setattr(routes, "MAX_UNITS", 8)
    monkeypatch.setattr(routes, "MAX_TOPICS", 50)
    m = Monitor()
    u = stream.address
    for i in range(400):
        t = T0 + i * 0.01
        m.feed(Message(t, u.topic(f"sensor/s{i}"), b"1.0"))
        m.feed(Message(t, u.topic("exec/command"), orjson.dumps(
            {"com-uuid": str(uuid.uuid4()), "command": f"c{i}", "sender": "x"})))
        m.feed(Message(t, u.topic("exec/feedback"), orjson.dumps(
            {"agent-uuid": stream.agent_uuid, "com-uuid": str(uuid.uuid4()),
             "status": "finished", "task-uuid": str(uuid.uuid4())})))
        m.feed(Message(t, UnitAddress(u.prefix, "air", "simulation", f"n{i}").topic("heartbeat"),
                       b"{}"))
        m.feed(Message(t, u.topic("Bad"), b"{}"))  # TOPIC-002 every time
    s = m.state(u)
    assert len(s.sensors_seen) == 16 and len(s.counts) == 8
    kept = s.stash[CONVERSATIONS]
    assert len(kept.commands) == 32 and len(kept.tasks) == 32
    assert len(m.units()) == 8
    assert m.topics_cached() == 50
    report = m.report()
    assert report.unexamined > 0  # messages of units beyond the cap are counted, not lost
    unit = report.units[str(u)]
    assert unit.violation_counts["TOPIC-002"] == 400
    assert len(unit.rules["TOPIC-002"].violations) == rows.MAX_EVIDENCE


def test_gaps_are_capped_and_a_point_gap_excludes_its_interval(stream):
    m = Monitor()
    for i in range(3000):
        m.connection_gap(i * 10.0, i * 10.0 + 1)
    assert len(m.ctx.gaps) <= 1000
    point = Monitor()
    stream.levels = []
    point.connection_gap(T0 + 5.5, T0 + 5.5)  # the suite marks a disconnect or reboot at once
    found = stream.feed(point, [stream.heartbeat(t) for t in (0, 1, 2, 3, 4, 5, 9, 10, 11)])
    assert not {v.rule for v in found} & {"HB-010", "HB-003"}


def test_commands_kept_cost_little_memory_each(stream):
    """Conversations keep thousands of commands per unit: a digest and an excerpt each, never the
    content (a command may be 1 MiB; orjson's output holds a 4 KiB buffer)."""
    import tracemalloc

    m = Monitor()
    u = stream.address
    big = "x" * 100_000
    msgs = [Message(T0 + i * 0.01, u.topic("exec/command"), orjson.dumps(
        {"com-uuid": str(uuid.uuid4()), "command": "ping", "sender": "x", "pad": big}))
        for i in range(300)]
    m.feed(msgs[0])
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for msg in msgs[1:]:
            m.feed(msg)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(m.state(u).stash[CONVERSATIONS].commands) == 300
    assert grown < 300 * 1500, f"{grown / 299:.0f} bytes per command kept"


def test_kept_evidence_full_of_decided_findings_keeps_room_for_one_that_fails():
    """The evidence of a rule is capped (``MAX_EVIDENCE``): when it is full of decided
    findings that only warn, a later finding of the rule's own words takes the place of the
    latest of them, so what the verdict stands on is shown; the count counts all."""
    from conformance.violation import Violation

    record = rows.RuleRecord()
    listed = [Violation.of("SI-004", condition="listed", expected="listed",
                            observed=f"missing {i}")
              for i in range(rows.MAX_EVIDENCE + 3)]
    for v in listed:
        record.add(v)
    stated = Violation.of("SI-004", expected="published", observed="nothing on heading")
    record.add(stated)
    assert record.count == rows.MAX_EVIDENCE + 4 and record.firm == 1
    assert len(record.evidence) == rows.MAX_EVIDENCE
    assert record.evidence[-1] is stated and listed[rows.MAX_EVIDENCE - 1] not in record.evidence
    record.add(Violation.of("SI-004", expected="published", observed="nothing on course"))
    assert len(record.evidence) == rows.MAX_EVIDENCE and record.firm == 2

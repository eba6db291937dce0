"""Each finding is charged to the party whose message it is about (docs/ARCHITECTURE.md 'Whose fault
it is'; docs/FIELD-NOTES.md precision: whose topic, operators): a unit's own topic is the unit's,
once, never each commander's; a command on a topic of its sender's making is that commander's."""

from __future__ import annotations

import uuid

import orjson

from conformance.checks import Monitor
from conformance.message import Message
from conformance.profile import Profile
from conformance.topics import UnitAddress
from conformance.violation import Verdict

PROFILE = Profile(response_timeout=1.0, feedback_timeout=3.0)


def _report(stream, extra):
    m = Monitor(PROFILE)
    stream.feed(m, stream.alive(12.0) + extra)
    m.finish()
    return m.report().units


def _pings(stream, n, sender="op0"):
    out = []
    for i in range(n):
        com = str(uuid.uuid4())
        out.append(stream.msg("exec/command", {"com-uuid": com, "command": "ping",
                                               "sender": sender}, 1.5 + i * 0.5))
        out.append(stream.response(1.6 + i * 0.5, com))
    return out


def _simulated(stream):
    """The stream's unit under the role 'simulated' (3.1 says simulation)."""
    a = stream.address
    stream.address = UnitAddress(a.prefix, a.agent_type, "simulated", a.name)
    return stream


def test_a_units_own_topic_fault_is_the_units_not_each_commanders(stream):
    stream = _simulated(stream)
    units = _report(stream, _pings(stream, 16) + _pings(stream, 2, sender="op1"))
    unit = units[str(stream.address)].rules["TOPIC-006"]
    assert unit.verdict is Verdict.WARN or unit.verdict is Verdict.FAIL
    for name in ("commander op0", "commander op1"):
        commander = units[name]
        assert commander.rules.get("TOPIC-006") is None or \
            commander.rules["TOPIC-006"].verdict not in (Verdict.FAIL, Verdict.WARN), name
        assert not commander.violation_counts.get("TOPIC-006"), name


def test_a_unit_only_addressed_by_a_bad_topic_gets_the_finding_once(stream):
    stream = _simulated(stream)
    m = Monitor(PROFILE)
    stream.feed(m, [c for c in _pings(stream, 4) if c.topic.endswith("/command")])
    m.finish()
    units = m.report().units
    assert units[str(stream.address)].violation_counts.get("TOPIC-006") == 1
    assert not units["commander op0"].violation_counts.get("TOPIC-006")


def test_an_operators_command_on_a_topic_of_its_own_is_on_its_row(stream, prefix):
    """An operator publishing commands on '.../None/command' (seen in the field)."""
    t0 = stream.msg("heartbeat", {}, 0.0).time
    body = {"com-uuid": str(uuid.uuid4()), "command": "ping", "sender": "op0"}
    msgs = [Message(t0 + t, f"{prefix}/unit/ground/real/None/command", orjson.dumps(body), 0,
                    False) for t in (1.0, 2.0)]
    m = Monitor(PROFILE)
    for msg in msgs:
        m.feed(msg)
    m.finish()
    units = m.report().units
    assert units["commander op0"].violation_counts.get("TOPIC-002") == 2
    assert not any(u.violation_counts.get("TOPIC-002") for k, u in units.items()
                   if k != "commander op0")


def test_the_suites_own_commands_and_probes_are_no_commanders_fault(stream):
    """A recording made during a certification holds the suite's deliberate probes (its
    sender 'waraps-conformance'; unreadable payloads once it was seen commanding the unit):
    no commander row fails for them; the unit's answers are still judged."""
    from conformance.checks.suite_commands import SENDER, UNREADABLE

    ping = {"com-uuid": str(uuid.uuid4()), "command": "ping", "sender": SENDER}
    probes = [stream.msg("exec/command", ping, 1.5), stream.response(1.6, ping["com-uuid"])]
    probes += [stream.msg("exec/command", payload, 2.0 + i * 0.1)
               for i, (_, payload) in enumerate(UNREADABLE)]
    bad = str(uuid.uuid4())
    probes.append(stream.msg("exec/command", orjson.dumps(
        {"com-uuid": bad, "sender": SENDER, "command": "waraps-conformance-no-such-command"}),
        3.0))
    probes.append(stream.msg("exec/command", f'{{"com-uuid": "{bad}x", "sender": "{SENDER}", '
                                             f'"command": "start-ta'.encode(), 3.1))
    units = _report(stream, probes)
    commanders = [k for k, u in units.items() if u.party == "commander"]
    assert not any(units[k].violation_counts for k in commanders), commanders
    unit = units[str(stream.address)]
    assert unit.rules["EXEC-PING-001"].verdict is Verdict.PASS
    assert unit.rules["EXEC-ROBUST-002"].verdict is Verdict.WARN  # unanswered: the unit's
    # The same probes from another commander are that commander's faults.
    others = [stream.msg("exec/command", payload, 2.0 + i * 0.1)
              for i, (_, payload) in enumerate(UNREADABLE)]
    units = _report(stream, others)
    assert sum(sum(u.violation_counts.values()) for u in units.values()
               if u.party == "commander") >= len(UNREADABLE)

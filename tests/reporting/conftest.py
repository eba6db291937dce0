"""A run report with something of everything: passes, failures, warnings, skips, rates, a
hostile payload, two units and an unattributed topic."""

from __future__ import annotations

import uuid

import orjson
import pytest

from conformance.checks import Monitor
from conformance.client import Message
from conformance.results import RunReport
from conformance.topics import UnitAddress
from conformance.violation import Observed

T0 = 1_700_000_000.0
HOSTILE = '<script>alert("x")</script></pre><img src=x onerror=alert(1)>\x00\x1b[31m&amp;'


def heartbeat(unit: UnitAddress, t: float, agent_uuid: str, rate: float = 1.0) -> Message:
    return Message(T0 + t, unit.topic("heartbeat"), orjson.dumps({
        "agent-type": unit.agent_type, "agent-uuid": agent_uuid, "levels": [],
        "name": unit.name, "rate": rate, "stamp": T0 + t, "type": "HeartBeat"}))


@pytest.fixture
def run_report(prefix: str) -> RunReport:
    good = UnitAddress(prefix, "air", "simulation", "dji0")
    slow = UnitAddress(prefix, "surface", "real", "piraya0")
    m = Monitor(kind="lint")
    a, b = str(uuid.uuid4()), str(uuid.uuid4())
    for i in range(15):
        m.feed(heartbeat(good, i, a))
        m.feed(heartbeat(slow, i * 3.5, b))  # declares 1 Hz, publishes at 0.29 Hz: HB-003 fails
    m.feed(Message(T0 + 3.5, slow.topic("sensor/Camera"), HOSTILE.encode()))  # TOPIC-002 fails
    m.feed(Message(T0 + 4.0, f"{prefix}/unit/air", b"{}"))
    m.record(good, "REBOOT-001", seen=Observed.UNTESTABLE, reason="no reboot command")
    m.finish()
    return m.report(broker="mqtts://alice:s3cret@127.0.0.1:8883")

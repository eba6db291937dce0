"""The Monitor on messages from real brokers (embedded amqtt and Mosquitto): the passive checks
judge what a subscriber really receives (retain flags, arrival times)."""

from __future__ import annotations

import threading
import time
import uuid

import orjson

from conformance.checks import Monitor
from conformance.client import BrokerURL, Message, MqttClient
from conformance.topics import UnitAddress
from conformance.violation import Verdict


def heartbeat(unit: UnitAddress, agent_uuid: str, stamp: float) -> bytes:
    return orjson.dumps({"agent-type": unit.agent_type, "agent-uuid": agent_uuid, "levels": [],
                         "name": unit.name, "rate": 1.0, "stamp": stamp, "type": "HeartBeat"})


def test_monitor_judges_real_traffic(broker_url: str, unit_address: UnitAddress):
    received: list[Message] = []
    arrived = threading.Condition()

    def on_message(m: Message) -> None:
        with arrived:
            received.append(m)
            arrived.notify_all()

    topic = unit_address.topic("heartbeat")
    url = BrokerURL.parse(broker_url)
    publisher = MqttClient(url, may_publish=lambda t: t == topic).connect()
    subscriber = MqttClient(url, on_message=on_message).connect()
    try:
        # A stale retained heartbeat (MSG-007), then a burst: 12 heartbeats declaring 1 Hz
        # arrive within milliseconds (HB-003), and the agent-uuid changes three times without
        # a silence (HB-006: once is a fast restart, twice may be two restarts: a warning).
        publisher.publish(topic, heartbeat(unit_address, str(uuid.uuid4()), time.time() - 600),
                          retain=True)
        subscriber.subscribe(f"{unit_address.prefix}/#")
        first, *later = (str(uuid.uuid4()) for _ in range(4))
        for i in range(14):
            publisher.publish(topic, heartbeat(
                unit_address, first if i < 11 else later[i - 11], time.time()))
        deadline = time.monotonic() + 10
        with arrived:
            while len(received) < 15 and time.monotonic() < deadline:
                arrived.wait(deadline - time.monotonic())
            got = list(received)
        assert len(got) == 15, f"only {len(got)} of 15 messages arrived"
    finally:
        subscriber.close()
        publisher.publish(topic, b"", retain=True)  # clear the retained message
        publisher.close()
    assert got[0].retain and not any(m.retain for m in got[1:])
    m = Monitor()
    for message in got:
        m.feed(message)
    m.finish()
    rules = m.report().units[str(unit_address)].rules
    assert rules["MSG-007"].verdict is Verdict.WARN
    assert rules["HB-006"].verdict is Verdict.FAIL
    assert rules["HB-003"].verdict is Verdict.FAIL
    # 12 heartbeats of the first agent: 11 intervals (the interval into the new agent-uuid
    # is a restart's, left out of the rate).
    assert "over 10 intervals" in rules["HB-003"].violations[0].observed
    assert rules["HB-001"].verdict is Verdict.PASS

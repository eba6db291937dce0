"""Synthetic message streams of one unit with controlled arrival times (no broker needed)."""

from __future__ import annotations

import uuid as uuidlib
from typing import Any

import orjson
import pytest

from conformance.checks import Monitor
from conformance.message import Message
from conformance.topics import UnitAddress

T0 = 1_700_000_000.0


class UnitStream:
    """Builds the messages of one unit: ``s.heartbeat(t)``, ``s.sensor("speed", 1.0, t)``..."""

    def __init__(self, address: UnitAddress, rate: float = 1.0,
                 levels: tuple[str, ...] = ("sensor", "direct execution")) -> None:
        self.address = address
        self.rate = rate
        self.levels = list(levels)
        self.agent_uuid = str(uuidlib.uuid4())

    def msg(self, subtopic: str, payload: Any, t: float, retain: bool = False) -> Message:
        raw = payload if isinstance(payload, bytes) else orjson.dumps(payload)
        return Message(T0 + t, self.address.topic(subtopic), raw, 0, retain)

    def heartbeat(self, t: float, *, agent_uuid: str | None = None, rate: float | None = None,
                  stamp: float | None = None, retain: bool = False,
                  levels: list[str] | None = None) -> Message:
        return self.msg("heartbeat", {
            "agent-type": self.address.agent_type, "agent-uuid": agent_uuid or self.agent_uuid,
            "levels": self.levels if levels is None else levels, "name": self.address.name,
            "rate": self.rate if rate is None else rate,
            "stamp": T0 + t if stamp is None else stamp, "type": "HeartBeat"}, t, retain)

    def sensor_info(self, t: float, sensors: list[str] | None = None, rate: float | None = None,
                    retain: bool = False, stamp: float | None = None) -> Message:
        return self.msg("sensor_info", {
            "agent-uuid": self.agent_uuid,
            "name": self.address.name, "rate": self.rate if rate is None else rate,
            "sensor-data-provided": sensors if sensors is not None else [
                "position", "heading", "course", "speed"],
            "stamp": T0 + t if stamp is None else stamp, "type": "SensorInfo"}, t, retain)

    def direct_execution_info(self, t: float, rate: float | None = None,
                              executing: list[dict[str, str]] | None = None) -> Message:
        return self.msg("direct_execution_info", {
            "agent-uuid": self.agent_uuid,
            "name": self.address.name, "rate": self.rate if rate is None else rate,
            "type": "DirectExecutionInfo", "stamp": T0 + t,
            "tasks-available": [{"name": "move-to", "signals": ["$abort", "$enough"]}],
            "tasks-executing": executing or []}, t)

    def sensor(self, name: str, value: Any, t: float, retain: bool = False) -> Message:
        return self.msg(f"sensor/{name}", value, t, retain)

    def position(self, lat: float, lon: float, t: float, alt: float = 10.0) -> Message:
        return self.sensor("position", {"latitude": lat, "longitude": lon, "altitude": alt,
                                        "rostype": "GeoPoint"}, t)

    def command(self, t: float, command: str = "ping", com_uuid: str | None = None,
                **extra: Any) -> Message:
        return self.msg("exec/command", {"com-uuid": com_uuid or str(uuidlib.uuid4()),
                                         "command": command, "sender": "commander", **extra}, t)

    def response(self, t: float, response_to: str, response: str = "pong",
                  agent_uuid: str | None = None, **extra: Any) -> Message:
        return self.msg("exec/response", {
            "agent-uuid": agent_uuid or self.agent_uuid, "com-uuid": str(uuidlib.uuid4()),
            "response": response, "response-to": response_to, **extra}, t)

    def feedback(self, t: float, task_uuid: str, status: str, agent_uuid: str | None = None,
                 com_uuid: str | None = None) -> Message:
        return self.msg("exec/feedback", {
            "agent-uuid": agent_uuid or self.agent_uuid, "com-uuid": com_uuid or str(uuidlib.uuid4()),
            "status": status, "task-uuid": task_uuid}, t)

    @staticmethod
    def feed(monitor: Monitor, messages: list[Message]) -> list:
        """Feed messages in arrival order; every violation they show."""
        found = []
        for m in sorted(messages, key=lambda m: m.time):
            found.extend(monitor.feed(m))
        return found

    def alive(self, seconds: float, *, start: float = 0.0, info: bool = True,
              sensors: bool = True) -> list[Message]:
        """A healthy unit: heartbeat and infos at the declared rate, the four sensors."""
        out: list[Message] = []
        period = 1.0 / self.rate
        n = int(seconds * self.rate) + 1
        for i in range(n):
            t = start + i * period
            out.append(self.heartbeat(t))
            if info:
                out.append(self.sensor_info(t + 0.01))
                out.append(self.direct_execution_info(t + 0.02))
            if sensors:
                out.append(self.position(58.4 + i * 1e-6, 15.6, t + 0.03))
                out.append(self.sensor("heading", 90.0, t + 0.04))
                out.append(self.sensor("course", 90.0, t + 0.05))
                out.append(self.sensor("speed", 1.0, t + 0.06))
        return out


@pytest.fixture
def stream(unit_address: UnitAddress) -> UnitStream:
    """A healthy simulated unit's message builder under this test's own prefix."""
    return UnitStream(unit_address)

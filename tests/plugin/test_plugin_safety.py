"""Safety (DESIGN): commands only to the unit under test; no motion on a real unit unless
--allow-motion AND the profile's motion-tasks say so; positions near the unit, inside the
profile's safe radius."""

from __future__ import annotations

from pathlib import Path

import orjson
import pytest
from certify_helpers import FAST, Rebooter, certify

from conformance import taskspec
from conformance.client import BrokerURL, Message, MqttClient
from conformance.scenarios.safety import MOVES_WITHOUT_TAG, Position
from conformance.sim import SimUnit

pytestmark = pytest.mark.slow


def moves(task: str) -> bool:
    try:
        return taskspec.task_spec(task).moves_unit or task in MOVES_WITHOUT_TAG
    except KeyError:
        return True


def geopoints(value: object) -> list[dict]:
    if isinstance(value, dict):
        if "latitude" in value and "longitude" in value:
            return [value]
        return [p for v in value.values() for p in geopoints(v)]
    if isinstance(value, list):
        return [p for v in value for p in geopoints(v)]
    return []


class Wire:
    """Everything published under the prefix while certifying (a read-only observer)."""

    def __init__(self, broker: str, prefix: str) -> None:
        self.messages: list[Message] = []
        self.client = MqttClient(BrokerURL.parse(broker), on_message=self.messages.append)
        self.prefix = prefix

    def __enter__(self) -> Wire:
        self.client.connect()
        self.client.subscribe(f"{self.prefix}/#")
        return self

    def __exit__(self, *exc: object) -> None:
        self.client.close()

    def commands(self) -> list[tuple[Message, dict]]:
        out = []
        for m in self.messages:
            if m.topic.endswith(("/exec/command", "/tst/command")):
                try:
                    body = orjson.loads(m.payload)
                except orjson.JSONDecodeError:
                    body = {}
                out.append((m, body if isinstance(body, dict) else {}))
        return out

    def position_before(self, unit: str, t: float) -> Position | None:
        found = None
        for m in self.messages:
            if m.topic == f"{unit}/sensor/position" and m.time <= t:
                p = orjson.loads(m.payload)
                found = Position(p["latitude"], p["longitude"], p.get("altitude", 0.0))
        return found


def started(wire: Wire) -> list[tuple[Message, dict]]:
    return [(m, b) for m, b in wire.commands() if b.get("command") == "start-task"
            and isinstance(b.get("task"), dict)]


def test_a_real_unit_is_not_moved_without_allow_motion(pytester: pytest.Pytester,
                                                       mosquitto: str, prefix: str) -> None:
    unit, other = f"{prefix}/unit/air/real/dji0", f"{prefix}/unit/air/real/dji1"
    with SimUnit(other, mosquitto, rate=3.0), SimUnit(unit, mosquitto, rate=3.0) as sim, \
            Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "--seed", "3", plugins=(Rebooter(sim),))
    assert run.result.ret == 0, run.text
    assert "no task that moves the unit (no --allow-motion)" in run.text
    names = {b["task"].get("name") for _, b in started(wire)}
    assert names and not any(moves(n) for n in names if n != "waraps-conformance-no-such-task")
    # Commands went to the unit under test only: never to its neighbour, never elsewhere.
    assert {m.topic for m, _ in wire.commands()} == {f"{unit}/exec/command"}


def test_allow_motion_starts_only_the_profile_motion_tasks_near_the_unit(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, tmp_path: Path) -> None:
    profile = tmp_path / "drone.yaml"
    profile.write_text(f"extends: {FAST}\nname: drone\nmotion_tasks: [move-to]\n"
                       f"safe_radius: 30\n")
    unit = f"{prefix}/unit/air/real/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={profile}",
                      "--allow-motion", "--seed", "3", plugins=(Rebooter(sim),))
    assert run.result.ret == 0, run.text
    assert "motion tasks: move-to" in run.text
    # (the name EXEC-START-005 sends is certainly not a task: the unit must refuse it)
    moving = {b["task"]["name"] for _, b in started(wire) if moves(b["task"]["name"])}
    assert moving - {"waraps-conformance-no-such-task"} == {"move-to"}
    for m, body in started(wire):
        origin = wire.position_before(unit, m.time)
        assert origin is not None
        for point in geopoints(body["task"].get("params")):
            target = Position(point["latitude"], point["longitude"])
            assert origin.distance(target) <= 30.0, (body["task"], origin)


def test_every_started_task_is_ended_by_the_suite(pytester: pytest.Pytester, mosquitto: str,
                                                  prefix: str) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "--seed", "3", plugins=(Rebooter(sim),))
        # After the run: the unit's own list of running tasks is empty.
        info = [m for m in wire.messages if m.topic == f"{unit}/direct_execution_info"][-1]
    assert run.result.ret == 0, run.text
    assert orjson.loads(info.payload)["tasks-executing"] == []

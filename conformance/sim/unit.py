"""One simulated WARA-PS unit: what it publishes, how it answers commands, what it remembers.

``UnitCore`` is the protocol logic of one unit, free of threads and sockets: the runtime
(``conformance.sim.runtime``) calls ``run(now)`` when it is due and ``command(payload, now)``
for each message on its ``exec/command`` topic, and the unit hands what it publishes to
``emit(topic, payload, retain)``. ``SimUnit`` is the public face: one unit on one MQTT
connection in a background thread.

Conformant by default on the levels ``sensor`` and ``direct execution`` (spec 5, 6, 9, 12), and
with ``tst_execution`` on ``tst execution`` (14; ``conformance.sim.tst``, reached through
``tst_command``); each fault switch (``conformance.sim.faults``) bends one behaviour the way a real unit would.
Times: ``now`` is ``time.monotonic()`` seconds; stamps are Unix seconds (5.1).
"""

from __future__ import annotations

import math
import random
import re
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterable
from typing import Any

import orjson

from conformance.sim.faults import TST_FAULTS, check_names
from conformance.sim.tasks import (
    BUILTIN_SIGNALS,
    SKIP_WAYPOINT,
    Task,
    TaskSpec,
    plan,
    tasks_for,
)
from conformance.sim.tst import TstEngine, misdirected
from conformance.sim.vehicle import LINKOPING, GeoPoint, Vehicle, bearing, destination
from conformance.topics import UnitAddress

TST_LEVEL_FAULTS = frozenset({"level-unbacked", "tst-info-incomplete", "tst-info-rate-drift"})
"""Faults that declare 'tst execution' to bend what the unit says about it (HB-008, TEI-*)."""
Emit = Callable[[str, bytes, bool], None]

COMMANDS = ("ping", "start-task", "signal-task", "query-status")  # 12.1
MAX_COMMAND_BYTES = 1 << 20
"""A command larger than this is refused unread (no WARA-PS command comes near 1 MiB)."""
MAX_HISTORY = 5000
"""Commands (and ended tasks) remembered per life; the oldest are forgotten first, so memory
stays bounded under a flood of commands."""
STEP = 0.1
LATE_PONG_PERIODS = 3.0
"""Fault pong-late: a pong is held back 3 periods (1.5 s at the fault matrix's 2 Hz, past its
1 s response timeout; 3 s at the workout's 1 Hz, past its 2 s), so it arrives before the
suite's reboot kills the process that held it."""
"""Seconds between simulation steps while a task runs or the vehicle moves."""
CAMERA_URL_EVERY = 2
"""The camera URL changes rarely: it is published every this many periods, inside SI-003's
window of three periods (checks.sensors.PUBLISH_WINDOW_PERIODS), so an observer that joins
late still sees it in time."""
REBOOT_SILENCE = 2.5
"""A reboot is silent for this many heartbeat periods, counted from the last heartbeat: more
than HB-006's two (so the new agent-uuid reads as a reboot), less than HB-010's three."""
DRIFT = 1.35  # the rate-drift faults send at 1/DRIFT of the declared rate
_COM_UUID = re.compile(rb'"com-uuid"\s*:\s*"([^"\\\x00-\x1f]{1,128})"')


def _dumps(obj: Any) -> bytes:
    # Sorted keys, like the spec's examples (json.dumps(sort_keys=True)).
    return orjson.dumps(obj, option=orjson.OPT_SORT_KEYS)


class _Stream:
    """A periodic message: its period in seconds and when it is next due (monotonic)."""

    __slots__ = ("name", "period", "due", "count")

    def __init__(self, name: str, period: float, due: float) -> None:
        self.name, self.period, self.due, self.count = name, period, due, 0


class UnitCore:
    """The protocol logic of one simulated unit (no threads, no sockets).

    ``rate`` is the declared rate of heartbeat, info messages and sensors in Hz;
    ``task_seconds`` how long a simulated task takes (time compression, see
    ``conformance.sim.tasks``); ``phase`` delays the first publication by that many seconds
    (a fleet spreads its units over one period).
    """

    def __init__(self, address: UnitAddress, emit: Emit, *, faults: Iterable[str] = (),
                 rate: float = 1.0, rng: random.Random | None = None,
                 position: GeoPoint | None = None, heading: float = 270.0,
                 task_seconds: float = 3.0, phase: float = 0.0,
                 clock: Callable[[], float] = time.time, tst_execution: bool = False,
                 tst_operator: UnitAddress | None = None) -> None:
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate {rate!r}: a rate is a positive number of Hz")
        self.address = address
        self.faults = check_names(list(faults))
        self.rate = float(rate)
        self.period = 1.0 / self.rate
        self.rng = rng or random.Random()
        self.clock = clock
        self.task_seconds = task_seconds
        self._emit = emit
        home = position or GeoPoint(*LINKOPING, 0.0)
        self.vehicle = Vehicle(address.agent_type, home, heading)
        self.specs: dict[str, TaskSpec] = {t.name: t for t in tasks_for(address.agent_type)}
        self.base = self._base()
        self.command_topic = f"{self.base}/exec/command"
        # The TST level (14), when declared (or a fault declares it): conformance.sim.tst. A
        # fault of tst_execution_info bends that message, not the running of trees.
        self.tst = TstEngine(self, tst_operator.base if tst_operator else None) if (
            tst_execution or self.faults & (TST_FAULTS | TST_LEVEL_FAULTS)) else None
        self.camera_sensor = self._camera_sensor()
        self.levels = self._levels()
        # Identity and memory of one life (12.1: history is lost with a reboot).
        self.boot = 0
        self.agent_uuid = self._new_agent_uuid()
        self.executor_uuid = self._uuid()  # faults response/feedback-stale-agent-uuid
        self.history: OrderedDict[str, dict[str, Any] | None] = OrderedDict()
        """com-uuid -> the response sent (None: deliberately not answered), for resends."""
        self.tasks: OrderedDict[str, Task] = OrderedDict()
        self.up = True
        self.crashed = False
        self.delayed: list[tuple[float, bytes]] = []
        """Fault pong-late: (when, payload) of answers held back."""
        self.dead = False
        """Fault dies-on-missing-task-uuid: the MQTT thread died; the process lives on (silent)."""
        self.back_at: float | None = None
        self.reboot_requested = False
        self._counter = 0
        self.last_heartbeat: float | None = None
        self.heartbeats = 0
        self.commands = 0
        self.published = 0
        self.retained_topics: set[str] = set()
        self._phase = phase
        self._streams: list[_Stream] = []
        self._last_step: float | None = None
        self.due = 0.0

    # --- identity -----------------------------------------------------------------------------
    def _uuid(self) -> str:
        return str(uuid.UUID(int=self.rng.getrandbits(128), version=4))

    def _new_agent_uuid(self) -> str:
        if "agent-uuid-not-uuid" in self.faults:
            return f"{self.address.name}-{self.boot}"
        return self._uuid()

    def _fresh_uuid(self) -> str:
        """A fresh com-uuid for a message of ours (2: 'Use UUID to identify a message')."""
        if "uuid-counter" in self.faults:
            self._counter += 1
            return f"msg-{self._counter}"
        return self._uuid()

    def _base(self) -> str:
        a = self.address
        agent_type = "uav" if "topic-type-uav" in self.faults else a.agent_type
        role = "sim" if "topic-role-sim" in self.faults else a.role
        base = f"{a.prefix}/unit/{agent_type}/{role}/{a.name}"
        return "/" + base if "topic-leading-slash" in self.faults else base

    def _camera_sensor(self) -> str:
        """The topic level of the optional camera sensor (spec 6.2's camera_url)."""
        for fault, sensor in (("topic-uppercase-sensor", "Camera_URL"),
                              ("topic-hyphen-sensor", "camera-url"),
                              ("topic-space-sensor", "camera url")):
            if fault in self.faults:
                return sensor
        return "camera_url"

    def _levels(self) -> list[str]:
        if "undeclared-direct-execution" in self.faults:
            return ["sensor"]  # it answers commands and sends direct_execution_info all the same
        levels = ["sensor", "direct_execution" if "level-underscore" in self.faults
                  else "direct execution"]
        if self.tst is not None:
            levels.append("tst execution")
        if "level-unknown" in self.faults:
            levels.append("telemetry")
        return levels

    def sensors_listed(self) -> list[str]:
        """sensor-data-provided (5.2): the mandatory four and the camera URL."""
        listed = ["position", "heading", "course", "speed"]
        if "mandatory-sensor-missing" in self.faults:
            listed.remove("course")
        if "topic-empty-level" not in self.faults:
            listed.append(self.camera_sensor)
        if "sensor-listed-unpublished" in self.faults:
            listed.append("battery_state")
        return listed

    def topic(self, sub: str) -> str:
        return f"{self.base}/{sub}"

    # --- publishing ---------------------------------------------------------------------------
    def emit(self, sub: str, payload: bytes, retain: bool = False) -> None:
        self.published += 1
        topic = self.topic(sub)
        if retain:
            self.retained_topics.add(topic)
        self._emit(topic, payload, retain)

    def stamp(self) -> float:
        t = self.clock()
        if "stamp-clock-skew" in self.faults:
            t -= 120.0
        if "stamp-milliseconds" in self.faults:
            t *= 1000.0
        return t

    def _info(self, type_: str, rate: float, **fields: Any) -> dict[str, Any]:
        """The fields every heartbeat and info message has (5.1, 5.2, 5.3); info messages
        carry agent-uuid too (ERR-012's decision; the heartbeat passes its own)."""
        name = self.address.name.upper() if "name-mismatch" in self.faults else self.address.name
        msg = {"name": name, "rate": rate, "stamp": self.stamp(), "type": type_, **fields}
        if "agent-uuid" not in fields and "info-no-agent-uuid" not in self.faults:
            msg["agent-uuid"] = self.agent_uuid
        return msg

    def heartbeat_message(self) -> dict[str, Any]:
        """The 5.1 heartbeat."""
        agent_type = self.address.agent_type
        if "topic-type-uav" in self.faults:
            agent_type = "uav"
        elif "agent-type-mismatch" in self.faults:
            agent_type = "ground" if agent_type != "ground" else "air"
        type_ = "Heartbeat" if "heartbeat-type-case" in self.faults else "HeartBeat"
        msg = self._info(type_, 0.0 if "rate-zero" in self.faults else self.rate,
                         **{"agent-type": agent_type, "agent-uuid": self.agent_uuid,
                            "levels": self.levels})
        if "heartbeat-missing-field" in self.faults:
            del msg["levels"]
        return msg

    def _publish_heartbeat(self, stream: _Stream, now: float) -> None:
        if "agent-uuid-changes" in self.faults and stream.count and stream.count % 5 == 0:
            self.agent_uuid = self._uuid()
        self.emit("heartbeat", _dumps(self.heartbeat_message()))
        self.last_heartbeat = now
        self.heartbeats += 1
        if "twin-agent" in self.faults:
            twin = self.heartbeat_message()
            twin["agent-uuid"] = self.executor_uuid
            self.emit("heartbeat", _dumps(twin))

    def _publish_sensor_info(self, stream: _Stream, now: float) -> None:
        type_ = "SensorInformation" if "sensor-info-type" in self.faults else "SensorInfo"
        msg = self._info(type_, self.rate, **{"sensor-data-provided": self.sensors_listed()})
        sub = "sensor.info" if "sensor-dot-info" in self.faults else "sensor_info"
        self.emit(sub, _dumps(msg))

    def _publish_dei(self, stream: _Stream, now: float) -> None:
        type_ = "DirectExecInfo" if "dei-type" in self.faults else "DirectExecutionInfo"
        extra = ["$resume"] if "signal-nonstandard" in self.faults else []
        available = [{"name": s.name, "signals": sorted(s.signals + tuple(extra))}
                     for s in self.specs.values()]
        if "tasks-executing-stale" in self.faults:
            executing = [t for t in self.tasks.values() if t.spec is not None]
        else:
            executing = [t for t in self.tasks.values() if not t.ended]
        msg = self._info(type_, self.rate, **{
            "tasks-available": available,
            "tasks-executing": [{"task-name": t.name, "task-uuid": t.uuid} for t in executing],
        })
        self.emit("direct_execution_info", _dumps(msg))

    def _publish_tei(self, stream: _Stream, now: float) -> None:
        # tst_execution_info is named, not defined (ERR-011): name, rate, stamp, type.
        msg = self._info("TstExecutionInfo", self.rate)
        if self.tst is not None:
            self.tst.fill_info(msg)
        if "tst-info-incomplete" in self.faults:
            del msg["rate"]
        self.emit("tst_execution_info", _dumps(msg))

    def position_message(self, count: int) -> Any:
        p = self.vehicle.position
        lat, lon = round(p.latitude, 7), round(p.longitude, 7)
        if "position-jumps" in self.faults and count % 5 >= 3:
            q = destination(p, 0.0, 800.0)
            lat, lon = round(q.latitude, 7), round(q.longitude, 7)
        if "position-deg-e7" in self.faults:
            lat, lon = round(lat * 1e7), round(lon * 1e7)  # type: ignore[assignment]
        msg: dict[str, Any] = {"altitude": round(p.altitude, 2), "latitude": lat,
                               "longitude": lon, "rostype": "GeoPoint"}
        if "geopoint-type-tag" in self.faults:
            msg["type"] = msg.pop("rostype")
        elif "geopoint-untagged" in self.faults:
            del msg["rostype"]
        return [msg] if "position-as-list" in self.faults else msg

    def _publish_sensors(self, stream: _Stream, now: float) -> None:
        v = self.vehicle
        # Speed, heading and course go out before the position they belong with: an observer
        # judging a position step (SENS-005) then already knows the speed that made it.
        heading = round(v.heading, 2) % 360.0
        if "heading-signed" in self.faults and heading > 180.0:
            heading -= 360.0
        self.emit("sensor/heading", _dumps(heading))
        if "mandatory-sensor-missing" not in self.faults:
            if "course-nan" in self.faults and v.speed == 0.0:
                self.emit("sensor/course", b"NaN")
            else:
                self.emit("sensor/course", _dumps(round(v.course, 2) % 360.0))
        speed = round(v.speed, 2)
        if "speed-sentinel" in self.faults and speed == 0.0:
            speed = -1.0
        self.emit("sensor/speed", _dumps(speed))
        self.emit("sensor/position", _dumps(self.position_message(stream.count)))
        if "sensor-unlisted" in self.faults:
            self.emit("sensor/battery_state", _dumps({"percentage": 0.87, "voltage": 16.2}))
        if stream.count % CAMERA_URL_EVERY == 0:
            self._publish_camera()
        if "topic-unknown-subtopic" in self.faults:
            self.emit("status", _dumps({"state": "ok"}))

    def _publish_camera(self) -> None:
        url = f"rtsp://127.0.0.1:8554/{self.address.name}"
        if "camera-data-url" in self.faults:
            payload = _dumps("data:image/jpeg;base64," + "A" * 1_500_000)
        elif "camera-url-object" in self.faults:
            payload = _dumps({"url": url})
        elif "payload-latin1" in self.faults:
            payload = f'"{url}/caméra"'.encode("latin-1")
        else:
            payload = _dumps(url)
        if "topic-empty-level" in self.faults:
            self.emit("sensor//camera_url", payload)
        else:
            self.emit(f"sensor/{self.camera_sensor}", payload)

    # --- time ---------------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Schedule the periodic messages; the first ones go out at ``now + phase``."""
        first = now + self._phase
        slow = self.period * DRIFT
        self._streams = [
            _Stream("heartbeat", slow if "heartbeat-rate-drift" in self.faults else self.period,
                    first),
            _Stream("sensor_info", slow if "sensor-info-rate-drift" in self.faults
                    else self.period, first),
            _Stream("direct_execution_info", slow if "dei-rate-drift" in self.faults
                    else self.period, first),
            _Stream("sensors", self.period, first),
        ]
        if self.tst is not None and "level-unbacked" not in self.faults:
            self._streams.append(_Stream("tst_execution_info", slow if "tst-info-rate-drift"
                                         in self.faults else self.period, first))
        self._last_step = now
        self.due = first
        if "retained-stale-heartbeat" in self.faults:
            birth = self.heartbeat_message()
            birth["stamp"] = self.stamp() - 5 * self.period
            self.emit("heartbeat", _dumps(birth), retain=True)

    _PUBLISHERS = {
        "heartbeat": _publish_heartbeat,
        "sensor_info": _publish_sensor_info,
        "direct_execution_info": _publish_dei,
        "sensors": _publish_sensors,
        "tst_execution_info": _publish_tei,
    }

    def run(self, now: float) -> None:
        """Do what is due at ``now``: come back from a reboot, step the tasks and the vehicle,
        publish the periodic messages. Sets ``due``, when to be called next."""
        if self.reboot_requested:
            self._go_down(now)
        if not self.up:
            if self.back_at is not None and now >= self.back_at:
                self._come_back(now)
            else:
                self.due = self.back_at if self.back_at is not None else now + self.period
                return
        if self.dead:  # publishes nothing until a reboot restarts the process
            self.due = now + self.period
            return
        self._step(now)
        while self.delayed and self.delayed[0][0] <= now:
            self.emit("exec/response", self.delayed.pop(0)[1])
        silent = "dropouts" in self.faults and self._in_dropout(now)
        for s in self._streams:
            if now >= s.due:
                if not silent:
                    self._PUBLISHERS[s.name](self, s, now)
                s.count += 1
                s.due += s.period
                if s.due < now:  # fell behind (a stalled process): skip, do not burst
                    s.due = now + s.period
        due = min(s.due for s in self._streams)
        if self.delayed:
            due = min(due, self.delayed[0][0])
        if self.busy():
            due = min(due, now + STEP)
        self.due = due

    def _in_dropout(self, now: float) -> bool:
        """Fault dropouts: silent for 4 periods out of every 25, first after 6 periods."""
        if not self._streams:
            return False
        n = self._streams[0].count
        return (n - 6) % 25 < 4 if n >= 6 else False

    def busy(self) -> bool:
        v = self.vehicle
        return (v.speed > 0 or v.target is not None or v.vertical != 0
                or any(not t.ended for t in self.tasks.values())
                or (v.look_at is not None and abs(((v.look_at - v.heading) + 180) % 360 - 180)
                    > 0.01))

    def _step(self, now: float) -> None:
        """Advance the running tasks and the vehicle to ``now``."""
        last = self._last_step if self._last_step is not None else now
        self._last_step = now
        dt = min(now - last, 1.0)  # a stalled process does not teleport the vehicle
        v = self.vehicle
        mover = next((t for t in self.tasks.values()
                      if t.group == "motion" and t.status == "running"), None)
        watcher = next((t for t in reversed(self.tasks.values())
                        if t.look_at is not None and not t.ended), None)
        if watcher is not None:
            target = watcher.look_at
            v.look_at = bearing(v.position, target) if isinstance(target, GeoPoint) else target
        else:
            v.look_at = None
        while dt > 1e-9:  # integrate in slices of at most STEP, however late we run
            v.advance(min(dt, STEP))
            dt -= STEP
        for task in list(self.tasks.values()):
            if task.status != "running":
                continue
            if task.fail_at is not None and now >= task.fail_at:
                self._end(task, "failed", "the task crashed on its parameters")
                continue
            if task is mover or task.group != "motion":
                self._advance_task(task, now)

    def _advance_task(self, task: Task, now: float) -> None:
        v = self.vehicle
        while task.status == "running":
            if task.leg >= len(task.legs):
                if task.loop_from is not None and task.loop_from < len(task.legs):
                    task.leg = task.loop_from
                    task.leg_started = now
                    self._start_leg(task)
                    return
                self._end(task, "finished")
                return
            leg = task.legs[task.leg]
            if leg.point is not None:
                if v.target is None:
                    self._start_leg(task)
                if not v.arrived:
                    break
                if not v.through:
                    v.stop()
            elif now - task.leg_started < leg.seconds:
                break
            task.leg += 1
            task.leg_started = now
            if task.leg < len(task.legs):
                self._start_leg(task)
        if (task.name in ("look-at-position", "look-at-positions") and not task.in_view_sent
                and task.look_at is not None and v.look_at is not None
                and abs(((v.look_at - v.heading) + 180) % 360 - 180) < 5.0):
            task.in_view_sent = True  # 9.4: feedback tells whether the position is in view
            self._feedback(task, "in-view-center")

    def _start_leg(self, task: Task) -> None:
        leg = task.legs[task.leg]
        if leg.point is not None:
            after = task.leg + 1 if task.leg + 1 < len(task.legs) else task.loop_from
            through = after is not None and task.legs[after].point is not None
            self.vehicle.goto(leg.point, task.cruise, task.climb, through=through,
                              ramp=min(1.0, self.task_seconds / 3))

    # --- reboot -------------------------------------------------------------------------------
    def request_reboot(self) -> None:
        """Reboot at the next ``run``: silent for a moment, history lost, new agent-uuid."""
        self.reboot_requested = True

    def _go_down(self, now: float) -> None:
        self.reboot_requested = False
        self.up = False
        self.delayed.clear()  # what the old process held back dies with it
        last = self.last_heartbeat if self.last_heartbeat is not None else now
        self.back_at = max(now + 0.1 * self.period, last + REBOOT_SILENCE * self.period)
        self.vehicle.stop()
        self.vehicle.speed = 0.0
        self.vehicle.look_at = None

    def _come_back(self, now: float) -> None:
        self.boot += 1
        if "reboot-keeps-agent-uuid" not in self.faults:
            self.agent_uuid = self._new_agent_uuid()
        if "reboot-remembers-history" not in self.faults:
            self.history.clear()
            self.tasks.clear()
        else:  # history kept on disk, but what ran has stopped
            for t in self.tasks.values():
                if not t.ended:
                    t.status, t.fail_reason = "failed", "interrupted by a reboot"
        self.crashed = False
        self.dead = False
        self.up = True
        self.back_at = None
        self._last_step = now
        for s in self._streams:
            s.due = now  # the first heartbeat of the new life goes out at once

    # --- commands -----------------------------------------------------------------------------
    def tst_command(self, payload: bytes, now: float, topic: str) -> None:
        """Handle one message from a ``tst/command`` topic (14; ``conformance.sim.tst``)."""
        if self.tst is None or not self.up or self.crashed:
            return
        self._step(now)
        self.tst.command(payload, now, topic)

    def command(self, payload: bytes, now: float, size: int | None = None) -> None:
        """Handle one message from ``exec/command``; ``size`` is its length in bytes when
        ``payload`` is only its head. Never raises on hostile input."""
        if not self.up or self.crashed or self.dead:
            return  # rebooting, or the command thread died (faults crash-on-malformed, dies-...)
        self.commands += 1
        self._step(now)
        size = len(payload) if size is None else size
        if size > MAX_COMMAND_BYTES:
            msg, problem = None, f"a command of {size} bytes is larger than {MAX_COMMAND_BYTES}"
        else:
            msg, problem = self._decode(payload)
        if problem is not None:
            com = self._readable_com_uuid(payload, msg)
            if "crash-on-malformed" in self.faults:
                self.crashed = True
                return
            if com is not None and "malformed-unanswered" not in self.faults:
                self._answer(com, "failed", fail_reason=problem)
            return
        assert isinstance(msg, dict)
        com = msg["com-uuid"]
        if (com in self.history and "resend-answered-failed" in self.faults
                and msg.get("command") == "start-task"):
            self._refuse_resend(com, msg)
            return
        if com in self.history and "resend-executes-twice" not in self.faults:
            # 12.1: a resent command reuses its com-uuid; answer it again, do not run it twice.
            cached = self.history[com]
            if cached is not None and "resend-unanswered" not in self.faults:
                self._send_response(dict(cached))
            self.history.move_to_end(com)
            return
        command = msg.get("command")
        if command == "ping":
            self._answer(com, "pong", kind="ping")
        elif command == "start-task":
            self._start_task(com, msg, now)
        elif command == "signal-task":
            self._signal_task(com, msg, now)
        elif command == "query-status":
            self._query_status(com, msg)
        elif not isinstance(command, str):
            self._answer(com, "failed", fail_reason="the command has no 'command' field (one of "
                         f"{', '.join(COMMANDS)})")
        else:
            self._answer(com, "failed", fail_reason=f"unknown command {command[:64]!r}: this "
                         f"unit understands {', '.join(COMMANDS)} (12.1)" + misdirected(command))

    def _refuse_resend(self, com: str, msg: dict[str, Any]) -> None:
        """Fault resend-answered-failed (seen in the field): the resent start-task is taken for
        a new one whose task-uuid is taken, answered 'failed', and the running task gets a
        'failed' feedback too, although it runs on."""
        cached = self.history.get(com)
        task_uuid = cached.get("task-uuid") if cached else msg.get("task-uuid")
        task = self.tasks.get(task_uuid) if isinstance(task_uuid, str) else None
        reason = f"task-uuid {task_uuid} is already used by another task"
        body: dict[str, Any] = {"agent-uuid": self.agent_uuid, "response": "failed",
                                "response-to": com, "task-uuid": task_uuid,
                                "fail-reason": reason}
        self._send_response(body, command_com=com)
        if task is not None and not task.ended:
            self._feedback(task, "failed")

    def _decode(self, payload: bytes) -> tuple[Any, str | None]:
        """The command as a dict with a string com-uuid, or what is wrong with it."""
        try:
            msg = orjson.loads(payload)
        except orjson.JSONDecodeError as e:
            return None, f"the command is not valid JSON (UTF-8, RFC 8259): {str(e)[:120]}"
        if not isinstance(msg, dict):
            return msg, f"a command is a JSON object, not a JSON {type(msg).__name__}"
        com = msg.get("com-uuid")
        if not isinstance(com, str) or not com or len(com) > 128:
            return msg, "the command has no com-uuid string"
        return msg, None

    @staticmethod
    def _readable_com_uuid(payload: bytes, msg: Any) -> str | None:
        """A com-uuid that can be read from a malformed command, if any (EXEC-ROBUST-002)."""
        if isinstance(msg, dict):
            com = msg.get("com-uuid")
            return com if isinstance(com, str) and 0 < len(com) <= 128 else None
        if msg is not None:
            return None  # valid JSON but not an object: nothing to read it from
        m = _COM_UUID.search(payload, 0, 65536)
        if m is None:
            return None
        try:
            return m.group(1).decode("utf-8")
        except UnicodeDecodeError:
            return None

    def _answer(self, com: str, response: str, *, task_uuid: str | None = None,
                fail_reason: str | None = None, kind: str = "") -> None:
        """Send a response (12.3) and remember it for a resend."""
        body: dict[str, Any] = {"agent-uuid": self.agent_uuid, "response": response,
                                "response-to": com}
        if task_uuid is not None:
            body["task-uuid"] = task_uuid
        if fail_reason is not None:
            body["fail-reason"] = "" if "fail-reason-empty" in self.faults else fail_reason
        if kind == "ping":
            if "pong-missing" in self.faults:
                return
            if "pong-late" in self.faults:
                self.history[com] = body
                self._send_response(dict(body), command_com=com,
                                    delay=LATE_PONG_PERIODS * self.period)
                return
            if "pong-response-to-uppercase" in self.faults:
                body["response-to"] = com.upper()
        if kind == "signal" and "signal-response-tst-form" in self.faults:
            body = {"response": "ok" if response == "ok" else response, "response-to": com}
            if response == "failed":
                body["fail-reason"] = fail_reason or ""
        silent = kind == "signal" and "signal-unanswered" in self.faults
        self.history[com] = None if silent else body
        if len(self.history) > MAX_HISTORY:
            self.history.popitem(last=False)
        if not silent:
            self._send_response(dict(body), command_com=com)

    def _send_response(self, body: dict[str, Any], command_com: str | None = None,
                       delay: float = 0.0) -> None:
        com = body.get("response-to", "") if command_com is None else command_com
        body["com-uuid"] = com if "response-reuses-com-uuid" in self.faults else self._fresh_uuid()
        if "agent-uuid" in body:
            if "response-no-agent-uuid" in self.faults:
                del body["agent-uuid"]
            elif "response-stale-agent-uuid" in self.faults:
                body["agent-uuid"] = self.executor_uuid
            else:
                body["agent-uuid"] = self.agent_uuid
        if delay:
            # in the clock ``run`` is given (the runtime's monotonic one): the last step's
            self.delayed.append(((self._last_step or 0.0) + delay, _dumps(body)))
            return
        self.emit("exec/response", _dumps(body))
        if "response-twice" in self.faults:  # a retry loop that does not wait for the PUBACK
            self.emit("exec/response", _dumps(body))

    def _feedback(self, task: Task, status: str) -> None:
        """Send feedback for a status change of a task (12.4)."""
        if task.node is not None:  # a TST leaf: its node reports (conformance.sim.tst)
            task.node(status, "")
            return
        agent = self.executor_uuid if "feedback-stale-agent-uuid" in self.faults \
            else self.agent_uuid
        if status == "finished" and "feedback-status-done" in self.faults:
            status = "done"
        body = {"agent-uuid": agent, "com-uuid": self._fresh_uuid(), "status": status,
                "task-uuid": task.uuid}
        if "feedback-no-com-uuid" in self.faults:
            del body["com-uuid"]
        if "feedback-no-task-uuid" in self.faults:
            del body["task-uuid"]
        self.emit("exec/feedback", _dumps(body))

    # --- start-task -----------------------------------------------------------------------------
    def _start_task(self, com: str, msg: dict[str, Any], now: float) -> None:
        task_field = msg.get("task")
        sent_uuid = msg.get("task-uuid")
        if sent_uuid is not None and (not isinstance(sent_uuid, str) or not sent_uuid
                                      or len(sent_uuid) > 128):
            self._answer(com, "failed", fail_reason="task-uuid must be a UUID string",
                         task_uuid=None)
            return
        if sent_uuid is None and "dies-on-missing-task-uuid" in self.faults:
            self.dead = True  # msg["task-uuid"] raised a KeyError in the MQTT thread
            return
        task_uuid = sent_uuid if sent_uuid is not None else self._task_uuid()
        if sent_uuid is not None and "task-uuid-ignored" in self.faults:
            task_uuid = self._task_uuid()
        if not isinstance(task_field, dict) or not isinstance(task_field.get("name"), str):
            self._answer(com, "failed", task_uuid=task_uuid, fail_reason="start-task needs "
                         "'task': {'name': ..., 'params': {...}} (12.2.3, section 10)")
            return
        if (task_uuid in self.tasks and "resend-executes-twice" in self.faults
                and self.tasks[task_uuid].com_uuid == com):
            del self.tasks[task_uuid]  # the resend starts the same task again from scratch
        if task_uuid in self.tasks:
            self._answer(com, "failed", task_uuid=task_uuid, fail_reason=f"task-uuid "
                         f"{task_uuid} is already used by another task")
            return
        name = task_field["name"]
        params = task_field.get("params", {})
        spec = self.specs.get(name)
        problems: list[str] = []
        if spec is None:
            if "accept-unknown-task" not in self.faults:
                known = ", ".join(self.specs)
                reason = (f"task {name[:64]!r} is not available on this "
                          f"{self.address.agent_type} unit; tasks-available: {known}")
                self._fail_task(com, task_uuid, name, params, reason)
                return
        else:
            problems = spec.problems(params)
            if problems and "accept-invalid-params" not in self.faults:
                self._fail_task(com, task_uuid, name, params,
                                f"invalid parameters for {name}: " + "; ".join(problems))
                return
        task = Task(task_uuid, name, params if isinstance(params, dict) else {}, spec, com,
                    leg_started=now)
        if problems:
            task.fail_at = now + 0.5  # fault accept-invalid-params: it fails once it runs
        else:
            plan(task, self.vehicle, self.task_seconds)
        # A task of the same group (the vehicle, the camera, the detector) is pre-empted.
        for other in self.tasks.values():
            if not other.ended and other.group == task.group and task.spec is not None:
                self._end(other, "aborted", f"pre-empted by task {task_uuid}")
        self._remember(task)
        response = "started" if "start-answered-started" in self.faults else "running"
        shown = None if (sent_uuid is not None and "start-response-no-task-uuid" in self.faults
                         or sent_uuid is None and "start-no-generated-task-uuid" in self.faults
                         ) else task_uuid
        if "start-response-unpublished" in self.faults:
            self.history[com] = None  # built into a response that is never published
        else:
            self._answer(com, response, task_uuid=shown, fail_reason="", kind="start")
        if "feedback-status-typo" in self.faults:
            self._feedback(task, "Starting")
        self._feedback(task, "running")
        if task.legs:
            self._start_leg(task)
        self._advance_task(task, now)

    def _task_uuid(self) -> str:
        if "uuid-counter" in self.faults:
            self._counter += 1
            return f"task-{self._counter}"
        return self._uuid()

    def _fail_task(self, com: str, task_uuid: str, name: str, params: Any, reason: str) -> None:
        task = Task(task_uuid, str(name)[:128], {}, None, com, status="failed",
                    fail_reason=reason)
        self._remember(task)
        self._answer(com, "failed", task_uuid=task_uuid, fail_reason=reason, kind="start")

    def _remember(self, task: Task) -> None:
        self.tasks[task.uuid] = task
        if len(self.tasks) > MAX_HISTORY:  # forget the oldest ended task
            for key, old in self.tasks.items():
                if old.ended:
                    del self.tasks[key]
                    break

    def _end(self, task: Task, status: str, reason: str = "") -> None:
        """A task reaches a final status: finished, aborted or failed (12.4)."""
        task.status, task.fail_reason = status, reason
        if task.group == "motion":
            self.vehicle.stop()
        if task.node is not None:  # a TST leaf: its node reports (conformance.sim.tst)
            task.node(status, reason)
            return
        on_its_own = status == "finished" and not reason
        if not (on_its_own and "no-final-feedback" in self.faults):
            self._feedback(task, status)
            if "feedback-after-final" in self.faults:
                self._feedback(task, status)
        if "response-on-finish" in self.faults:
            self.emit("exec/response", _dumps({
                "agent-uuid": self.agent_uuid, "com-uuid": self._fresh_uuid(),
                "response": "finished", "response-to": task.uuid}))

    # --- signal-task ----------------------------------------------------------------------------
    def _signal_task(self, com: str, msg: dict[str, Any], now: float) -> None:
        task_uuid, signal = msg.get("task-uuid"), msg.get("signal")
        shown = task_uuid if isinstance(task_uuid, str) and len(task_uuid) <= 128 else None

        def refuse(reason: str) -> None:
            self._answer(com, "failed", task_uuid=shown, fail_reason=reason, kind="signal")

        if not isinstance(task_uuid, str) or not isinstance(signal, str):
            refuse("signal-task needs a task-uuid and a signal (strings, 12.2.2)")
            return
        task = self.tasks.get(task_uuid)
        if task is None:
            if "signal-unknown-task-ok" in self.faults:
                self._answer(com, "ok", task_uuid=shown, fail_reason="", kind="signal")
            else:
                refuse(f"no task with task-uuid {task_uuid[:64]} is known")
            return
        if task.ended:
            refuse(f"task {task_uuid} has already ended ({task.status})")
            return
        signals = task.spec.signals if task.spec else BUILTIN_SIGNALS
        if "signal-nonstandard" in self.faults and signal == "$resume":
            signal = "$continue"
        if signal not in signals:
            refuse(f"task {task.name} does not understand {signal[:64]!r}; it understands "
                   f"{', '.join(signals)}")
            return
        self._answer(com, "ok", task_uuid=task_uuid, fail_reason="", kind="signal")
        self._step(now)
        if signal == "$abort":
            if "abort-ignored" not in self.faults:
                self._end(task, "aborted", "aborted by $abort")
        elif signal == "$enough":
            self._end(task, "aborted" if "enough-aborts" in self.faults else "finished",
                      "ended by $enough")
        elif signal == "$pause":
            if task.status == "running" and "pause-ignored" not in self.faults:
                task.status = "paused"
                leg = task.legs[task.leg] if task.leg < len(task.legs) else None
                if leg is not None and leg.point is None:
                    task.paused_left = leg.seconds - (now - task.leg_started)
                if task.group == "motion":
                    self.vehicle.stop()
                self._feedback(task, "paused")
        elif signal == "$continue":
            if task.status == "paused":
                task.status = "running"
                task.resume_clock(now)
                if task.group == "motion" and task.leg < len(task.legs):
                    for other in self.tasks.values():  # the vehicle is this task's again
                        if other is not task and other.group == "motion" and not other.ended:
                            self._end(other, "aborted", f"pre-empted by task {task.uuid}")
                    self._start_leg(task)
                self._feedback(task, "running")
        elif signal == SKIP_WAYPOINT:
            if task.leg < len(task.legs):
                self.vehicle.stop()
                task.leg += 1
                task.leg_started = now
                if task.leg < len(task.legs) and task.status == "running":
                    self._start_leg(task)
        if task.status == "running":
            self._advance_task(task, now)

    # --- query-status ---------------------------------------------------------------------------
    def _query_status(self, com: str, msg: dict[str, Any]) -> None:
        if "query-unanswered" in self.faults:
            return  # never answered (every agent seen in the field)
        task_uuid = msg.get("task-uuid")
        if not isinstance(task_uuid, str) or not task_uuid or len(task_uuid) > 128:
            self._answer(com, "failed", fail_reason="query-status needs the task-uuid of the "
                         "task to query (12.1)", kind="query")
            return
        task = self.tasks.get(task_uuid)
        if task is not None and task.ended and "query-forgets-finished" in self.faults:
            task = None
        if task is None:
            if "query-unknown-failed" in self.faults:
                self._answer(com, "failed", task_uuid=task_uuid, fail_reason="no such task",
                             kind="query")
            else:  # 12.1: 'unknown' for a task this life has never seen
                self._answer(com, "unknown", task_uuid=task_uuid, fail_reason="", kind="query")
            return
        status = task.status
        if status == "finished" and "query-answers-success" in self.faults:
            status = "success"
        reason = task.fail_reason if status == "failed" else ""
        self._answer(com, status, task_uuid=task_uuid, fail_reason=reason, kind="query")

    # --- shutdown ---------------------------------------------------------------------------------
    def clear_retained(self) -> None:
        """Remove what this unit left retained on the broker (an empty retained message)."""
        for topic in sorted(self.retained_topics):
            self._emit(topic, b"", True)
        self.retained_topics.clear()

"""What the reference unit publishes on its own, period by period: the heartbeat (5.1),
sensor_info (5.2), direct_execution_info (5.3), tst_execution_info (named, not defined: ERR-011)
and its sensors (6), each bent by the faults that name it; and the topics it publishes under (3).

Free of threads, like ``UnitCore``: ``now`` is ``time.monotonic()`` seconds; stamps are Unix
seconds (5.1).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from conformance.sim.variants import EDGE, INFO_SLOWER
from conformance.sim.vehicle import destination
from conformance.topics import DIRECT_EXECUTION, SENSOR_LEVEL, TST_EXECUTION, UnitAddress

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

CAMERA_URL_EVERY = 2
"""The camera URL changes rarely: it is published every this many periods, inside SI-003's
window of three periods (checks.sensors.PUBLISH_WINDOW_PERIODS), so an observer that joins
late still sees it in time."""
DRIFT = 1.35  # the rate-drift faults send at 1/DRIFT of the declared rate
GROSS = 5.0
"""Fault heartbeat-rate-gross: every heartbeat interval is this many declared periods (the
field's was 25: a mismatch this gross is judged from a few intervals, 5.1)."""


def topic_base(address: UnitAddress, faults: frozenset[str]) -> str:
    """The base of every topic the unit publishes under (3.1): its address, unless a topic
    fault moves it."""
    agent_type = "uav" if "topic-type-uav" in faults else address.agent_type
    role = "sim" if "topic-role-sim" in faults else address.role
    base = f"{address.prefix}/unit/{agent_type}/{role}/{address.name}"
    return "/" + base if "topic-leading-slash" in faults else base


def camera_sensor(faults: frozenset[str]) -> str:
    """The topic level of the optional camera sensor (spec 6.2's camera_url)."""
    for fault, sensor in (("topic-uppercase-sensor", "Camera_URL"),
                          ("topic-hyphen-sensor", "camera-url"),
                          ("topic-space-sensor", "camera url")):
        if fault in faults:
            return sensor
    return "camera_url"


class Stream:
    """A periodic message: its period in seconds and when it is next due (monotonic)."""

    __slots__ = ("name", "period", "due", "count")

    def __init__(self, name: str, period: float, due: float) -> None:
        self.name, self.period, self.due, self.count = name, period, due, 0


class Publisher:
    """The periodic messages of one ``UnitCore``, at its declared ``rate``."""

    def __init__(self, unit: UnitCore) -> None:
        self.unit = unit
        self.faults = unit.faults
        self.variants = unit.variants
        self.camera_sensor = camera_sensor(self.faults)
        self.levels = self._levels()
        self.streams: list[Stream] = []
        self.heartbeats = 0
        self.last_heartbeat: float | None = None
        self.listed_paused: set[str] = set()
        """Fault paused-dropped-from-list: the paused tasks tasks-executing listed once."""
        """When the last heartbeat went out (monotonic seconds)."""

    def _levels(self) -> list[str]:
        if "undeclared-direct-execution" in self.faults:
            return [SENSOR_LEVEL]  # it answers commands and sends direct_execution_info all the same
        # ERR-008: the fault (and the variant level-spelling) writes 'direct_execution', as
        # units found in practice do.
        underscore = "level-underscore" in self.faults or "level-spelling" in self.variants
        direct = DIRECT_EXECUTION.replace(" ", "_") if underscore else DIRECT_EXECUTION
        levels = [SENSOR_LEVEL, direct]
        if self.unit.tst is not None:
            levels.append(TST_EXECUTION)
        if "level-unknown" in self.faults:
            levels.append("telemetry")
        return levels

    # --- schedule -----------------------------------------------------------------------------
    def start(self, first: float) -> None:
        """Schedule the periodic messages; the first ones go out at ``first``."""
        period = self.unit.period

        # Variant sensor-rate-edge: sensor_info and the sensors at the slow edge of the rate
        # tolerance (5.2's rate), not past it.
        edge = period / (1.0 - EDGE) if "sensor-rate-edge" in self.variants else period

        # Variant rate-edge: the heartbeat and the execution info messages at the fast edge.
        fast = period / (1.0 + EDGE) if "rate-edge" in self.variants else period
        # Variant info-rates: the info messages at a lower rate of their own (5), declared.
        slower = period * INFO_SLOWER if "info-rates" in self.variants else None
        info = slower or fast

        def stream(name: str, drift_fault: str, normal: float = period) -> Stream:
            return Stream(name, normal * DRIFT if drift_fault in self.faults else normal, first)

        beat = fast * GROSS if "heartbeat-rate-gross" in self.faults else fast
        self.streams = [stream("heartbeat", "heartbeat-rate-drift", beat),
                        stream("sensor_info", "sensor-info-rate-drift",
                               edge if "sensor-rate-edge" in self.variants else slower or period),
                        stream("direct_execution_info", "dei-rate-drift", info),
                        Stream("sensors", edge, first)]
        if self.unit.tst is not None and "level-unbacked" not in self.faults:
            self.streams.append(stream("tst_execution_info", "tst-info-rate-drift", info))
        if "retained-stale-heartbeat" in self.faults:
            birth = self.heartbeat_message()
            birth["stamp"] = self.stamp() - 5 * period
            self.unit.send("heartbeat", birth, retain=True)

    def restart(self, now: float) -> None:
        """After a reboot: the first heartbeat of the new life goes out at once."""
        for s in self.streams:
            s.due = now

    def publish_due(self, now: float) -> float:
        """Publish what is due at ``now``; returns when the next message is due."""
        silent = "dropouts" in self.faults and self._in_dropout()
        for s in self.streams:
            if now >= s.due:
                if not silent:
                    self._PUBLISHERS[s.name](self, s, now)
                s.count += 1
                s.due += s.period
                if s.due < now:  # fell behind (a stalled process): skip, do not burst
                    s.due = now + s.period
        return min(s.due for s in self.streams)

    def _in_dropout(self) -> bool:
        """Fault dropouts: silent for 4 periods out of every 25, first after 6 periods."""
        if not self.streams:
            return False
        n = self.streams[0].count
        return (n - 6) % 25 < 4 if n >= 6 else False

    # --- heartbeat and info messages ----------------------------------------------------------
    def stamp(self) -> float:
        t = self.unit.clock()
        if "stamp-clock-skew" in self.faults:
            t -= 120.0
        if "stamp-milliseconds" in self.faults:
            t *= 1000.0
        return t

    def _info(self, type_: str, rate: float, **fields: Any) -> dict[str, Any]:
        """The fields every heartbeat and info message has (5.1, 5.2, 5.3); info messages
        carry agent-uuid too (ERR-012's decision; the heartbeat passes its own)."""
        unit = self.unit
        name = unit.address.name.upper() if "name-mismatch" in self.faults else unit.address.name
        msg = {"name": name, "rate": rate, "stamp": self.stamp(), "type": type_, **fields}
        if "agent-uuid" not in fields and "info-no-agent-uuid" not in self.faults:
            msg["agent-uuid"] = unit.agent_uuid
        return msg

    @property
    def retain_info(self) -> bool:
        """Variant retained-info: the info messages are retained (a late subscriber learns the
        unit's sensors and tasks at once)."""
        return "retained-info" in self.variants

    @property
    def info_rate(self) -> float:
        """The rate the info messages declare (5.2, 5.3): the heartbeat's, unless variant
        info-rates sends them slower."""
        return self.unit.rate / INFO_SLOWER if "info-rates" in self.variants else self.unit.rate

    def heartbeat_message(self) -> dict[str, Any]:
        """The 5.1 heartbeat."""
        unit = self.unit
        agent_type = unit.address.agent_type
        if "topic-type-uav" in self.faults:
            agent_type = "uav"
        elif "agent-type-mismatch" in self.faults:
            agent_type = "ground" if agent_type != "ground" else "air"
        type_ = "Heartbeat" if "heartbeat-type-case" in self.faults else "HeartBeat"
        msg = self._info(type_, 0.0 if "rate-zero" in self.faults else unit.rate,
                         **{"agent-type": agent_type, "agent-uuid": unit.agent_uuid,
                            "levels": self.levels})
        if "heartbeat-missing-field" in self.faults:
            del msg["levels"]
        return msg

    def _publish_heartbeat(self, stream: Stream, now: float) -> None:
        unit = self.unit
        if "agent-uuid-changes" in self.faults and stream.count and stream.count % 5 == 0:
            unit.agent_uuid = unit.new_uuid()
        unit.send("heartbeat", self.heartbeat_message())
        self.last_heartbeat = now
        self.heartbeats += 1
        went_on = unit.executor.went_on  # fault abort-running-goes-on: those it still runs
        if "periodic-feedback" in unit.variants or went_on:  # 12.4 'Update of the status'
            for task in list(unit.runner.tasks.values()):
                if task.node is None and task.status in ("running", "paused") and (
                        "periodic-feedback" in unit.variants or task.uuid in went_on):
                    unit.runner.feedback(task, task.status)
        if "twin-agent" in self.faults:
            twin = self.heartbeat_message()
            twin["agent-uuid"] = unit.executor_uuid
            unit.send("heartbeat", twin)

    def sensors_listed(self) -> list[str]:
        """sensor-data-provided (5.2): the mandatory four and the camera URL."""
        listed = ["position", "heading", "course", "speed"]
        if "mandatory-sensor-missing" in self.faults:
            listed.remove("course")
        if "terse" in self.variants:  # the optional camera_url (6.2) is left out
            return listed
        if "topic-empty-level" not in self.faults:
            listed.append(self.camera_sensor)
        if "sensor-listed-unpublished" in self.faults:
            listed.append("battery_state")
        return listed

    def _publish_sensor_info(self, stream: Stream, now: float) -> None:
        type_ = "SensorInformation" if "sensor-info-type" in self.faults else "SensorInfo"
        msg = self._info(type_, self.info_rate, **{"sensor-data-provided": self.sensors_listed()})
        self.unit.send("sensor.info" if "sensor-dot-info" in self.faults else "sensor_info", msg,
                       retain=self.retain_info)
        if "both-sensor-info" in self.variants:  # 5.2's spelling too, a stream of its own
            self.unit.send("sensor.info", msg, retain=self.retain_info)

    def _publish_dei(self, stream: Stream, now: float) -> None:
        unit = self.unit
        type_ = "DirectExecInfo" if "dei-type" in self.faults else "DirectExecutionInfo"
        extra = ["$resume"] if "signal-nonstandard" in self.faults else []
        available = [{"name": s.name, "signals": sorted(s.signals + tuple(extra))}
                     for s in unit.specs.values()]
        tasks = unit.runner.tasks.values()
        if "tasks-executing-stale" in self.faults:
            executing = [t for t in tasks if t.spec is not None]
        elif "paused-not-executing" in self.variants:  # 5.3: 'currently executing'
            executing = [t for t in tasks if not t.ended and t.status != "paused"]
        else:
            executing = [t for t in tasks if not t.ended or (
                "refused-task-listed" in self.faults and t.spec is None and not t.legs)]
        if "paused-dropped-from-list" in self.faults:  # listed once paused, then moved away
            executing = [t for t in executing
                         if t.status != "paused" or t.uuid not in self.listed_paused]
            self.listed_paused = {t.uuid for t in tasks if t.status == "paused"}
        if "tasks-executing-twice" in self.faults:
            executing = [t for t in executing for _ in (t, t)]
        msg = self._info(type_, self.info_rate, **{
            "tasks-available": available,
            "tasks-executing": [{"task-name": t.name, "task-uuid": t.uuid} for t in executing],
        })
        if "dei-no-tasks-executing" in self.faults:
            del msg["tasks-executing"]
        unit.send("direct_execution_info", msg, retain=self.retain_info)

    def _publish_tei(self, stream: Stream, now: float) -> None:
        # tst_execution_info is named, not defined (ERR-011): name, rate, stamp, type.
        msg = self._info("TstExecutionInfo", self.info_rate)
        if self.unit.tst is not None:
            self.unit.tst.fill_info(msg)
        if "tst-info-incomplete" in self.faults:
            del msg["rate"]
        if "terse" in self.variants:  # optional (TST-013: a unit without it is not judged)
            msg.pop("nodes-executing", None)
        self.unit.send("tst_execution_info", msg, retain=self.retain_info)

    # --- sensors (6) ----------------------------------------------------------------------------
    def position_message(self, count: int) -> Any:
        p = self.unit.vehicle.position
        lat, lon = round(p.latitude, 7), round(p.longitude, 7)
        if "position-jumps" in self.faults and count % 5 >= 3:
            q = destination(p, 0.0, 800.0)
            lat, lon = round(q.latitude, 7), round(q.longitude, 7)
        if "position-deg-e7" in self.faults:
            lat, lon = round(lat * 1e7), round(lon * 1e7)
        msg: dict[str, Any] = {"altitude": round(p.altitude, 2), "latitude": lat,
                               "longitude": lon, "rostype": "GeoPoint"}
        if "geopoint-type" in self.variants:
            msg["type"] = msg.pop("rostype")
        return [msg] if "position-as-list" in self.faults else msg

    def _publish_sensors(self, stream: Stream, now: float) -> None:
        unit, v = self.unit, self.unit.vehicle
        # Speed, heading and course go out before the position they belong with: an observer
        # judging a position step (SENS-005) then already knows the speed that made it.
        heading = round(v.heading, 2) % 360.0
        if heading > 180.0 and ("heading-signed" in self.faults
                                or "signed-heading" in unit.variants):
            heading -= 360.0
        unit.send("sensor/heading", heading)
        if "mandatory-sensor-missing" not in self.faults:
            if "course-nan" in self.faults and v.speed == 0.0:
                unit.emit("sensor/course", b"NaN")
            else:
                unit.send("sensor/course", round(v.course, 2) % 360.0)
        speed = round(v.speed, 2)
        if "speed-sentinel" in self.faults and speed == 0.0:
            speed = -1.0
        unit.send("sensor/speed", speed)
        unit.send("sensor/position", self.position_message(stream.count))
        if "sensor-unlisted" in self.faults:
            unit.send("sensor/battery_state", {"percentage": 0.87, "voltage": 16.2})
        if stream.count % CAMERA_URL_EVERY == 0 and "terse" not in self.variants:
            self._publish_camera()
        if "topic-unknown-subtopic" in self.faults:
            unit.send("status", {"state": "ok"})

    def _publish_camera(self) -> None:
        unit = self.unit
        url = f"rtsp://127.0.0.1:8554/{unit.address.name}"
        topic = ("sensor//camera_url" if "topic-empty-level" in self.faults
                 else f"sensor/{self.camera_sensor}")
        if "camera-data-url" in self.faults:
            unit.send(topic, "data:image/jpeg;base64," + "A" * 1_500_000)
        elif "camera-url-object" in self.faults:
            unit.send(topic, {"url": url})
        elif "payload-latin1" in self.faults:
            unit.emit(topic, f'"{url}/caméra"'.encode("latin-1"))
        else:
            unit.send(topic, url)

    _PUBLISHERS: dict[str, Callable[[Publisher, Stream, float], None]] = {
        "heartbeat": _publish_heartbeat,
        "sensor_info": _publish_sensor_info,
        "direct_execution_info": _publish_dei,
        "sensors": _publish_sensors,
        "tst_execution_info": _publish_tei,
    }

"""Small ROS bags for the tests (imported as ``ros_bags``): the traffic of a conformant ROS unit
as (topic, type, time, fields) entries, and writers for ROS 1 and ROS 2 (sqlite3, MCAP) bags
that use ``rosbags`` the way a real recorder stores them."""

from __future__ import annotations

import contextlib
import io
import json
import uuid
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

T0 = 1_763_700_000.0
UNIT = "waraps/unit/ground/real/husky0"
NAME = "husky0"
TOPIC_MSG = "lrs_msgs_common/msg/TopicMsg"
GEOPOINT = "geographic_msgs/msg/GeoPoint"
SPEC_TYPES = {TOPIC_MSG: "string topic\nstring msg\n",
              GEOPOINT: "float64 latitude\nfloat64 longitude\nfloat64 altitude\n"}
ACME_STATUS = "acme_msgs/msg/Status"
"""A type no distribution ships: written without its definition, it cannot be read."""
ACME_COMMAND = "acme_msgs/msg/JsonCommand"
"""A custom type with a ``data`` string: exec_command of the wrong type (ROS-006)."""


@dataclass(frozen=True)
class Entry:
    """One message of a bag: its ROS topic, its type, its record time (Unix seconds) and its
    fields; or ``raw``, bytes written as they are (a damaged message)."""

    topic: str
    msgtype: str
    time: float
    fields: dict[str, Any] = field(default_factory=dict)
    raw: bytes = b""


def typestore(ros2: bool) -> Typestore:
    """The distribution's standard types plus the spec's TopicMsg and GeoPoint."""
    store = get_typestore(Stores.LATEST if ros2 else Stores.ROS1_NOETIC)
    types: dict[str, Any] = {}
    for name, text in SPEC_TYPES.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    store.register(get_types_from_msg("string state\n", ACME_STATUS))
    store.register(get_types_from_msg("string data\n", ACME_COMMAND))
    return store


def battery(ros2: bool, t: float) -> dict[str, Any]:
    """The fields of a sensor_msgs/BatteryState (NaN where ROS says 'not measured')."""
    import numpy as np

    stamp = {"sec": int(t), "nanosec": 0}
    nan = float("nan")
    return {"header": {"stamp": stamp, "frame_id": "", **({} if ros2 else {"seq": 0})},
            "voltage": 24.1, "temperature": nan, "current": -1.2, "charge": nan,
            "capacity": nan, "design_capacity": 20.0, "percentage": 0.87,
            "power_supply_status": 2, "power_supply_health": 1, "power_supply_technology": 3,
            "present": True, "cell_voltage": np.array([], dtype=np.float32),
            "cell_temperature": np.array([], dtype=np.float32), "location": "",
            "serial_number": ""}


def unit_entries(*, name: str = NAME, unit: str = UNIT, seconds: int = 12, t0: float = T0,
                 heartbeat_info: bool = True, sensors: Iterable[str] = (
                     "position", "heading", "course", "speed", "camera_url", "battery_state"),
                 types: dict[str, str] | None = None, namespace: str | None = None,
                 heartbeat_topic: str | None = None, heartbeat_payload: Any = None,
                 heartbeat_every: int = 1, heartbeat_info_type: str = TOPIC_MSG,
                 exec_command_type: str = "std_msgs/msg/String", ros2: bool = False,
                 ) -> list[Entry]:
    """A conformant ROS unit at 1 Hz for ``seconds``: heartbeat, sensor_info and
    direct_execution_info on /heartbeat_info (4), the sensors of 7 under /NAME/sensor/, and a
    commander's ping on /NAME/exec_command answered by a pong carried on /heartbeat_info.

    Faults: ``types`` (sensor -> another type), ``namespace`` (another ROS namespace),
    ``heartbeat_topic`` (the TopicMsg topic of the heartbeat), ``heartbeat_payload`` (its msg,
    as text), ``heartbeat_every=2`` (every second heartbeat at a declared 1 Hz),
    ``heartbeat_info_type`` (std_msgs/msg/String: 2.3's reading), ``exec_command_type``.
    """
    ns = name if namespace is None else namespace
    prefix = f"/{ns}" if ns else ""
    sensors = list(sensors)
    types = dict(types or {})
    agent_uuid = str(uuid.uuid4())
    out: list[Entry] = []

    def carried(topic: str, t: float, msg: Any) -> None:
        if not heartbeat_info:
            return
        text = msg if isinstance(msg, str) else json.dumps(msg)
        if heartbeat_info_type == TOPIC_MSG:
            out.append(Entry("/heartbeat_info", TOPIC_MSG, t, {"topic": topic, "msg": text}))
        else:
            out.append(Entry("/heartbeat_info", heartbeat_info_type, t, {"data": text}))

    for i in range(seconds):
        t = t0 + i
        if heartbeat_info:
            if i % heartbeat_every == 0:
                hb = {"agent-type": "ground", "agent-uuid": agent_uuid,
                      "levels": ["sensor", "direct execution"], "name": name, "rate": 1.0,
                      "stamp": t, "type": "HeartBeat"}
                carried(heartbeat_topic or f"{unit}/heartbeat", t,
                        hb if heartbeat_payload is None else heartbeat_payload)
            carried(f"{unit}/sensor_info", t + 0.01, {
                "name": name, "rate": 1.0, "agent-uuid": agent_uuid, "stamp": t + 0.01,
                "sensor-data-provided": sensors, "type": "SensorInfo"})
            carried(f"{unit}/direct_execution_info", t + 0.02, {
                "name": name, "rate": 1.0, "agent-uuid": agent_uuid, "stamp": t + 0.02,
                "type": "DirectExecutionInfo", "tasks-executing": [],
                "tasks-available": [{"name": "move-to",
                                     "signals": ["$abort", "$enough", "$pause", "$continue"]}]})
        ts = t + 0.1
        for sensor in sensors:
            msgtype = types.get(sensor) or {
                "position": GEOPOINT, "heading": "std_msgs/msg/Float32",
                "course": "std_msgs/msg/Float32", "speed": "std_msgs/msg/Float32",
                "camera_url": "std_msgs/msg/String",
                "battery_state": "sensor_msgs/msg/BatteryState"}[sensor]
            out.append(Entry(f"{prefix}/sensor/{sensor}", msgtype, ts,
                             _sensor_fields(sensor, msgtype, i, ts, ros2)))
            ts += 0.001
        if i == 3:  # a commander pings; the unit answers through its bridge (13.3)
            com_uuid = str(uuid.uuid4())
            command = json.dumps({"com-uuid": com_uuid, "command": "ping", "sender": "op0"})
            out.append(Entry(f"{prefix}/exec_command", exec_command_type, t + 0.5,
                             {"data": command}))
            carried(f"{unit}/exec/response", t + 0.6, {
                "agent-uuid": agent_uuid, "com-uuid": str(uuid.uuid4()),
                "response": "pong", "response-to": com_uuid})
    return out


def _sensor_fields(sensor: str, msgtype: str, i: int, t: float, ros2: bool) -> dict[str, Any]:
    if msgtype == GEOPOINT:
        return {"latitude": 58.3945 + i * 1e-6, "longitude": 15.5645, "altitude": 100.0}
    if msgtype == "sensor_msgs/msg/NavSatFix":
        status = {"status": 0, "service": 1}
        header = {"stamp": {"sec": int(t), "nanosec": 0}, "frame_id": "gps",
                  **({} if ros2 else {"seq": i})}
        import numpy as np
        return {"header": header, "status": status, "latitude": 58.3945 + i * 1e-6,
                "longitude": 15.5645, "altitude": 100.0,
                "position_covariance": np.zeros(9, dtype=np.float64),
                "position_covariance_type": 0}
    if msgtype == "sensor_msgs/msg/BatteryState":
        return battery(ros2, t)
    if msgtype == "std_msgs/msg/String":
        return {"data": "rtsp://127.0.0.1:8554/husky0"}
    return {"data": {"heading": 90.0, "course": 90.0, "speed": 0.5}.get(sensor, 1.0)}


def _build(store: Typestore, msgtype: str, fields: dict[str, Any]) -> Any:
    """A message object from nested field dicts."""
    cls = store.types[msgtype]
    defs = store.fielddefs[msgtype][1]
    kwargs = {}
    for fname, (_kind, detail) in defs:
        value = fields[fname]
        if isinstance(value, dict) and isinstance(detail, str):  # a nested message
            value = _build(store, detail, value)
        kwargs[fname] = value
    return cls(**kwargs)


def write_bag(path: Path, entries: Iterable[Entry], *, ros2: bool = False,
              storage: str = "sqlite3", undefined: Iterable[str] = (),
              compression: str = "") -> Path:
    """A ROS 1 bag (``path`` ends in .bag) or a ROS 2 bag directory holding ``entries``.

    ``undefined``: types written without their definition (as older ROS 2 recorders do, or a
    ROS 1 recorder that lost them), so the reader must know them from elsewhere.
    ``compression``: ROS 1 ``bz2`` or ``lz4`` chunks; ROS 2 ``storage`` (MCAP's zstd chunks),
    ``message`` (each message zstd-compressed) or ``file`` (the store compressed whole).
    """
    store = typestore(ros2)
    undefined = set(undefined)
    entries = sorted(entries, key=lambda e: e.time)
    if ros2:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer: Any = Writer2(path, version=9, storage_plugin=plugin)
    else:
        writer = Writer1(path)
    if compression and ros2:
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

        writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    elif compression:
        writer.set_compression(Writer1.CompressionFormat[compression.upper()])
    conns: dict[tuple[str, str], Any] = {}
    with writer:
        for e in entries:
            key = (e.topic, e.msgtype)
            if key not in conns:
                if e.msgtype in undefined:
                    digest = ({"rihs01": "RIHS01_" + "0" * 64} if ros2 else {"md5sum": "*"})
                    conns[key] = writer.add_connection(e.topic, e.msgtype, msgdef="", **digest)
                else:
                    conns[key] = writer.add_connection(e.topic, e.msgtype, typestore=store)
            if e.raw:
                data = e.raw
            else:
                msg = _build(store, e.msgtype, e.fields)
                data = (store.serialize_cdr(msg, e.msgtype) if ros2
                        else store.serialize_ros1(msg, e.msgtype))
            writer.write(conns[key], int(e.time * 1e9), data)
    return path


@dataclass
class LintRun:
    """A ``waraps-conformance lint --from BAG`` run: exit code, output, errors, JSON report."""

    code: int
    out: str
    err: str
    report: dict[str, Any] | None

    def verdicts(self, unit: str = UNIT) -> dict[str, str]:
        assert self.report is not None, self.err
        return {r: v["verdict"] for r, v in self.report["units"][unit]["rules"].items()}

    def failed(self, unit: str = UNIT) -> set[str]:
        return {r for r, v in self.verdicts(unit).items() if v == "fail"}

    def violations(self, rule: str, unit: str = UNIT) -> list[dict[str, Any]]:
        assert self.report is not None
        return self.report["units"][unit]["rules"][rule]["violations"]


def lint_bag(bag: Path, reports: Path, *args: str) -> LintRun:
    """``waraps-conformance lint --from BAG ARGS --plain`` in-process, JSON report only."""
    from conformance.cli.lint import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["--from", str(bag), *args, "--plain", "--format", "json",
                     "--reports-dir", str(reports)], stdout=out)
    found = sorted(reports.glob("*.json")) if reports.exists() else []
    report = json.loads(found[-1].read_text()) if found else None
    return LintRun(code, out.getvalue(), err.getvalue(), report)

"""ROS bags as traffic: the ROS side of the API (spec 4, 7, 13) mapped onto the JSON API.

A ROS 1 ``.bag`` file or a ROS 2 bag (a directory with ``metadata.yaml``, sqlite3 or MCAP
storage; or one ``.db3``/``.mcap`` file) is read with the pure-Python ``rosbags`` (no ROS
installation) and yields, in record-time order, the ``Message`` objects the JSON API would have
carried, judged by the same ``Monitor`` as MQTT traffic, and the ROS-side ``Finding`` objects
(rules ``ROS-*``) that the JSON rules cannot see:

- ``/heartbeat_info`` ``lrs_msgs_common/TopicMsg {string topic, string msg}`` (4): the message
  ``msg`` on the JSON/MQTT topic ``topic``;
- ``/UNIT/sensor/SENSOR`` (7): ``geographic_msgs/GeoPoint`` -> a GeoPoint tagged ``rostype``,
  ``std_msgs/Float32`` -> a number, ``std_msgs/String`` -> a string, other messages (e.g.
  ``sensor_msgs/BatteryState``) -> an object of their fields without ``header``;
- ``/UNIT/exec_command`` ``std_msgs/String`` (13.3.2): the JSON command on ``exec/command``.

The unit's address comes from the TopicMsg topics; ``ros_unit`` gives it for a bag that holds
only sensor topics. Times are the bag's record times (Unix seconds). Types a bag does not define
are taken from the ROS distribution's standard messages, and TopicMsg and GeoPoint from the
spec; a topic whose type is still unknown is skipped and said so in ``notes``.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from conformance.bagfile import BagError, bag_format, is_bag, is_ros2, open_bag, reason
from conformance.bagmeta import odd_count
from conformance.client import Message
from conformance.rosvalues import converter, dumps
from conformance.topics import MANDATORY_SENSORS, TopicKind, UnitAddress, parse_topic
from conformance.violation import Violation

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

TOPIC_MSG = "lrs_msgs_common/msg/TopicMsg"
GEOPOINT = "geographic_msgs/msg/GeoPoint"
FLOAT32 = "std_msgs/msg/Float32"
STRING = "std_msgs/msg/String"
BATTERY_STATE = "sensor_msgs/msg/BatteryState"

SPEC_TYPES = {
    TOPIC_MSG: "string topic\nstring msg\n",  # 4
    GEOPOINT: "float64 latitude\nfloat64 longitude\nfloat64 altitude\n",  # 7.1
}
"""Types the spec names that no ROS distribution ships: registered when a bag lacks them."""

SENSOR_TYPES = {  # 7.1 mandatory, 7.2 optional
    "position": GEOPOINT, "heading": FLOAT32, "course": FLOAT32, "speed": FLOAT32,
    "camera_url": STRING, "videoserver_url": STRING, "battery_state": BATTERY_STATE,
}

MAX_LISTED = 8
"""Topics named in a note or an error before '... and N more'."""

_SENSOR = re.compile(r"^/?(?:(?P<ns>.*)/)?sensor/(?P<sensor>[^/]+)$")
_EXEC_COMMAND = re.compile(r"^/?(?:(?P<ns>.*)/)?exec_command$")


@dataclass(frozen=True)
class Finding:
    """A ROS-side judgement for the Monitor: ``violation`` None means ``rule`` was examined on
    ``unit`` and held (``unit`` None: the finding names no unit)."""

    unit: UnitAddress | None
    rule: str
    violation: Violation | None = None


def ros_type(msgtype: str) -> str:
    """A type as the spec writes it: ``std_msgs/Float32`` (rosbags says std_msgs/msg/Float32)."""
    return msgtype.replace("/msg/", "/")


@dataclass
class _Route:
    """How the messages of one bag connection become JSON API messages."""

    kind: str  # heartbeat_info | sensor | exec_command
    namespace: str = ""
    sensor: str = ""
    unit: UnitAddress | None = None
    deserialize: Callable[[bytes, str], Any] | None = None
    convert: Callable[[Any], Any] | None = None
    seen: bool = False


_SKIP = _Route("other")


class BagReader:
    """Reads a ROS bag as ``Message`` and ``Finding`` items in record-time order.

    Raises ``BagError`` (when opened, or while reading a damaged bag) with what, where and how
    to fix it. After iterating: ``read`` messages were read from the bag, ``notes`` say what
    was skipped, ``format`` names the bag format.
    """

    def __init__(self, source: str, ros_unit: UnitAddress | None = None) -> None:
        self.path = Path(source)
        self.name = str(self.path)
        self.ros_unit = ros_unit
        self.read = 0
        self.undecodable = 0
        self.not_topic_msg = 0
        self.notes: list[str] = []
        self.ros2 = is_ros2(self.path)
        self.format = bag_format(self.path)
        self._units: dict[str, UnitAddress] = {}
        self._sensor_units: set[UnitAddress] = set()
        self._topic_msg_topics: set[str] = set()

    # --- opening ----------------------------------------------------------------------------
    # --- reading ----------------------------------------------------------------------------
    def __iter__(self) -> Iterator[Message | Finding]:
        reader = open_bag(self.path)
        try:
            yield from self._items(reader)
        finally:
            reader.close()

    def _items(self, reader: Any) -> Iterator[Message | Finding]:
        routes = self._routes(reader.connections)
        self._prepare(reader, routes)
        try:
            self._scan_units(reader, routes)
        except Exception as e:  # a damaged chunk or database page
            raise self._damaged(e) from None
        self.undecodable = self.not_topic_msg = 0  # counted again by the main pass
        self._attribute(routes)
        linted = [c for c in reader.connections if routes.get(c.id, _SKIP).deserialize]
        self._check_counts(reader)
        indexed = sum(c.msgcount for c in linted)
        last = 0.0
        try:
            for conn, stamp, raw in reader.messages(connections=linted):
                self.read += 1
                t = last = stamp / 1e9
                route = routes[conn.id]
                if not route.seen:
                    route.seen = True
                    yield from self._connection_findings(conn, route, t)
                item = self._message(conn, route, raw, t)
                if item is not None:
                    yield from item
        except Exception as e:  # a damaged chunk or database page in the middle of the bag
            raise self._damaged(e) from None
        if self.read != indexed:  # read whole or refused: never a verdict on part of a bag
            own = ("metadata.yaml" if self.ros2 and self.path.is_dir()
                   else "its index" if not self.ros2 else "its own message count")
            raise BagError(
                f"{self.path}: {own} says the bag holds {indexed} messages on the topics "
                f"linted, but {self.read} could be read (the bag is damaged or cut off), so "
                f"nothing was judged. Fix: reindex it ('rosbag reindex' / 'ros2 bag reindex') "
                f"or record it again")
        if self.not_topic_msg:
            self.notes.append(f"{self.not_topic_msg} /heartbeat_info message(s) were not linted: "
                              f"they have no string fields 'topic' and 'msg' (ROS-003)")
        if self.undecodable:  # a damaged container gives no verdict
            raise BagError(f"{self.path}: {self.undecodable} message(s) could not be deserialized "
                           f"with their connection's type (the bag is damaged), so nothing was "
                           f"judged. Fix: record it again")
        yield from self._mandatory_sensors(routes, last)

    def _check_counts(self, reader: Any) -> None:
        """The bag's own counts (metadata.yaml's, as rosbags read them, or its index) agree
        with each other, else a BagError: nothing is judged on a damaged index."""
        total = getattr(reader, "message_count", None)
        why = odd_count(self.path, [*(c.msgcount for c in reader.connections), total])
        if why:
            raise BagError(why)
        if total is not None and total != sum(c.msgcount for c in reader.connections):
            raise BagError(
                f"{self.path}: the bag's own counts disagree ({total} messages in all, "
                f"{sum(c.msgcount for c in reader.connections)} over its topics): its index "
                f"or metadata.yaml is damaged, so nothing was judged. Fix: reindex it "
                f"('rosbag reindex' / 'ros2 bag reindex') or record it again")

    def _damaged(self, e: Exception) -> BagError:
        return BagError(f"{self.path}: the bag is damaged after {self.read} messages "
                        f"({reason(e)}), so nothing was judged. Fix: reindex it ('rosbag "
                        f"reindex' / 'ros2 bag reindex') or record it again")

    def _routes(self, connections: list[Connection]) -> dict[int, _Route]:
        """The WARA-PS connections (4, 7, 13.3.2); BagError when there are none."""
        routes: dict[int, _Route] = {}  # by connection id (a ROS 2 Connection is unhashable)
        others: set[str] = set()
        for conn in connections:
            topic = conn.topic
            if topic == "/heartbeat_info" or topic.endswith("/heartbeat_info"):
                routes[conn.id] = _Route("heartbeat_info")
            elif m := _SENSOR.match(topic):
                routes[conn.id] = _Route("sensor", m["ns"] or "", m["sensor"])
            elif m := _EXEC_COMMAND.match(topic):
                routes[conn.id] = _Route("exec_command", m["ns"] or "")
            else:
                others.add(topic)
        if not routes:
            raise BagError(
                f"{self.path}: no WARA-PS topic in this bag (4, 7, 13: /heartbeat_info, "
                f"/UNIT/sensor/SENSOR, /UNIT/exec_command); it holds "
                f"{_listed(sorted(others)) or 'no topic at all'}. Fix: record the unit's topics, "
                f"e.g. rosbag record /heartbeat_info -e '/dji0/sensor/.*'")
        if others:
            self.notes.append(f"{len(others)} topic(s) outside the WARA-PS API were not read: "
                              f"{_listed(sorted(others))}")
        return routes

    def _prepare(self, reader: Any, routes: dict[int, _Route]) -> None:
        """A deserializer for each connection: the bag's own definition of its type, else the
        distribution's standard one or the spec's (SPEC_TYPES); else the topic is skipped."""
        from rosbags.interfaces import MessageDefinitionFormat
        from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

        own = get_typestore(Stores.EMPTY)
        standard: Typestore | None = None
        skipped: list[str] = []
        for conn in reader.connections:
            route = routes.get(conn.id)
            if route is None:
                continue
            store: Typestore | None = None
            msgdef = conn.msgdef
            if msgdef.data.strip() and msgdef.format is not MessageDefinitionFormat.NONE:
                try:
                    types = (get_types_from_msg(msgdef.data, conn.msgtype)
                             if msgdef.format is MessageDefinitionFormat.MSG
                             else get_types_from_idl(msgdef.data))
                    own.register(types)
                    store = own if conn.msgtype in own.types else None
                except Exception:  # an unparsable or conflicting definition: try the standard
                    store = None
            if store is None:
                if standard is None:
                    standard = get_typestore(Stores.LATEST if self.ros2 else Stores.ROS1_NOETIC)
                    spec: dict[str, Any] = {}
                    for name, text in SPEC_TYPES.items():
                        if name not in standard.types:
                            spec.update(get_types_from_msg(text, name))
                    standard.register(spec)
                store = standard if conn.msgtype in standard.types else None
            if store is None:
                skipped.append(f"{conn.topic} ({ros_type(conn.msgtype)})")
                continue
            route.deserialize = store.deserialize_cdr if self.ros2 else store.deserialize_ros1
        if skipped:
            self.notes.append(f"{len(skipped)} topic(s) skipped: their type is defined neither "
                              f"in the bag nor in ROS's standard messages or the spec: "
                              f"{_listed(skipped)}")

    def _scan_units(self, reader: Any, routes: dict[int, _Route]) -> None:
        """The units of the bag, from the topics of its TopicMsgs (4), read before the main
        pass so that sensor topics earlier than the first heartbeat are attributed too; it
        stops once every namespace has its unit (the main pass adds later units)."""
        conns = [c for c in reader.connections
                 if routes.get(c.id, _SKIP).kind == "heartbeat_info" and routes[c.id].deserialize]
        namespaces = {r.namespace for r in routes.values() if r.kind != "heartbeat_info"}
        if not conns:
            return
        for conn, _, raw in reader.messages(connections=conns):
            pair = self._topic_msg(routes[conn.id], raw, conn.msgtype)
            unit = parse_topic(pair[0]).unit if pair is not None else None
            if unit is not None and unit.name not in self._units:
                self._units[unit.name] = unit
                if namespaces <= self._units.keys():
                    break

    @property
    def fallback(self) -> UnitAddress | None:
        """The unit of topics that name none: ``ros_unit``, else the bag's only unit."""
        if self.ros_unit is not None:
            return self.ros_unit
        return next(iter(self._units.values())) if len(self._units) == 1 else None

    def _attribute(self, routes: dict[int, _Route]) -> None:
        """The unit of each namespaced connection (7: UNIT/sensor/SENSOR, 13.3.2)."""
        unattributed = sorted({f"/{r.namespace}" for r in routes.values()
                               if r.kind != "heartbeat_info" and r.deserialize
                               and r.namespace not in self._units and self.fallback is None})
        if unattributed and not self._units:
            raise BagError(
                f"{self.path}: no unit address for the topics of {', '.join(unattributed)}: no "
                f"/heartbeat_info TopicMsg in the bag names a unit (4). Fix: pass "
                f"--ros-unit PREFIX/unit/TYPE/ROLE/NAME, e.g. --ros-unit "
                f"waraps/unit/ground/real/{unattributed[0].strip('/') or 'husky0'}")
        if unattributed:
            self.notes.append(f"topics of {', '.join(unattributed)} were not linted: no unit of "
                              f"that name sends /heartbeat_info; pass --ros-unit to name it")
        for route in routes.values():
            if route.kind != "heartbeat_info":
                route.unit = self._units.get(route.namespace) or self.fallback
                if route.unit is None:
                    route.deserialize = None

    # --- findings ---------------------------------------------------------------------------
    def _connection_findings(self, conn: Connection, route: _Route,
                             t: float) -> Iterator[Finding]:
        """The rules about a connection's type and name, judged at its first message."""
        unit = route.unit or self.fallback
        have = ros_type(conn.msgtype)
        if route.kind == "heartbeat_info":
            yield self._judge(unit, "ROS-003", have == ros_type(TOPIC_MSG), conn.topic, t,
                              ros_type(TOPIC_MSG), have,
                              "4: heartbeat/info messages go out as TopicMsg {string topic, "
                              "string msg}, so the topic travels with the JSON")
            return
        if route.kind == "exec_command":
            yield self._judge(unit, "ROS-006", have == ros_type(STRING), conn.topic, t,
                              ros_type(STRING), have, "13.3.2: exec_command (String) carries "
                              "the JSON command")
        else:
            expected = SENSOR_TYPES.get(route.sensor)
            if expected is not None:
                yield self._judge(unit, "ROS-002", conn.msgtype == expected, conn.topic, t,
                                  ros_type(expected), have,
                                  f"7: /UNIT/sensor/{route.sensor} is a {ros_type(expected)}")
        assert route.unit is not None
        yield self._judge(route.unit, "ROS-005", route.namespace == route.unit.name, conn.topic,
                          t, f"/{route.unit.name}/...", conn.topic,
                          f"7, 7.3: the namespace is the unit's name ({route.unit}); topics "
                          f"of /{route.namespace} were judged as this unit's")

    @staticmethod
    def _judge(unit: UnitAddress | None, rule: str, holds: bool, topic: str, t: float | None,
               expected: str, observed: str, detail: str) -> Finding:
        if holds:
            return Finding(unit, rule)
        return Finding(unit, rule, Violation.of(
            rule, expected=expected, observed=observed, topic=topic, time=t, detail=detail,
            unit=str(unit) if unit is not None else ""))

    def _mandatory_sensors(self, routes: dict[int, _Route],
                           t: float) -> Iterator[Finding]:
        """ROS-001 for every unit with a sensor topic or a heartbeat claiming the sensor level."""
        recorded: dict[UnitAddress, set[str]] = {u: set() for u in self._sensor_units}
        for route in routes.values():
            if route.kind == "sensor" and route.unit is not None:
                recorded.setdefault(route.unit, set()).add(route.sensor)
        for unit, sensors in sorted(recorded.items()):
            missing = [s for s in MANDATORY_SENSORS if s not in sensors]
            if not missing:
                yield Finding(unit, "ROS-001")
            for sensor in missing:
                yield Finding(unit, "ROS-001", Violation.of(
                    "ROS-001", expected=f"/{unit.name}/sensor/{sensor} "
                                        f"({ros_type(SENSOR_TYPES[sensor])})",
                    observed=f"no /{unit.name}/sensor/{sensor} topic in the bag",
                    topic=f"/{unit.name}/sensor/{sensor}", time=t, unit=str(unit),
                    detail="7.1: position, heading, course and speed are mandatory"))

    # --- messages ---------------------------------------------------------------------------
    def _message(self, conn: Connection, route: _Route, raw: bytes,
                 t: float) -> tuple[Message | Finding, ...] | None:
        if route.kind == "heartbeat_info":
            pair = self._topic_msg(route, raw, conn.msgtype)
            if pair is None:
                return None
            return self._carried(conn, pair[0], pair[1], t)
        try:
            msg = route.deserialize(raw, conn.msgtype)  # type: ignore[misc]
            convert = route.convert
            if convert is None:  # worked out once per connection, from its first message
                convert = route.convert = converter(route.kind, type(msg))
            value = convert(msg)
            assert route.unit is not None
        except Exception:  # a message its connection's type cannot read: skip it
            self.undecodable += 1
            return None
        if route.kind == "exec_command":
            if not isinstance(value, str):
                return None
            return (Message(t, route.unit.topic("exec/command"), value.encode()),)
        return (Message(t, route.unit.topic(f"sensor/{route.sensor}"), dumps(value)),)

    def _topic_msg(self, route: _Route, raw: bytes, msgtype: str) -> tuple[str, str] | None:
        """(topic, msg) of a TopicMsg, or of any type with those two string fields."""
        try:
            m = route.deserialize(raw, msgtype)  # type: ignore[misc]
        except Exception:
            self.undecodable += 1
            return None
        topic, msg = getattr(m, "topic", None), getattr(m, "msg", None)
        if isinstance(topic, str) and isinstance(msg, str):
            return topic, msg
        self.not_topic_msg += 1
        return None

    def _carried(self, conn: Connection, topic: str, msg: str,
                 t: float) -> tuple[Message | Finding, ...] | None:
        """The JSON message a TopicMsg carries (4), and ROS-004 once per distinct topic."""
        parsed = parse_topic(topic)
        if parsed.unit is not None:
            self._units.setdefault(parsed.unit.name, parsed.unit)
            if parsed.kind is TopicKind.SENSOR_INFO:  # on the sensor level (5.2): ROS-001
                self._sensor_units.add(parsed.unit)
        fed = topic
        if parsed.unit is None:  # a relative topic ('heartbeat'): the bag's unit, if it has one
            fallback = self.fallback
            fed = fallback.topic(topic.strip("/")) if fallback is not None else ""
            if fed and parse_topic(fed).kind is TopicKind.UNKNOWN:
                fed = ""
        out: list[Message | Finding] = []
        if topic not in self._topic_msg_topics:
            self._topic_msg_topics.add(topic)
            holds = parsed.unit is not None and parsed.kind is not TopicKind.UNKNOWN
            unit = parsed.unit or self.fallback
            out.append(self._judge(
                unit, "ROS-004", holds, conn.topic, t,
                "the JSON/MQTT topic of the message, PREFIX1/unit/TYPE/ROLE/UNIT/heartbeat (or "
                "sensor_info, direct_execution_info, ...)", repr(topic),
                "4: 'the topic used in the JSON/MQTT API is put on the msg also'"
                + (f"; read as {fed}" if fed and fed != topic else
                   "; its msg was not linted" if not fed else "")))
        if fed:
            out.append(Message(t, fed, msg.encode("utf-8", "surrogateescape")))
        return tuple(out)


def _listed(items: list[str]) -> str:
    shown = ", ".join(items[:MAX_LISTED])
    return shown + (f" and {len(items) - MAX_LISTED} more" if len(items) > MAX_LISTED else "")


__all__ = ["BagError", "BagReader", "Finding", "is_bag", "ros_type"]

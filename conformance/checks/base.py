"""What checks read: the state of a unit (``UnitState``) and the run's ``CheckContext``.

The checks themselves are registered in ``checks/registry.py``. Checks mark what they examined (``unit.examine(rule)``): a rule passes only when examined. When
a check cannot judge yet it leaves a note (``unit.note(rule, "only 3 intervals; need 10")``)
that becomes the skip reason.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, TypeGuard

from conformance.checks.stall import StallWatch
from conformance.checks.stash import Stash, StashKey
from conformance.facts import RunKind
from conformance.message import Message
from conformance.profile import Profile
from conformance.topics import TopicKind, UnitAddress, level_name
from conformance.validator import Validation


class BoundedDict(OrderedDict[Any, Any]):
    """An LRU mapping holding at most ``limit`` entries (bounded memory for any run length)."""

    def __init__(self, limit: int = 4096) -> None:  # a default: copy and pickle call cls()
        super().__init__()
        self.limit = limit
        self.evicted = 0

    def __setitem__(self, key: Any, value: Any) -> None:
        if key in self:
            self.move_to_end(key)
        super().__setitem__(key, value)
        if len(self) > self.limit:
            self.popitem(last=False)
            self.evicted += 1


SENSORS_LISTED_RAW: StashKey[list[Any]] = StashKey("sensors-listed-raw")
LEVELS_RAW: StashKey[list[Any]] = StashKey("levels-raw")
TASKS_AVAILABLE_RAW: StashKey[Any] = StashKey("tasks-available-raw")
"""The latest raw lists of the unit's info messages: one unchanged since (the usual case) is
not read again."""

MAX_AGENT_UUIDS = 16
MAX_SENSORS = 256
MAX_KIND_COUNTS = 64
MAX_TASKS = 256


class Arrivals:
    """The messages of one validation kind of one unit: how many, when the first and the latest
    arrived, and when the first and the latest live (not retained) one arrived. Counted on every message in slots (a few attribute
    stores instead of a dozen dict updates); ``UnitState``'s per-kind dicts are made from
    these when read."""

    __slots__ = ("kind", "vkind", "sensor", "order", "n", "first", "last", "first_live",
                 "last_live")

    def __init__(self, kind: TopicKind, vkind: str, sensor: str, order: int, t: float) -> None:
        self.kind = kind
        self.vkind = vkind
        self.sensor = sensor
        self.order = order
        self.n = 0
        self.first = t
        self.last = t
        self.first_live: float | None = None
        self.last_live: float | None = None


@dataclass(eq=False)
class UnitState:
    """What the observer knows about one unit, from its own messages (read by active scenarios).

    Times are arrival times in Unix seconds, rates in Hz, positions in degrees and metres.
    Every collection is bounded, whatever a unit publishes.
    """

    address: UnitAddress
    agent_uuid: str | None = None
    """The agent-uuid of the latest heartbeat."""
    agent_uuids: list[str] = field(default_factory=list)
    """Distinct agent-uuids seen in heartbeats, in order (at most 16)."""
    agent_type: str | None = None
    levels: tuple[str, ...] | None = None
    """Declared levels (5.1), normalised to the spaced form; None until a heartbeat is seen."""
    declared_rates: dict[str, float] = field(default_factory=dict)
    """Topic kind (heartbeat, sensor_info, ...) -> declared rate in Hz."""
    tasks_available: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """Task name -> signals it understands (5.3)."""
    tasks_executing: dict[str, str] = field(default_factory=dict)
    """task-uuid -> task-name (5.3)."""
    sensors_listed: tuple[str, ...] | None = None
    """sensor-data-provided of the latest sensor_info; None until one is seen."""
    position: tuple[float, float, float | None] | None = None
    """Latest (latitude, longitude, altitude) from sensor/position."""
    position_time: float | None = None
    speed: float | None = None
    max_speed: float = 0.0
    last_heartbeat: float | None = None
    """Arrival time of the latest live (not retained) heartbeat."""
    heartbeat_retained: bool = True
    """Whether the latest heartbeat was a retained copy (its publication time is unknown)."""
    arrivals: dict[str, Arrivals] = field(default_factory=dict, repr=False)
    """Validation kind -> its arrivals: the first MAX_KIND_COUNTS kinds that are not sensors
    and the first MAX_SENSORS sensors; the messages of further kinds are counted by topic
    kind in ``arrivals_beyond``. Read through ``counts``, ``kinds_seen``, ``sensors_seen``,
    ``first_by_kind`` and ``last_by_kind``."""
    arrivals_beyond: dict[TopicKind, Arrivals] = field(default_factory=dict, repr=False)
    examined: dict[str, int] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)
    stash: Stash = field(default_factory=Stash, repr=False)
    """The unit's typed components, each owned by one module, under its ``StashKey``
    (conversations, the model, rate trackers, identity, ...: ``checks/stash.py``)."""

    def examine(self, rule: str, times: int = 1) -> None:
        """Mark ``rule`` as examined on this unit (it may now pass)."""
        self.examined[rule] = self.examined.get(rule, 0) + times

    def note(self, rule: str, why: str) -> None:
        """Why ``rule`` could not be judged (yet): the skip reason if it never is."""
        self.notes[rule] = why

    def period(self, kind: TopicKind | str) -> float | None:
        """The declared period in seconds of a periodic message kind, None when not declared."""
        rate = self.declared_rates.get(kind)  # a TopicKind hashes and compares as its value
        return 1.0 / rate if rate else None

    def claims(self, level: str) -> bool:
        return self.levels is not None and level in self.levels

    # -- what arrived, by kind (made from ``arrivals`` when read) -------------------------

    @property
    def counts(self) -> dict[str, int]:
        """Validation kind (heartbeat, sensor/position, exec/command/ping, ...) -> messages,
        for the first MAX_KIND_COUNTS kinds seen."""
        kept = sorted(self.arrivals.values(), key=lambda a: a.order)[:MAX_KIND_COUNTS]
        return {a.vkind: a.n for a in kept}

    @property
    def message_count(self) -> int:
        return sum(a.n for a in (*self.arrivals.values(), *self.arrivals_beyond.values()))

    @property
    def first_seen(self) -> float | None:
        """Arrival time of the unit's first message (retained ones included)."""
        return min((a.first for a in (*self.arrivals.values(), *self.arrivals_beyond.values())),
                   default=None)

    @property
    def last_seen(self) -> float | None:
        """Arrival time of the unit's latest message (retained ones included)."""
        return max((a.last for a in (*self.arrivals.values(), *self.arrivals_beyond.values())),
                   default=None)

    @property
    def kinds_seen(self) -> dict[TopicKind, int]:
        """Topic kind -> messages, retained ones included."""
        out: dict[TopicKind, int] = {}
        for a in (*self.arrivals.values(), *self.arrivals_beyond.values()):
            out[a.kind] = out.get(a.kind, 0) + a.n
        return out

    @property
    def sensors_seen(self) -> dict[str, int]:
        """Sensor name -> messages seen (at most MAX_SENSORS names)."""
        return {a.sensor: a.n for a in sorted(self.arrivals.values(), key=lambda a: a.order)
                if a.sensor}

    @property
    def first_by_kind(self) -> dict[TopicKind, float]:
        """Topic kind -> arrival time of its first live (not retained) message."""
        out: dict[TopicKind, float] = {}
        for a in (*self.arrivals.values(), *self.arrivals_beyond.values()):
            if a.first_live is not None and (a.kind not in out or a.first_live < out[a.kind]):
                out[a.kind] = a.first_live
        return out

    @property
    def last_by_kind(self) -> dict[TopicKind, float]:
        """Topic kind -> arrival time of its latest live (not retained) message."""
        out: dict[TopicKind, float] = {}
        for a in (*self.arrivals.values(), *self.arrivals_beyond.values()):
            if a.last_live is not None and (a.kind not in out or a.last_live > out[a.kind]):
                out[a.kind] = a.last_live
        return out

    def _arrivals_of(self, v: Validation, t: float) -> Arrivals:
        """The arrivals a message of a validation kind not seen before is counted in."""
        kind = v.topic.kind
        sensor = v.topic.sensor if kind is _SENSOR else ""
        arrivals = self.arrivals
        same = [a for a in arrivals.values() if bool(a.sensor) == bool(sensor)]
        if len(same) < (MAX_SENSORS if sensor else MAX_KIND_COUNTS):
            a = arrivals[v.kind] = Arrivals(kind, v.kind, sensor, len(arrivals), t)
            return a
        beyond = self.arrivals_beyond.get(kind)
        if beyond is None:
            beyond = self.arrivals_beyond[kind] = Arrivals(kind, "", "", -1, t)
        return beyond

    # -- updating from one message (after the message checks ran) --------------------------

    def observe(self, msg: Message, v: Validation) -> None:
        # On every message: module constants, not TopicKind.X (an Enum class attribute costs
        # ~0.2 us in Python 3.11), and no more dict operations than needed.
        t = msg.time
        a = self.arrivals.get(v.kind)
        if a is None:
            a = self._arrivals_of(v, t)
        a.n += 1
        a.last = t
        retain = msg.retain
        if not retain:
            a.last_live = t
            if a.first_live is None:
                a.first_live = t
        kind = v.topic.kind
        m = v.message
        if kind is _SENSOR:
            self._observe_sensor(v.topic.sensor, m, t)
            return
        if kind is _HEARTBEAT:
            # Any heartbeat arrival, even one that does not parse, shows the unit is alive (HB-010).
            self.heartbeat_retained = retain
            if not retain:
                self.last_heartbeat = t
        if not isinstance(m, dict):
            return
        periodic = _PERIODIC.get(kind)
        if periodic is None:
            return
        rate = usable_rate(m.get("rate"))
        if rate is not None:
            self.declared_rates[periodic] = rate
        if kind is _HEARTBEAT:
            self._observe_heartbeat(m)
        elif kind is _SENSOR_INFO:
            listed = m.get("sensor-data-provided")
            if isinstance(listed, list) and listed != self.stash.get(SENSORS_LISTED_RAW):
                self.stash[SENSORS_LISTED_RAW] = listed
                self.sensors_listed = tuple(s for s in listed if isinstance(s, str))[:MAX_SENSORS]
        elif kind is _DIRECT_EXECUTION_INFO:
            self._observe_direct_execution_info(m)

    def _observe_heartbeat(self, m: dict[str, Any]) -> None:
        uuid = m.get("agent-uuid")
        if isinstance(uuid, str):
            self.agent_uuid = uuid
            if uuid not in self.agent_uuids:
                self.agent_uuids.append(uuid)
                del self.agent_uuids[:-MAX_AGENT_UUIDS]
        agent_type = m.get("agent-type")
        if isinstance(agent_type, str):
            self.agent_type = agent_type
        levels = m.get("levels")
        if isinstance(levels, list) and (self.levels is None
                                         or levels != self.stash.get(LEVELS_RAW)):
            self.stash[LEVELS_RAW] = levels  # unchanged since (the usual case): kept
            # ERR-008: 'direct_execution' is read as 'direct execution' (the warning is the
            # validator's); the claim is the same.
            self.levels = tuple(level_name(lv) for lv in levels if isinstance(lv, str))[:8]

    def _observe_direct_execution_info(self, m: dict[str, Any]) -> None:
        available = m.get("tasks-available")
        if available == self.stash.get(TASKS_AVAILABLE_RAW):
            available = None  # unchanged since the last one (the usual case): nothing to do
        else:
            self.stash[TASKS_AVAILABLE_RAW] = available
        if isinstance(available, list):
            tasks: dict[str, tuple[str, ...]] = {}
            for task in available[:MAX_TASKS]:
                if isinstance(task, dict) and isinstance(task.get("name"), str):
                    signals = task.get("signals")
                    tasks[task["name"]] = tuple(
                        s for s in signals if isinstance(s, str)) if isinstance(signals, list) else ()
            self.tasks_available = tasks
        executing = m.get("tasks-executing")
        if isinstance(executing, list):
            self.tasks_executing = {
                task["task-uuid"]: str(task.get("task-name", ""))
                for task in executing[:MAX_TASKS]
                if isinstance(task, dict) and isinstance(task.get("task-uuid"), str)}

    def _observe_sensor(self, name: str, m: Any, t: float) -> None:
        if name == "position":
            point = geopoint(m)
            if point is not None:
                self.position = point
                self.position_time = t
        elif name == "speed" and _is_number(m) and math.isfinite(m):
            self.speed = float(m)
            self.max_speed = max(self.max_speed, abs(float(m)))


_SENSOR, _HEARTBEAT = TopicKind.SENSOR, TopicKind.HEARTBEAT
_SENSOR_INFO, _DIRECT_EXECUTION_INFO = TopicKind.SENSOR_INFO, TopicKind.DIRECT_EXECUTION_INFO
_PERIODIC = {k: k.value for k in (TopicKind.HEARTBEAT, TopicKind.SENSOR_INFO,
                                  TopicKind.DIRECT_EXECUTION_INFO, TopicKind.TST_EXECUTION_INFO)}


def usable_rate(x: Any) -> float | None:
    """``x`` as a declared rate in Hz, None unless it is a number whose period (1/rate, in
    seconds) is finite and above zero: 1e-310 Hz passes the schema's '> 0' but its period is
    infinite, and every deadline measured in it would be too (refused as a value)."""
    if not _is_number(x) or not x > 0:
        return None
    try:
        rate = float(x)  # an int of 400 digits overflows
        period = 1.0 / rate
    except (OverflowError, ZeroDivisionError):
        return None
    return rate if math.isfinite(rate) and 0.0 < period < math.inf else None


def _is_number(x: object) -> TypeGuard[float]:
    t = type(x)
    return t is float or t is int or (isinstance(x, (int, float)) and not isinstance(x, bool))


def geopoint(m: Any) -> tuple[float, float, float | None] | None:
    """(latitude, longitude, altitude) of a GeoPoint (6.1), None when it is not one."""
    if not isinstance(m, dict):
        return None
    lat, lon, alt = m.get("latitude"), m.get("longitude"), m.get("altitude")
    if type(lat) is float and type(lon) is float:  # the usual case, decided without calls
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return None
        return lat, lon, float(alt) if type(alt) is float or _is_number(alt) else None
    if not (_is_number(lat) and _is_number(lon)) or not (
            -90 <= lat <= 90 and -180 <= lon <= 180):
        return None
    return float(lat), float(lon), float(alt) if _is_number(alt) else None


class CheckContext:
    """What checks may read besides the unit: the profile, the run kind, the observer's gaps."""

    def __init__(self, profile: Profile, kind: RunKind) -> None:
        self.profile = profile
        self.kind = kind
        self.started: float | None = None
        """Arrival time of the first message the observer saw (of any unit)."""
        self.gaps: list[tuple[float, float]] = []
        self.stalls = StallWatch(self)
        """The broker's stalls found in the traffic, each marked as a gap: ``found``, ``count``
        (``Monitor.feed`` feeds it every message before any check)."""
        self.quiet: float | None = None
        """While messages arrive in a burst after a silence of every topic (a stall of the
        broker, perhaps: ``checks/stall.py``): when that silence began; None otherwise."""
        self.reboots: list[float] = []
        """When the observer's side (the suite) rebooted the unit: a silence that only such a
        reboot ended was a death (HB-012), not a silence the unit came back from."""

    MAX_GAPS = 1000

    def add_gap(self, start: float, end: float) -> None:
        if end < start:
            start, end = end, start
        gaps = self.gaps
        if gaps and start <= gaps[-1][1]:  # overlapping or touching the last one: merge
            gaps[-1] = (min(gaps[-1][0], start), max(gaps[-1][1], end))
        else:
            gaps.append((start, end))
            gaps.sort()
        if len(gaps) > self.MAX_GAPS:
            # Bounded memory: merge the oldest two (they only ever widen an exclusion).
            gaps[0:2] = [(gaps[0][0], gaps[1][1])]

    def close_gap(self, end: float) -> None:
        """The open gap (``add_gap(start, math.inf)``: the observer is back, but the unit not
        yet heard again) ends at ``end``."""
        if self.gaps and self.gaps[-1][1] == math.inf:
            start = self.gaps[-1][0]
            self.gaps[-1] = (start, max(start, float(end)))

    def gaps_until(self, now: float) -> list[tuple[float, float]]:
        """The gaps as a report shows them: one still open (the unit not heard again) ends
        at ``now``."""
        return [(start, min(end, max(start, now))) for start, end in self.gaps]

    def in_gap(self, t0: float, t1: float) -> bool:
        """Whether [t0, t1] overlaps a time the observer was disconnected."""
        for start, end in reversed(self.gaps):
            if end < t0:
                return False
            if start <= t1:
                return True
        return False

    def gap_overlap(self, t0: float, t1: float) -> float:
        """Seconds of [t0, t1] during which the observer was disconnected."""
        total = 0.0
        for start, end in reversed(self.gaps):
            if end < t0:
                break
            total += max(0.0, min(end, t1) - max(start, t0))
        return total

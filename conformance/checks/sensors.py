"""Sensors over time (spec 5.2, 6): every listed sensor published (SI-003), the mandatory four
listed and published (SI-004), no unlisted sensor topics (SI-005), and positions that move no
faster than the reported speed allows (SENS-005)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from typing import Any

from conformance.checks.base import CheckContext, UnitState, geopoint
from conformance.checks.registry import check, reinterprets
from conformance.checks.stash import StashKey
from conformance.message import Message
from conformance.topics import MANDATORY_SENSORS, SENSOR_LEVEL, TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

SI = TopicKind.SENSOR_INFO
PUBLISH_WINDOW_PERIODS = 3.0
"""A listed sensor is judged unpublished only after 3 declared periods of the slower of
heartbeat and sensor_info since the first sensor_info (sensors declare no rate of their own)."""
MIN_JUMP_INTERVAL = 0.5
"""SENS-005 compares positions at least 0.5 s apart: arrival-time jitter
(docs/FIELD-NOTES.md 'Timing jitter': up to
tens of ms) over a shorter interval would turn metre-level noise into absurd speeds."""
BURST_GAP = 0.002
"""Positions arriving closer than this were queued and flushed together (a broker or link
catching up; docs/FIELD-NOTES.md 'Timing jitter': +-0.7 ms idle, 1-7 ms loaded between messages
sent a
period apart): their arrival times are not when they were sent, so the latest of them is the
new anchor and none is compared with one from before the burst."""
SAME_INSTANT = 0.05
"""Seconds within which a speed belongs to the position published with it (SENS-005): a unit
publishes its sensors of one instant together, in an order of its own (6.1 sets none),
and they arrive a few ms apart (docs/FIELD-NOTES.md 'Timing jitter': 1-7 ms loaded)."""
EARTH_RADIUS = 6_371_000.0  # metres


class SensorsSeen:
    """What the sensor checks keep of a unit between its messages."""

    __slots__ = ("heading_range_said", "missing_listed", "unlisted_reported", "anchor",
                 "last_position", "held")

    def __init__(self) -> None:
        self.heading_range_said = False
        """SENS-002 was said once for this unit."""
        self.missing_listed: tuple[Any, ...] | None = None
        """The latest sensor list SI-004 found wanting (a violation per distinct list)."""
        self.unlisted_reported: set[str] = set()
        """Sensors already reported unlisted (SI-005)."""
        self.anchor: tuple[tuple[float, float, float | None], float, str | None] | None = None
        """(point, time, life) the next position is compared with (SENS-005)."""
        self.last_position: float | None = None
        """Arrival time of the latest live position (SENS-005: bursts)."""
        self.held: Jump | None = None
        """A position step too fast for the speeds known when it came, held until the speed
        of the same instant is known (SENS-005: the pair is judged together)."""


@dataclasses.dataclass(frozen=True)
class Jump:
    """A position step (SENS-005): ``metres`` in ``seconds``, the position's ``time``,
    ``topic`` and ``payload``, and the largest speed reported so far (m/s)."""

    metres: float
    seconds: float
    time: float
    topic: str
    payload: bytes
    speed: float

    @property
    def limit(self) -> float:
        """The fastest plausible step, m/s: 3x the largest reported speed + 5 m/s."""
        return 3 * self.speed + 5.0

    def too_fast(self) -> bool:
        return self.metres > self.limit * self.seconds

    def violation(self) -> Violation:
        return Violation.of(
            "SENS-005", expected=f"at most {self.limit:.1f} m/s (3x the largest reported "
                                 f"speed {self.speed:.1f} m/s, + 5 m/s)",
            observed=f"moved {self.metres:.1f} m in {self.seconds:.2f} s "
                     f"({self.metres / self.seconds:.1f} m/s)", topic=self.topic,
            time=self.time, payload=self.payload,
            detail="check units: speed in m/s (6.1), latitude/longitude in degrees")


SENSORS_SEEN: StashKey[SensorsSeen] = StashKey("sensors-seen")
_RADIANS = math.pi / 180


def _listed(v: Validation) -> list[str] | None:
    m = v.message
    listed = m.get("sensor-data-provided") if isinstance(m, dict) else None
    if not isinstance(listed, list):
        return None
    return [s for s in listed if isinstance(s, str)]


@reinterprets("SENS-002", on=(TopicKind.SENSOR,), reads=(SENSORS_SEEN,))
def angle_range_once(ctx: CheckContext, unit: UnitState, msg: Message, v: Validation,
                     found: list[Violation]) -> list[Violation]:
    """6.1 says only 'heading : float' (and course): the range [0, 360) is this suite's
    decision (SENS-002), an interop risk, not a fault of each message. It is said once per
    unit, on the first value outside it, and not repeated (a unit that sends
    headings in (-180, 180] would otherwise warn at every message)."""
    if not found:
        return found
    kept: list[Violation] = []
    for f in found:
        if f.rule != "SENS-002":
            kept.append(f)
        elif not (seen := unit.stash.setdefault(SENSORS_SEEN, SensorsSeen)).heading_range_said:
            seen.heading_range_said = True
            kept.append(dataclasses.replace(
                f, detail="6.1 says 'float' and states no range: [0, 360) is this suite's "
                          "decision; said once per unit, later values are not repeated"))
    return kept


@check("SI-004", on=(SI,), reads=(SENSORS_SEEN,))
def mandatory_sensors_listed(ctx: CheckContext, unit: UnitState, msg: Message,
                             v: Validation) -> list[Violation] | None:
    """6.1: position, heading, course and speed are mandatory: each sensor_info lists them
    (a violation per distinct list, not per message)."""
    listed = _listed(v)
    if listed is None:
        return None
    unit.examine("SI-004")
    missing = [s for s in MANDATORY_SENSORS if s not in listed]
    key = tuple(listed)
    if not missing:
        return None
    seen = unit.stash.setdefault(SENSORS_SEEN, SensorsSeen)
    if seen.missing_listed == key:
        return None
    seen.missing_listed = key
    return [Violation.of(  # decided: 5.2's own examples leave heading and course out
        "SI-004", condition="listed",
        expected=f"sensor-data-provided lists {', '.join(MANDATORY_SENSORS)}",
        observed=f"missing {', '.join(missing)}", topic=msg.topic, path="$.sensor-data-provided",
        time=msg.time, payload=msg.payload,
        detail="6.1 spells 'positon' once; the topic is sensor/position")]


def _window(unit: UnitState) -> float | None:
    periods = [p for p in (unit.period(SI), unit.period(TopicKind.HEARTBEAT)) if p]
    return PUBLISH_WINDOW_PERIODS * max(periods) if periods else None


@check("SI-003", finish=True)
def listed_sensors_published(ctx: CheckContext, unit: UnitState, now: float,
                             findings: Any) -> Iterator[Violation]:
    """5.2: 'The string in sensor-data-provided is the string used in sensor topic': each
    listed sensor is published within the window after sensor_info."""
    listed = unit.sensors_listed
    first = unit.first_by_kind.get(SI)
    if listed is None or first is None:
        why = ("no sensor_info seen" if listed is None
               else "only a retained sensor_info seen (its time is unknown)")
        findings.note("SI-003", why)
        return
    seen = unit.sensors_seen
    window = _window(unit)
    observed = now - first
    unpublished = [s for s in listed if s not in seen]
    if window is None or observed < window:
        need = f"{window:.1f} s" if window else "a declared rate"
        if unpublished:
            findings.note("SI-003", f"observed only {observed:.1f} s since sensor_info; "
                                    f"need {need}")
        else:
            findings.examine("SI-003")
        return
    findings.examine("SI-003")
    if unpublished:
        yield Violation.of(
            "SI-003", expected="a message on sensor/<name> for every sensor listed",
            observed=f"nothing on {', '.join(unpublished)} in {observed:.1f} s",
            topic=unit.address.topic("sensor/") + "<name>", time=now,
            detail="publish every sensor listed in sensor-data-provided, or stop listing it")


def _sensor_level_since(unit: UnitState) -> float | None:
    """When the unit was first seen to be of the sensor level, live: its first sensor_info,
    else its first sensor message or its first heartbeat if that level is claimed (6.1 makes
    the four sensors mandatory whether or not sensor_info is sent); None: it never was."""
    first = unit.first_by_kind
    if (si := first.get(SI)) is not None:
        return si  # the window SI-003 judges by too: the same unit, the same deadline
    since = [first.get(TopicKind.SENSOR)]
    if unit.claims(SENSOR_LEVEL):
        since.append(first.get(TopicKind.HEARTBEAT))
    return min((t for t in since if t is not None), default=None)


def _sensor_level(unit: UnitState) -> bool:
    """Whether 6.1's mandatory sensors apply: the unit claims the sensor level (5.1), lists
    sensors (5.2) or publishes any (6)."""
    return unit.claims(SENSOR_LEVEL) or unit.sensors_listed is not None \
        or TopicKind.SENSOR in unit.kinds_seen


@check("SI-004", finish=True)
def mandatory_sensors_published(ctx: CheckContext, unit: UnitState, now: float,
                                findings: Any) -> Iterator[Violation]:
    """6.1: 'The following sensors are mandatory: positon, heading, course, speed': a unit of
    the sensor level publishes each within the window (3 declared periods of the slower of
    heartbeat and sensor_info) from when it was first seen to be of that level, whether it
    sends sensor_info or not (whether sensor_info lists them is the 'listed' condition)."""
    if not _sensor_level(unit):
        return  # no sensor level claimed or shown: the skip says so (``skip_reason``)
    since = _sensor_level_since(unit)
    if since is None:
        findings.note("SI-004", "only retained messages seen (their time is unknown)")
        return
    # Up to the unit's latest message: a unit that died publishes nothing, and its death is
    # HB-012's finding (docs/ARCHITECTURE.md 'Whose fault it is': the root cause).
    last = unit.last_seen
    end = now if last is None else min(now, last)
    observed = end - since
    window = _window(unit)
    unpublished = [s for s in MANDATORY_SENSORS if s not in unit.sensors_seen]
    if not unpublished:
        findings.examine("SI-004")
        return
    if window is None or observed < window:
        need = f"{window:.1f} s" if window else "a declared rate"
        findings.note("SI-004", f"observed {observed:.1f} s of the sensor level; need {need} "
                                f"to judge {', '.join(unpublished)} unpublished")
        return
    findings.examine("SI-004")
    yield Violation.of(
        "SI-004", expected=f"messages on sensor/{{{','.join(MANDATORY_SENSORS)}}}",
        observed=f"nothing on {', '.join(unpublished)} in {observed:.1f} s",
        topic=unit.address.topic("sensor/") + "<name>", time=end,
        detail="6.1: position, heading, course and speed are mandatory for a unit of the "
               "sensor level, whether or not it sends sensor_info")


def _reported(unit: UnitState) -> set[str]:
    return unit.stash.setdefault(SENSORS_SEEN, SensorsSeen).unlisted_reported


def _unlisted(unit: UnitState, name: str, t: float, topic: str,
              payload: bytes | None) -> Violation:
    return Violation.of(
        "SI-005", expected=f"only sensors listed in sensor_info "
                           f"({', '.join(unit.sensors_listed or ()) or 'none'})",
        observed=f"sensor/{name} published", topic=topic, time=t, payload=payload,
        detail="add it to sensor-data-provided (5.2), or stop publishing it")


@check("SI-005", on=(TopicKind.SENSOR,), reads=(SENSORS_SEEN,))
def sensor_is_listed(ctx: CheckContext, unit: UnitState, msg: Message,
                     v: Validation) -> list[Violation] | None:
    """5.2: sensor_info lists the sensors provided: an unlisted sensor topic warns (once per
    sensor name). (Runs on every sensor message: returns a list, not a generator.)"""
    listed = unit.sensors_listed
    if listed is None:
        unit.note("SI-005", "no sensor_info seen before the sensor messages")
        return None
    examined = unit.examined
    examined["SI-005"] = examined.get("SI-005", 0) + 1
    name = v.topic.sensor
    if name in listed:
        return None
    reported = _reported(unit)
    if name in reported or len(reported) >= 256:
        return None
    reported.add(name)
    return [_unlisted(unit, name, msg.time, msg.topic, msg.payload)]


@check("SI-005", finish=True, reads=(SENSORS_SEEN,))
def sensors_seen_before_the_list_are_listed(ctx: CheckContext, unit: UnitState, now: float,
                                            findings: Any) -> Iterator[Violation]:
    listed = unit.sensors_listed
    if listed is None:
        return
    reported = _reported(unit)
    findings.examine("SI-005")
    for name in unit.sensors_seen:
        if name not in listed and name not in reported:
            yield _unlisted(unit, name, now, unit.address.topic(f"sensor/{name}"), None)


def _distance_bound(a: tuple[float, float, float | None],
                    b: tuple[float, float, float | None]) -> float:
    """An upper bound of ``distance(a, b)`` without trigonometry: a path north-south, then
    east-west along a parallel (never longer than along the equator), then up or down, is
    never shorter than the great circle."""
    dlon = abs(b[1] - a[1])
    if dlon > 180.0:
        dlon = 360.0 - dlon
    ground = EARTH_RADIUS * _RADIANS * (abs(b[0] - a[0]) + dlon)
    if a[2] is None or b[2] is None:
        return ground
    return ground + abs(b[2] - a[2])


def distance(a: tuple[float, float, float | None], b: tuple[float, float, float | None]) -> float:
    """Great-circle distance in metres between two (latitude, longitude, altitude) points,
    altitude difference included when both have one."""
    lat1, lat2 = a[0] * _RADIANS, b[0] * _RADIANS
    s_lat = math.sin((lat2 - lat1) / 2)
    s_lon = math.sin((b[1] - a[1]) * _RADIANS / 2)
    h = s_lat * s_lat + math.cos(lat1) * math.cos(lat2) * s_lon * s_lon
    ground = 2 * EARTH_RADIUS * math.asin(min(1.0, math.sqrt(h)))
    if a[2] is None or b[2] is None:
        return ground
    return math.hypot(ground, b[2] - a[2])


@check("SENS-005", on=("sensor/position",), reads=(SENSORS_SEEN,))
def position_moves_plausibly(ctx: CheckContext, unit: UnitState, msg: Message,
                             v: Validation) -> list[Violation] | None:
    """Position jumps faster than 3x the largest reported speed + 5 m/s warn (SENS-005: speed
    in km/h, or degrees and radians mixed up). (Runs on every position: a list or None.)"""
    if msg.retain:
        return None
    seen = unit.stash.setdefault(SENSORS_SEEN, SensorsSeen)
    held, seen.held = seen.held, None  # its instant has passed: judged on what came with it
    found = _step(ctx, unit, seen, msg, v)
    return [held.violation(), *(found or [])] if held is not None else found


def _step(ctx: CheckContext, unit: UnitState, seen: SensorsSeen, msg: Message,
          v: Validation) -> list[Violation] | None:
    """SENS-005 on one position: the step from the anchor, held when too fast for the speeds
    known so far (the speed of the same instant may come just after it)."""
    anchor = seen.anchor
    t = msg.time
    last, seen.last_position = seen.last_position, t
    burst = last is not None and t - last < BURST_GAP
    if anchor is not None and t - anchor[1] < MIN_JUMP_INTERVAL and not burst:
        return None  # too close to the last position compared to judge (a point is not read)
    point = geopoint(v.message)
    if point is None:
        return None
    life = unit.agent_uuid
    if burst:  # arrival times of a flushed queue are not the unit's timing: start again here
        seen.anchor = (point, t, life)
        return None
    if anchor is None:
        seen.anchor = (point, t, life)
        unit.note("SENS-005", "only one position seen")
        return None
    prev, t0, life0 = anchor
    dt = t - t0
    seen.anchor = (point, t, life)
    if life != life0 or (ctx.gaps and ctx.in_gap(t0, t)):
        # Another life of the unit: a new agent-uuid, a reboot the suite asked
        # for, or a gap of the broker between the two positions. A restarted agent may spawn
        # elsewhere; positions are compared within one life only.
        return None
    examined = unit.examined
    examined["SENS-005"] = examined.get("SENS-005", 0) + 1
    limit = 3 * unit.max_speed + 5.0
    if _distance_bound(prev, point) <= limit * dt:
        return None  # cannot be too fast: the exact distance (trigonometry) is not needed
    jump = Jump(distance(prev, point), dt, t, msg.topic, msg.payload, unit.max_speed)
    if jump.too_fast():
        seen.held = jump
    return None


@check("SENS-005", on=("sensor/speed",), reads=(SENSORS_SEEN,))
def speed_of_the_same_instant(ctx: CheckContext, unit: UnitState, msg: Message,
                              v: Validation) -> list[Violation] | None:
    """A position step held as too fast (``position_moves_plausibly``) is judged with the speed
    published at the same instant, which may come just after it: the pair together."""
    seen = unit.stash.get(SENSORS_SEEN)
    if seen is None or seen.held is None or msg.retain:
        return None
    held, seen.held = seen.held, None
    m = v.message
    if msg.time - held.time <= SAME_INSTANT and isinstance(m, (int, float)) \
            and not isinstance(m, bool) and math.isfinite(m):
        held = dataclasses.replace(held, speed=max(held.speed, abs(float(m))))
    return [held.violation()] if held.too_fast() else None


@check("SENS-005", finish=True, reads=(SENSORS_SEEN,))
def position_held_at_the_end(ctx: CheckContext, unit: UnitState, now: float,
                             findings: Any) -> Iterator[Violation]:
    """A position step still held when the observation ends (no speed came after it)."""
    seen = unit.stash.get(SENSORS_SEEN)
    if seen is not None and seen.held is not None:
        yield seen.held.violation()

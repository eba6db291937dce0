"""The simulated vehicle: position, heading, course and speed under plausible kinematics.

A point mass that accelerates, brakes before its target and climbs at a bounded vertical
speed; its heading slews towards its course (or towards what its camera should look at) at a
bounded turn rate. Distances are in metres, speeds in m/s, angles in degrees (0 = north,
clockwise), times in seconds. Geodesy is spherical: good to centimetres over the few
kilometres a simulated task covers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS = 6_371_000.0  # metres (mean radius)

LINKOPING = (58.3945, 15.5645)  # a sensible home: the WARA-PS arena's city (lat, lon degrees)


@dataclass(frozen=True)
class GeoPoint:
    """A position: latitude and longitude in degrees, altitude in metres."""

    latitude: float
    longitude: float
    altitude: float = 0.0


def distance(a: GeoPoint, b: GeoPoint) -> float:
    """Horizontal great-circle distance in metres (haversine)."""
    p1, p2 = math.radians(a.latitude), math.radians(b.latitude)
    dp, dl = p2 - p1, math.radians(b.longitude - a.longitude)
    h = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS * math.asin(min(1.0, math.sqrt(h)))


def bearing(a: GeoPoint, b: GeoPoint) -> float:
    """Initial bearing from ``a`` to ``b`` in degrees [0, 360)."""
    p1, p2 = math.radians(a.latitude), math.radians(b.latitude)
    dl = math.radians(b.longitude - a.longitude)
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return wrap360(math.degrees(math.atan2(y, x)))


def destination(a: GeoPoint, course: float, metres: float, altitude: float | None = None
                ) -> GeoPoint:
    """The point ``metres`` from ``a`` along ``course`` degrees."""
    d, th = metres / EARTH_RADIUS, math.radians(course)
    p1, l1 = math.radians(a.latitude), math.radians(a.longitude)
    p2 = math.asin(math.sin(p1) * math.cos(d) + math.cos(p1) * math.sin(d) * math.cos(th))
    l2 = l1 + math.atan2(math.sin(th) * math.sin(d) * math.cos(p1),
                         math.cos(d) - math.sin(p1) * math.sin(p2))
    lon = (math.degrees(l2) + 540.0) % 360.0 - 180.0
    return GeoPoint(math.degrees(p2), lon, a.altitude if altitude is None else altitude)


def wrap360(angle: float) -> float:
    """An angle in degrees folded into [0, 360) (never 360.0 after rounding)."""
    a = angle % 360.0
    return 0.0 if a >= 360.0 else a


def angle_diff(target: float, current: float) -> float:
    """The signed smallest turn from ``current`` to ``target``, degrees in (-180, 180]."""
    d = (target - current + 180.0) % 360.0 - 180.0
    return 180.0 if d == -180.0 else d


@dataclass(frozen=True)
class Kinematics:
    """Performance of one agent type: speeds in m/s for the qualitative speed levels of
    section 9 ('slow', 'standard', 'fast'), acceleration in m/s², turn rate in degrees/s,
    vertical speed in m/s (0: stays on the surface)."""

    slow: float
    standard: float
    fast: float
    acceleration: float
    turn_rate: float
    vertical_speed: float

    def speed_of(self, level: str | None) -> float:
        return {"slow": self.slow, "fast": self.fast}.get(level or "standard", self.standard)


KINEMATICS = {
    "air": Kinematics(3.0, 8.0, 15.0, 3.0, 90.0, 3.0),
    "surface": Kinematics(2.0, 5.0, 10.0, 1.0, 30.0, 0.0),
    "ground": Kinematics(1.0, 3.0, 6.0, 1.5, 45.0, 0.0),
    "subsurface": Kinematics(1.0, 2.0, 3.0, 0.5, 20.0, 0.5),
}

ARRIVED = 0.3  # metres: close enough to a waypoint


class Vehicle:
    """A simulated vehicle of one agent type. ``advance(dt)`` integrates ``dt`` seconds.

    ``goto(point, speed)`` sets a target; the vehicle accelerates towards it, brakes so as to
    stop there, and reports ``arrived``. ``stop()`` brakes to a halt where it is. Surface and
    ground vehicles stay at altitude 0; subsurface ones never rise above 0.
    """

    def __init__(self, agent_type: str, position: GeoPoint, heading: float = 0.0) -> None:
        self.agent_type = agent_type
        self.kin = KINEMATICS[agent_type]
        self.position = GeoPoint(position.latitude, position.longitude,
                                 self._clamp_altitude(position.altitude))
        self.heading = wrap360(heading)
        self.course = self.heading
        self.speed = 0.0
        self.vertical = 0.0
        self.target: GeoPoint | None = None
        self.cruise = 0.0
        self.climb = self.kin.vertical_speed
        self.accel = self.kin.acceleration
        self.through = False
        """Fly through the target without braking (an intermediate waypoint)."""
        self.look_at: float | None = None
        """A bearing the heading should turn to when the vehicle does not move (camera tasks)."""

    def _clamp_altitude(self, altitude: float) -> float:
        if self.agent_type in ("surface", "ground"):
            return 0.0
        if self.agent_type == "subsurface":
            return min(0.0, altitude)
        return max(0.0, altitude)

    @property
    def airborne(self) -> bool:
        return self.agent_type == "air" and self.position.altitude > 0.5

    def goto(self, point: GeoPoint, speed: float, climb: float | None = None,
             through: bool = False, ramp: float = 1.0) -> None:
        """Head for ``point`` at up to ``speed`` m/s (and ``climb`` m/s vertically); with
        ``through``, pass it without braking (a waypoint with another one after it). A
        time-compressed task reaches its speed within ``ramp`` seconds."""
        self.through = through
        self.target = GeoPoint(point.latitude, point.longitude,
                               self._clamp_altitude(point.altitude))
        self.cruise = max(0.1, speed)
        self.climb = max(self.kin.vertical_speed, climb or 0.0)
        # Time-compressed tasks go faster, and so accelerate harder; a vehicle still fast from
        # the task before brakes as hard (a slow task after a fast one held the spot for its
        # old speed / the new task's acceleration: 4.5 s, past a 5 s feedback deadline).
        self.accel = max(self.kin.acceleration, max(self.cruise, self.speed) / max(0.1, ramp))

    def stop(self) -> None:
        """Brake to a halt where the vehicle is (pause, abort, $enough)."""
        self.target = None

    @property
    def arrived(self) -> bool:
        return self.target is None or (
            distance(self.position, self.target) <= ARRIVED
            and abs(self.position.altitude - self.target.altitude) <= ARRIVED
            and (self.through or self.speed == 0.0))

    def advance(self, dt: float) -> None:
        """Integrate ``dt`` seconds of motion."""
        if dt <= 0:
            return
        pos, target = self.position, self.target
        if target is None:
            self.speed = max(0.0, self.speed - self.accel * dt)
            step = self.speed * dt
            if step > 0:
                pos = destination(pos, self.course, step)
            self.vertical = 0.0
        else:
            d = distance(pos, target)
            brake = math.inf if self.through else math.sqrt(2.0 * self.accel * d)
            wanted = min(self.cruise, brake)
            self.speed += max(-self.accel * dt, min(self.accel * dt, wanted - self.speed))
            self.speed = max(0.0, self.speed)
            if d > ARRIVED:
                self.course = bearing(pos, target)
            step = min(self.speed * dt, d)
            if d - step <= ARRIVED:
                # There: hold the spot while the last of the speed brakes away (bounded: the
                # braking curve above wants 0 at the target).
                pos = GeoPoint(target.latitude, target.longitude, pos.altitude)
            elif step > 0:
                pos = destination(pos, self.course, step)
            dz = target.altitude - pos.altitude
            climb = max(-self.climb * dt, min(self.climb * dt, dz))
            self.vertical = climb / dt
            pos = GeoPoint(pos.latitude, pos.longitude, pos.altitude + climb)
        self.position = GeoPoint(pos.latitude, pos.longitude, self._clamp_altitude(pos.altitude))
        # The heading follows the course while moving; a camera task turns a still vehicle.
        wanted_heading = self.course if self.speed > 0.2 else self.look_at
        if wanted_heading is not None:
            turn = angle_diff(wanted_heading, self.heading)
            limit = self.kin.turn_rate * dt
            self.heading = wrap360(self.heading + max(-limit, min(limit, turn)))

"""The tasks the reference unit runs: which it offers, how it checks their parameters, and how
each one moves the simulated vehicle.

Section 9 defines the tasks; the parameter rules (types, enums, which are required) follow the
task specification files in ``schemas/tasks/`` (their ``required-why`` notes say why). Time is
compressed so that a simulated task ends within about ``task_seconds`` (default 3 s): a task
that covers more ground than its qualitative speed allows in that time goes faster (and
reports that speed), and observation durations are capped. Tasks that the spec says end only
on ``$enough`` (look-at-*, image-object-detection, observe-position with a negative duration)
run until they get it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeGuard

from conformance.sim.vehicle import GeoPoint, Vehicle, bearing, destination, distance

BUILTIN_SIGNALS = ("$abort", "$continue", "$enough", "$pause")  # 12.2.2
SKIP_WAYPOINT = "skip-waypoint"
"""A task-specific signal (12.2.2: 'other names are specific for the task'): go on to the next
waypoint."""

Check = Callable[[Any], str | None]
"""A parameter check: None when the value is fine, else what is wrong with it."""


def _is_number(v: object) -> TypeGuard[float]:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _geopoint_problem(v: Any) -> str | None:
    if not isinstance(v, dict):
        return f"a GeoPoint object {{latitude, longitude, altitude}}, not {type(v).__name__}"
    for key, low, high in (("latitude", -90, 90), ("longitude", -180, 180)):
        x = v.get(key)
        if not _is_number(x):
            return f"a GeoPoint with a numeric {key} (got {x!r})"
        if not low <= x <= high:
            return f"a GeoPoint with {key} in [{low}, {high}] degrees (got {x!r})"
    if "altitude" in v and not _is_number(v["altitude"]):
        return f"a GeoPoint with a numeric altitude in metres (got {v['altitude']!r})"
    return None


def string(*enum: str) -> Check:
    def check(v: Any) -> str | None:
        if not isinstance(v, str):
            return f"a string, not {type(v).__name__}"
        if enum and v not in enum:
            return f"one of {', '.join(enum)} (got {v!r})"
        return None
    return check


def strings(*enum: str) -> Check:
    item = string(*enum)

    def check(v: Any) -> str | None:
        if not isinstance(v, list):
            return f"a list of strings, not {type(v).__name__}"
        return next((f"[{i}]: {p}" for i, x in enumerate(v) if (p := item(x))), None)
    return check


def boolean(v: Any) -> str | None:
    return None if isinstance(v, bool) else f"true or false, not {v!r}"


def number(v: Any) -> str | None:
    return None if _is_number(v) else f"a finite number, not {v!r}"


def integer(v: Any) -> str | None:
    ok = isinstance(v, int) and not isinstance(v, bool) and -2**31 <= v < 2**31
    return None if ok else f"a 32-bit integer, not {v!r}"


def numbers(v: Any) -> str | None:
    if not isinstance(v, list):
        return f"a list of numbers, not {type(v).__name__}"
    return next((f"[{i}]: a finite number >= 0, not {x!r}" for i, x in enumerate(v)
                 if not _is_number(x) or x < 0), None)


def geopoint(v: Any) -> str | None:
    return _geopoint_problem(v)


def geopoints(min_items: int = 1) -> Check:
    def check(v: Any) -> str | None:
        if not isinstance(v, list):
            return f"a list of GeoPoints, not {type(v).__name__}"
        if len(v) < min_items:
            return f"at least {min_items} GeoPoint(s), got {len(v)}"
        return next((f"[{i}]: {p}" for i, x in enumerate(v) if (p := _geopoint_problem(x))),
                    None)
    return check


def geopointarrays(v: Any) -> str | None:
    if not isinstance(v, list) or not v:
        return "a non-empty list of areas (each a list of at least 3 GeoPoints)"
    area = geopoints(3)
    return next((f"[{i}]: {p}" for i, x in enumerate(v) if (p := area(x))), None)


SPEED = string("fast", "standard", "slow")


@dataclass(frozen=True)
class TaskSpec:
    """A task of section 9 as this unit implements it."""

    name: str
    params: dict[str, Check]
    required: tuple[str, ...] = ()
    one_of: tuple[str, ...] = ()
    """At least one of these parameters must be given (look-at-position(s))."""
    agent_types: tuple[str, ...] = ("air", "ground", "surface", "subsurface")
    group: str = "motion"
    """Tasks of one group share a resource (the vehicle, the camera, the detector): a new one
    pre-empts the running one."""
    signals: tuple[str, ...] = BUILTIN_SIGNALS

    def problems(self, params: Any) -> list[str]:
        """Everything wrong with ``params``, as 'where: what was expected' texts."""
        if not isinstance(params, dict):
            return [f"params: a JSON object of parameters, not {type(params).__name__}"]
        found = [f"params.{k}: required by {self.name} (section 9)"
                 for k in self.required if k not in params]
        if self.one_of and not any(k in params for k in self.one_of):
            found.append(f"params: {self.name} needs one of {', '.join(self.one_of)}")
        for key, value in params.items():
            check = self.params.get(key)
            # Unknown parameters are ignored: the spec's own examples carry misspelled ones
            # (ERR-003), and a unit that refused them would refuse the spec.
            if check is not None and (p := check(value)):
                found.append(f"params.{key}: expected {p}")
        if (self.name == "land" and not params.get("land-at-current-position-flag")
                and "p" not in params):
            found.append("params.p: required unless land-at-current-position-flag is true")
        return found


_ALL = (
    TaskSpec("image-object-detection", {
        "image-input-url": string(), "image-input-ros-topic": string(), "score": number,
        "annotation": string("debug", "standard"), "detections-sensor-topic": string(),
        "object-types": strings(), "wanted-detection-rate": integer,
        "salient-points-topic": string(), "salient-score": number,
    }, group="detector"),
    TaskSpec("look-at-bearing", {
        "bearing": number, "use-absolute-bearing": boolean, "tilt": number,
        "tilt-body-relative": boolean,
    }, required=("bearing",), group="camera"),
    TaskSpec("look-at-position", {"geopoint": geopoint, "named-position": string()},
             one_of=("geopoint", "named-position"), group="camera"),
    TaskSpec("look-at-positions", {"geopoints": geopoints(1), "named-positions": strings()},
             one_of=("geopoints", "named-positions"), group="camera"),
    TaskSpec("move-path", {"waypoints": geopoints(1), "speed": SPEED},
             required=("waypoints",), signals=BUILTIN_SIGNALS + (SKIP_WAYPOINT,)),
    TaskSpec("move-to", {"waypoint": geopoint, "speed": SPEED}, required=("waypoint",)),
    TaskSpec("observe-position", {
        "geopoint": geopoint, "speed": SPEED, "distance": number, "height": number,
        "duration": integer,
    }, required=("geopoint",)),
    TaskSpec("search-area", {
        "area": geopoints(3), "speed": SPEED, "target-type": string(),
        "area-type": string("water", "beach", "forrest", "field"), "target-size": number,
    }, required=("area",)),
    TaskSpec("search-areas", {
        # 9.10: area-type is 'a list of tags' in one string: no single value to check
        "areas": geopointarrays, "speed": SPEED, "target-type": string(),
        "area-type": string(), "target-size": number,
    }, required=("areas",)),
    TaskSpec("search-around-position", {
        "geopoint": geopoint, "radius": number, "speed": SPEED, "target-type": string(),
        "target-size": number,
    }, required=("geopoint",)),
    # 9.12: vehicle type specific. Take-off and land only make sense in the air.
    TaskSpec("land", {
        "p": geopoint, "land-at-current-position-flag": boolean, "z": number,
        "heading": number,
    }, agent_types=("air",)),
    TaskSpec("navigate", {
        "waypoints": geopoints(1), "commanded-speed": numbers, "speed": strings(
            "fast", "standard", "slow"), "continue-flag": boolean, "loop-flag": boolean,
        "hold-flag": boolean, "straight-line-flag": boolean,
    }, required=("waypoints",), signals=BUILTIN_SIGNALS + (SKIP_WAYPOINT,)),
    TaskSpec("take-off", {"height-above-takeoff": number, "path": geopoints(0)},
             agent_types=("air",)),
)
TASKS: dict[str, TaskSpec] = {t.name: t for t in _ALL}
GO_HOME = TaskSpec("go-home", {"speed": number}, required=("speed",))
"""Variant own-task: a task of the unit's own, outside section 9 (5.3)."""


def tasks_for(agent_type: str) -> list[TaskSpec]:
    """The tasks a unit of this agent type offers (5.3 tasks-available), in name order."""
    return [t for t in _ALL if agent_type in t.agent_types]


# --- execution --------------------------------------------------------------------------------

FOREVER = math.inf
MAX_COMPRESSION = 10.0
"""Time compression goes at most this many times the 'fast' speed: a task far away takes
longer than ``task_seconds`` rather than crossing the country in three seconds."""


@dataclass
class Leg:
    """One step of a task's plan: go to ``point``, or stay ``seconds`` (FOREVER: until
    $enough)."""

    point: GeoPoint | None = None
    seconds: float = 0.0


def _point(v: dict[str, Any], altitude: float | None = None) -> GeoPoint:
    alt = v.get("altitude", 0.0) if altitude is None else altitude
    return GeoPoint(float(v["latitude"]), float(v["longitude"]), float(alt))


def circle(center: GeoPoint, radius: float, start_bearing: float = 0.0, n: int = 12
           ) -> list[GeoPoint]:
    """``n`` points on a circle of ``radius`` metres around ``center``, clockwise."""
    return [destination(center, start_bearing + 360.0 * i / n, radius, center.altitude)
            for i in range(n)]


@dataclass
class Task:
    """A task started by start-task: its identity, status and plan.

    ``status`` is one of running, paused, finished, aborted, failed (12.4).
    """

    uuid: str
    name: str
    params: dict[str, Any]
    spec: TaskSpec | None
    com_uuid: str
    status: str = "running"
    fail_reason: str = ""
    legs: list[Leg] = field(default_factory=list)
    leg: int = 0
    loop_from: int | None = None
    leg_started: float = 0.0
    paused_left: float | None = None
    cruise: float = 0.0
    climb: float = 0.0
    look_at: GeoPoint | float | None = None
    in_view_sent: bool = False
    fail_at: float | None = None
    """When a task accepted despite bad parameters fails (fault accept-invalid-params)."""
    prepared_at: float | None = None
    """Variant preparing-status: when it says 'running' after its 'preparing' (None: said,
    or another status came first)."""
    node: Callable[[str, str], None] | None = None
    """For a leaf of a TST tree (``conformance.sim.tst``): told each status change (status,
    reason) instead of sending exec/feedback."""

    @property
    def group(self) -> str:
        return self.spec.group if self.spec else "other"

    @property
    def ended(self) -> bool:
        return self.status in ("finished", "aborted", "failed")

    def resume_clock(self, now: float) -> None:
        """$continue: a timed stay resumes where it paused (``paused_left`` seconds were left)."""
        if self.paused_left is not None:
            leg = self.legs[self.leg]
            if math.isfinite(leg.seconds):
                self.leg_started = now - (leg.seconds - self.paused_left)
            self.paused_left = None


def plan(task: Task, vehicle: Vehicle, task_seconds: float) -> None:
    """Fill in the task's legs, cruise speed and camera target from its parameters."""
    legs = _route(task, vehicle.position)
    task.legs = legs if legs is not None else _station(task, vehicle, task_seconds)
    _pace(task, vehicle, task_seconds)


def _route(task: Task, here: GeoPoint) -> list[Leg] | None:
    """The legs of a task that moves along points (9.1-9.3, 9.9-9.11), None for another."""
    p, name = task.params, task.name
    legs: list[Leg] = []

    def goto(v: dict[str, Any], altitude: float | None = None) -> None:
        legs.append(Leg(_point(v, altitude)))

    if name == "move-to":
        goto(p["waypoint"])
    elif name in ("move-path", "navigate"):
        for w in p["waypoints"]:
            goto(w)
        if name == "navigate":
            if p.get("loop-flag"):
                task.loop_from = 0
            elif p.get("hold-flag"):
                last = legs[-1].point
                assert last is not None
                task.loop_from = len(legs)
                legs.extend(Leg(c) for c in circle(last, 30.0))
            elif p.get("continue-flag"):
                prev = legs[-2].point if len(legs) > 1 else here
                last = legs[-1].point
                assert prev is not None and last is not None
                legs.append(Leg(destination(last, bearing(prev, last), 1000.0, last.altitude)))
                legs.append(Leg(seconds=FOREVER))
    elif name == "search-area":
        for w in p["area"]:
            goto(w)
        goto(p["area"][0])  # 9.9: the area is closed by a segment back to the first point
    elif name == "search-areas":
        for area in p["areas"]:
            for w in area:
                goto(w)
            goto(area[0])
    elif name == "search-around-position":
        center = _point(p["geopoint"])
        radius = float(p.get("radius") or 20.0)
        ring = circle(center, radius, bearing(center, here) if distance(center, here) > 1 else 0)
        legs.extend(Leg(c) for c in ring + ring[:1])
    else:
        return None
    return legs


def _station(task: Task, vehicle: Vehicle, task_seconds: float) -> list[Leg]:
    """The legs of a task that goes to one spot or none, and what its camera looks at."""
    p, here, name = task.params, vehicle.position, task.name
    alt = here.altitude
    legs: list[Leg] = []
    if name == "observe-position":
        target = _point(p["geopoint"])
        height = float(p.get("height") or 0.0)
        dist = float(p.get("distance") or 0.0)
        if vehicle.agent_type == "air" and height > 0:
            spot = GeoPoint(target.latitude, target.longitude, target.altitude + height)
        else:
            away = bearing(target, here) if distance(target, here) > 1 else 180.0
            spot = destination(target, away, dist if dist > 0 else 10.0,
                               max(target.altitude, alt) if vehicle.agent_type == "air" else 0)
        legs.append(Leg(spot))
        duration = p.get("duration", -1)
        legs.append(Leg(seconds=FOREVER if duration < 0 else min(duration, task_seconds)))
        task.look_at = target
    elif name == "take-off":
        if not vehicle.airborne:
            height = float(p.get("height-above-takeoff") or 20.0)
            legs.append(Leg(GeoPoint(here.latitude, here.longitude, alt + height)))
    elif name == "land":
        ground = float(p.get("z") or 0.0)
        if not p.get("land-at-current-position-flag") and "p" in p:
            spot = _point(p["p"], alt)
            legs.append(Leg(spot))
            legs.append(Leg(GeoPoint(spot.latitude, spot.longitude, ground)))
        else:
            legs.append(Leg(GeoPoint(here.latitude, here.longitude, ground)))
    elif name == "look-at-bearing":
        b = float(p.get("bearing", 0.0))
        task.look_at = b if p.get("use-absolute-bearing") else (vehicle.heading + b) % 360.0
        legs.append(Leg(seconds=FOREVER))
    elif name == "look-at-position":
        if "geopoint" in p:
            task.look_at = _point(p["geopoint"])
        legs.append(Leg(seconds=FOREVER))
    elif name == "look-at-positions":
        points = [_point(g) for g in p.get("geopoints", [])]
        if points:  # 9.5: the position nearest to the vehicle
            task.look_at = min(points, key=lambda g: distance(here, g))
        legs.append(Leg(seconds=FOREVER))
    else:  # image-object-detection, or a task accepted by a fault: runs until $enough
        legs.append(Leg(seconds=FOREVER if name in TASKS else 1.0))
    return legs


def _pace(task: Task, vehicle: Vehicle, task_seconds: float) -> None:
    """The task's cruise and climb speeds."""
    p, here, kin, legs = task.params, vehicle.position, vehicle.kin, task.legs
    # Time compression: one lap of the plan takes about task_seconds (or less, at the
    # qualitative speed). The vehicle then reports the speed it really flies (SENS-005).
    length, climb, prev = 0.0, 0.0, here
    for leg in legs:
        if leg.point is not None:
            length += distance(prev, leg.point)
            climb = max(climb, abs(leg.point.altitude - prev.altitude))
            prev = leg.point
    level = p.get("speed")
    level = level[0] if isinstance(level, list) and level else level
    nominal = kin.speed_of(level if isinstance(level, str) else None)
    task.cruise = max(nominal, min(length / max(0.5, task_seconds), MAX_COMPRESSION * kin.fast))
    task.climb = min(climb / max(0.5, task_seconds), MAX_COMPRESSION * max(1.0, kin.vertical_speed))

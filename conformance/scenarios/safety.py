"""Which tasks the suite may start on the unit under test, and where (DESIGN 'Safety').

A unit whose topic says ``real`` is sent no task that moves it unless ``--allow-motion`` is
given AND the profile lists that task in ``motion_tasks``. Positions for any task are computed
near the unit's own reported position, within the profile's ``safe_radius`` (metres), never
the spec's example coordinates.

``MotionGate`` is the same decision made on the bytes about to be published (DESIGN: 'the
publish policy is the one gate'): the suite's connection asks it about every payload, so no
payload naming a motion task reaches a ``real`` unit without the flag, whatever the scenario
meant to send and however malformed the payload is.
"""

from __future__ import annotations

import math
import random
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import orjson

from conformance.profile import Profile
from conformance.topics import UnitAddress

# Section 9 tasks that move the unit although their tags do not say 'vehicle': navigate flies
# waypoints (9.14), observe-position circles or hovers at a distance (9.8).
MOVES_WITHOUT_TAG = frozenset({"navigate", "observe-position"})

EARTH_METRES_PER_DEGREE = 111_320.0


@dataclass(frozen=True)
class Position:
    """A WGS84 position: degrees, and altitude in metres."""

    latitude: float
    longitude: float
    altitude: float = 0.0

    def offset(self, north: float, east: float, up: float = 0.0) -> Position:
        """The position ``north``/``east``/``up`` metres away (flat-earth: fine within km)."""
        lat = self.latitude + north / EARTH_METRES_PER_DEGREE
        cos = max(0.01, math.cos(math.radians(self.latitude)))
        lon = self.longitude + east / (EARTH_METRES_PER_DEGREE * cos)
        return Position(lat, lon, self.altitude + up)

    def distance(self, other: Position) -> float:
        """Horizontal distance in metres (equirectangular: fine within km)."""
        cos = math.cos(math.radians((self.latitude + other.latitude) / 2))
        dn = (other.latitude - self.latitude) * EARTH_METRES_PER_DEGREE
        de = (other.longitude - self.longitude) * EARTH_METRES_PER_DEGREE * cos
        return math.hypot(dn, de)

    def geopoint(self) -> dict[str, object]:
        """As a spec GeoPoint (6.1), tagged ``rostype`` (the canonical form, ERR-010)."""
        return {"latitude": self.latitude, "longitude": self.longitude,
                "altitude": self.altitude, "rostype": "GeoPoint"}


class Safety:
    """Decides which tasks may be started, and generates positions inside the safe area.

    ``task_moves(name)`` says whether a task moves the unit (tag 'vehicle', or known to move;
    None for a task this suite does not know, which is treated as moving).
    """

    def __init__(self, unit: UnitAddress, profile: Profile, *, allow_motion: bool,
                 task_moves: Callable[[str], bool | None]) -> None:
        self.unit = unit
        self.profile = profile
        self.allow_motion = allow_motion
        self._task_moves = task_moves

    def moves(self, task: str) -> bool:
        """Whether starting ``task`` may move the unit (unknown tasks: assume it does)."""
        known = self._task_moves(task)
        return True if known is None else (known or task in MOVES_WITHOUT_TAG)

    def may_start(self, task: str) -> tuple[bool, str]:
        """(allowed, reason it is not) for starting ``task`` on this unit."""
        if self.profile.tasks and task not in self.profile.tasks:
            return False, (f"profile '{self.profile.name}' does not let the suite start "
                           f"'{task}' (its tasks: {', '.join(self.profile.tasks)})")
        if self.unit.is_real and self.moves(task):
            if not self.allow_motion:
                return False, (f"'{task}' moves the unit and {self.unit} is a real unit: pass "
                               f"--allow-motion and list it in the profile's motion-tasks")
            if task not in self.profile.motion_tasks:
                return False, (f"'{task}' moves the unit and the profile "
                               f"'{self.profile.name}' does not list it in motion-tasks")
        return True, ""

    def target_radius(self) -> float:
        """How far from the unit generated positions may be: metres, inside safe_radius."""
        return max(1.0, 0.5 * self.profile.safe_radius)

    def near(self, origin: Position, rng: random.Random, radius: float | None = None
             ) -> Position:
        """A random position within ``radius`` metres (default and at most: half the safe
        radius) of ``origin``; at the same altitude, except that with the default radius an
        air unit's targets are at least 10 m up (a generated move does not go into the
        ground)."""
        up = max(0.0, 10.0 - origin.altitude) \
            if self.unit.agent_type == "air" and radius is None else 0.0
        radius = min(radius or self.target_radius(), self.target_radius())
        distance = radius * math.sqrt(rng.random())
        bearing = rng.uniform(0, 2 * math.pi)
        return origin.offset(distance * math.cos(bearing), distance * math.sin(bearing), up)

    def within(self, origin: Position, point: Position) -> bool:
        return origin.distance(point) <= self.profile.safe_radius


def motion_tasks_of_the_spec() -> frozenset[str]:
    """The tasks of section 9 that move the unit (tag 'vehicle', or ``MOVES_WITHOUT_TAG``)."""
    from conformance import taskspec

    return frozenset(s.name for s in taskspec.task_specs()
                     if s.moves_unit or s.name in MOVES_WITHOUT_TAG) | MOVES_WITHOUT_TAG


_NAME_CHARS = "a-z0-9-"


def _strings(value: Any) -> Iterator[str]:
    """Every string of a decoded JSON value: values and keys, at any depth."""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, str):
            yield v
        elif isinstance(v, dict):
            for k, x in v.items():
                yield str(k)
                stack.append(x)
        elif isinstance(v, list):
            stack.extend(v)


def named_tasks(payload: bytes, names: Iterable[str]) -> list[str]:
    """Which of ``names`` the payload names, read leniently, as the most lenient unit might
    read it: in its raw text and in every string of it once decoded (escapes such as
    ``move\\u002dto`` resolved), case-insensitively, with ``_`` read as ``-``, wherever a
    name stands as a word of its own (``"move-to"``, ``task: MOVE_TO``; not ``island``)."""
    wanted = sorted({n.lower().replace("_", "-") for n in names if n}, key=len, reverse=True)
    if not wanted:
        return []
    pattern = re.compile(rf"(?<![{_NAME_CHARS}])(?:{'|'.join(map(re.escape, wanted))})"
                         rf"(?![{_NAME_CHARS}])")
    texts = [payload.decode("utf-8", "replace")]
    try:
        texts += list(_strings(orjson.loads(payload)))
    except (orjson.JSONDecodeError, TypeError, ValueError):
        pass  # malformed: its raw text is what a lenient parser would read
    found: set[str] = set()
    for text in texts:
        found.update(pattern.findall(text.lower().replace("_", "-")))
    return sorted(found)


class MotionGate:
    """The payload half of the suite's publish policy (DESIGN 'Safety').

    On a ``real`` unit, a payload that names a motion task is refused unless
    ``--allow-motion`` is given and the profile lists that task in ``motion_tasks``. Motion
    tasks: section 9's moving tasks, the profile's ``motion_tasks``, and the tasks the unit
    lists (``listed()``) that this suite does not know (assumed to move, as ``Safety.moves``)."""

    def __init__(self, unit: UnitAddress, profile: Profile, *, allow_motion: bool,
                 listed: Callable[[], Iterable[str]] = tuple,
                 task_moves: Callable[[str], bool | None] | None = None) -> None:
        self.unit = unit
        self.profile = profile
        self.allow_motion = allow_motion
        self._listed = listed
        self._task_moves = task_moves
        self._spec = motion_tasks_of_the_spec() | frozenset(profile.motion_tasks)

    def motion_tasks(self) -> set[str]:
        """The task names that count as motion for this unit now."""
        unknown = {t for t in self._listed()
                   if isinstance(t, str) and self._task_moves is not None
                   and self._task_moves(t) is None}
        return set(self._spec) | unknown

    def refusal(self, payload: bytes) -> str | None:
        """Why ``payload`` may not be published to the unit, or None when it may."""
        if not self.unit.is_real:
            return None
        allowed = set(self.profile.motion_tasks) if self.allow_motion else set()
        named = named_tasks(payload, self.motion_tasks() - allowed)
        if not named:
            return None
        how = ("list it in the profile's motion-tasks" if self.allow_motion else
               "pass --allow-motion and list it in the profile's motion-tasks")
        return (f"not sent: the payload names the motion task(s) {', '.join(named)} and "
                f"{self.unit} is a real unit ({how}; DESIGN 'Safety')")

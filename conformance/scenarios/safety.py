"""Which tasks the suite may start on the unit under test, what it may send, and where
(docs/ARCHITECTURE.md 'Safety').

Safety fails closed: a unit is a simulation only when its role is ``simulation`` or one of the
profile's ``simulated-roles``; every other role (real, playback, live, a misspelling, an
unknown word) is real (``SafetyDecision``). A real unit is sent no task that moves it unless
``--allow-motion`` is given AND the profile lists that task in ``motion_tasks``, and no hostile
or malformed payload (``hostility``) unless ``--allow-hostile`` is given or the profile says
``robustness: true``. Positions for any task are computed near the unit's own reported
position, within the profile's ``safe_radius`` (metres), never the spec's example coordinates.

``MotionGate`` makes the decision on the bytes about to be published (the publish policy
is the one gate, docs/ARCHITECTURE.md 'Safety'): the suite's connection asks it about every payload,
so nothing the decision forbids reaches a real unit, whatever the scenario meant to send.
"""

from __future__ import annotations

import math
import random
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import orjson

from conformance import taskspec
from conformance.profile import Profile
from conformance.topics import UnitAddress
from conformance.validator import validate

# Section 9 tasks that move the unit although their tags do not say 'vehicle': navigate flies
# waypoints (9.14), observe-position circles or hovers at a distance (9.8).
MOVES_WITHOUT_TAG = frozenset({"navigate", "observe-position"})

EARTH_METRES_PER_DEGREE = 111_320.0

HOSTILE_REFUSAL = ("not sent: hostile payloads to a real unit need --allow-hostile (or "
                   "robustness: true in the profile)")
"""Why a hostile payload is not published: the reason its rules' could-not-test gives."""
MAX_COMMAND_BYTES = 64 * 1024
"""A command larger than this is a huge payload (the suite's own are well under 4 KiB)."""
MAX_COMMAND_DEPTH = 16
"""A command nested deeper than this is a deep payload (a TST tree of the suite: under 10)."""
# Parameters left out of anything sent: they name positions elsewhere than near the unit.
DROPPED = frozenset({"named-position", "named-positions", "image-input-ros-topic",
                     "detections-sensor-topic", "salient-points-topic"})
WELL_FORMED_FINDINGS = frozenset({"TASK-002"})
"""Validator findings a well-formed command may have: a task outside section 9 (5.3 lets a
unit offer others; the refusal probes name one no unit has)."""


@dataclass(frozen=True)
class SafetyDecision:
    """What the suite may send to one unit, and why (the run header says it)."""

    role: str
    simulation: bool
    """Whether the unit is a simulation (role ``simulation`` or a profile's simulated-roles)."""
    allow_motion: bool
    motion_tasks: tuple[str, ...]
    hostile: str
    """How hostile payloads were allowed ("--allow-hostile", "robustness: true in the
    profile"), or "" when they are not."""

    @classmethod
    def of(cls, unit: UnitAddress, profile: Profile, *, allow_motion: bool,
           allow_hostile: bool) -> SafetyDecision:
        how = "--allow-hostile" if allow_hostile else (
            "robustness: true in the profile" if profile.robustness else "")
        return cls(unit.role, profile.is_simulation(unit.role), allow_motion,
                   tuple(profile.motion_tasks), how)

    @property
    def real(self) -> bool:
        return not self.simulation

    @property
    def hostile_allowed(self) -> bool:
        return self.simulation or bool(self.hostile)

    def sentence(self) -> str:
        """The decision and why, in one line (the run header's ``safety:``)."""
        if self.simulation:
            why = ("3.1's role of a simulation" if self.role == "simulation"
                   else "listed in the profile's simulated-roles")
            return f"role {self.role!r} is a simulation ({why}): motion and hostile payloads allowed"
        motion = ("motion tasks: " + (", ".join(self.motion_tasks) or "none (no motion-tasks "
                                      "in the profile)")
                  if self.allow_motion else "no motion (no --allow-motion)")
        hostile = (f"hostile payloads allowed ({self.hostile})" if self.hostile
                   else "no hostile payloads (no --allow-hostile)")
        return (f"role {self.role!r} is treated as real (only 'simulation' or a profile's "
                f"simulated-roles are simulations): {motion}, {hostile}")


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

    def may_start(self, task: str, scenario: str = "") -> tuple[bool, str]:
        """(allowed, reason it is not) for starting ``task`` on this unit in ``scenario``
        (the profile may name the scenarios a task is for): only a task whose parameters
        are known (the profile's, or a section 9 example: never invented)."""
        if self.profile.tasks and task not in self.profile.tasks:
            return False, (f"profile '{self.profile.name}' does not let the suite start "
                           f"'{task}' (its tasks: {', '.join(self.profile.tasks)})")
        only = self.profile.task_scenarios.get(task)
        if scenario and only is not None and scenario not in only:
            return False, (f"the profile lets only the scenarios {', '.join(only)} start "
                           f"'{task}'")
        if not has_params(task, self.profile.task_params):
            return False, no_params_reason(task)
        if not self.profile.is_simulation(self.unit.role) and self.moves(task):
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


class NoParams(LookupError):
    """A task the suite would have to invent parameters for (docs/ARCHITECTURE.md 'Safety'); the
    message says what to add to the profile."""


def no_params_reason(task: str) -> str:
    """Why ``task`` is not started: its parameters are not known."""
    return (f"no task to start: {task} has no parameters in the profile and is not a section "
            f"9 task; add tasks: {{{task}: {{params: ...}}}} to the profile")


def has_params(task: str, given: dict[str, Any]) -> bool:
    """Whether the suite knows parameters for ``task``: the profile's (``given``), or the
    example of a section 9 task (9: each task's specification has one)."""
    if task in given:
        return True
    try:
        return bool(taskspec.params_schema(task).get("examples"))
    except KeyError:
        return False


def motion_tasks_of_the_spec() -> frozenset[str]:
    """The tasks of section 9 that move the unit (tag 'vehicle', or ``MOVES_WITHOUT_TAG``)."""
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


def _depth_over(value: Any, limit: int) -> bool:
    """Whether a decoded JSON value nests deeper than ``limit`` (iterative: no recursion)."""
    stack = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, (dict, list)):
            if depth > limit:
                return True
            stack.extend((x, depth + 1) for x in (v.values() if isinstance(v, dict) else v))
    return False


def _shape(value: Any) -> Any:
    """What making parameters safe leaves of them (``params.make_safe``: positions moved,
    numbers bounded, flags forced, some keys dropped): keys, strings and the type of every
    other leaf. Iterative; the depth was bounded before."""
    def leaf(v: Any) -> Any:
        if isinstance(v, dict) and "latitude" in v and "longitude" in v:
            return "<GeoPoint>"
        if isinstance(v, bool):
            return "<bool>"
        if isinstance(v, (int, float)):
            return "<number>"
        return v if not isinstance(v, (dict, list)) else None

    root: list[Any] = [None]
    stack: list[tuple[Any, list[Any] | dict[str, Any], Any]] = [(value, root, 0)]
    while stack:
        v, into, key = stack.pop()
        out = leaf(v)
        if out is None and isinstance(v, dict):
            out = {}
            stack.extend((x, out, k) for k, x in v.items() if k not in DROPPED)
        elif out is None and isinstance(v, list):
            out = [None] * len(v)
            stack.extend((x, out, i) for i, x in enumerate(v))
        into[key] = out
    return root[0]


def hostility(topic: str, payload: bytes, *, given: dict[str, Any] | None = None
              ) -> str | None:
    """What makes ``payload`` hostile or malformed as a command on ``topic`` (12, 14), or
    None for a well-formed one: huge, not UTF-8, not JSON, not an object, deep, or a command
    the suite's own validator finds fault with (unknown command, missing or mistyped fields,
    parameters invalid under the task's section 9 schema). ``given``: task name -> the
    parameters the profile gives it; a start-task with exactly those is the user's choice."""
    if len(payload) > MAX_COMMAND_BYTES:
        return f"{len(payload)} bytes (over {MAX_COMMAND_BYTES})"
    try:
        payload.decode("utf-8")
        body = orjson.loads(payload)
    except UnicodeDecodeError:
        return "not UTF-8"
    except orjson.JSONDecodeError:
        return "not JSON"
    if not isinstance(body, dict):
        return f"a JSON {type(body).__name__}, not an object"
    if _depth_over(body, MAX_COMMAND_DEPTH):
        return f"nested deeper than {MAX_COMMAND_DEPTH}"

    found = sorted({v.rule for v in validate(topic, payload).violations
                    if v.rule not in WELL_FORMED_FINDINGS
                    and not v.rule.startswith(("ERR-", "TOPIC-"))})
    task = body.get("task")
    if found == ["TASK-001"] and given and isinstance(task, dict) \
            and str(task.get("name")) in given \
            and _shape(given[str(task.get("name"))]) == _shape(task.get("params")):
        return None  # the profile's own parameters for this task (the user's word)
    return f"malformed ({', '.join(found)})" if found else None


class MotionGate:
    """The payload half of the suite's publish policy (docs/ARCHITECTURE.md 'Safety').

    On a real unit (``SafetyDecision``), a payload that names a motion task is refused unless
    ``--allow-motion`` is given and the profile lists that task in ``motion_tasks``; a hostile
    or malformed one (``hostility``) unless hostile payloads are allowed. Motion tasks:
    section 9's moving tasks, the profile's ``motion_tasks``, and the tasks the unit lists
    (``listed()``) that this suite does not know (assumed to move, as ``Safety.moves``)."""

    def __init__(self, unit: UnitAddress, profile: Profile, *, allow_motion: bool,
                 allow_hostile: bool = False,
                 listed: Callable[[], Iterable[str]] = tuple,
                 task_moves: Callable[[str], bool | None] | None = None) -> None:
        self.unit = unit
        self.profile = profile
        self.allow_motion = allow_motion
        self.decision = SafetyDecision.of(unit, profile, allow_motion=allow_motion,
                                          allow_hostile=allow_hostile)
        self._listed = listed
        self._task_moves = task_moves
        self._spec = motion_tasks_of_the_spec() | frozenset(profile.motion_tasks)

    def motion_tasks(self) -> set[str]:
        """The task names that count as motion for this unit now."""
        unknown = {t for t in self._listed()
                   if isinstance(t, str) and self._task_moves is not None
                   and self._task_moves(t) is None}
        return set(self._spec) | unknown

    def refusal(self, payload: bytes, topic: str | None = None) -> str | None:
        """Why ``payload`` may not be published to the unit on ``topic`` (default: its
        exec/command), or None when it may."""
        if self.decision.simulation:
            return None
        allowed = set(self.profile.motion_tasks) if self.allow_motion else set()
        named = named_tasks(payload, self.motion_tasks() - allowed)
        if not named:
            return self._hostile(payload, topic)
        how = ("list it in the profile's motion-tasks" if self.allow_motion else
               "pass --allow-motion and list it in the profile's motion-tasks")
        return (f"not sent: the payload names the motion task(s) {', '.join(named)} and "
                f"{self.unit} is a real unit ({how}; docs/ARCHITECTURE.md 'Safety')")

    def _hostile(self, payload: bytes, topic: str | None) -> str | None:
        if self.decision.hostile_allowed:
            return None
        what = hostility(topic or self.unit.topic("exec/command"), payload,
                         given=self.profile.task_params)
        return f"{HOSTILE_REFUSAL}; this payload is {what}" if what is not None else None

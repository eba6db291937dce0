"""What a report says for people: the run's metadata (``RunMeta``, the JSON report's ``meta``)
and a unit's facts (``UnitFacts``), typed both ways and read back from JSON with a precise
error. No verdict reads them (the judge reads ``RunFacts``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar


class MalformedReport(ValueError):
    """A JSON report's ``meta`` or a unit's ``facts`` is not what a writer writes."""


RERUN_OF = "rerun "
"""How a JSON report's ``meta`` key of ``RunMeta.rerun_of`` begins: ``rerun HB-003``."""


@dataclass(frozen=True)
class RunMeta:
    """What a run was, for people (source, seed, options): no verdict reads it (the judge
    reads ``RunFacts``). Each field is the key of the JSON report's ``meta`` object and its text
    as every report shows it; None: not said (no key). A certification writes the suite's
    fields (``suite/session.py``), lint the lint's (``lint/runner.py``)."""

    # -- a certification's (every one written, '' when there is nothing to say)
    unit: str | None = None
    """The unit under test (its address)."""
    seed: str | None = None
    timing_scale: str | None = None
    profile_source: str | None = None
    """The profile's file (or the bundled profile's name)."""
    dry_run: str | None = None
    """``true`` or ``false``, as the options."""
    allow_motion: str | None = None
    allow_hostile: str | None = None
    safety: str | None = None
    """The safety decision in words (motion, hostile payloads)."""
    reboot: str | None = None
    agent_uuid: str | None = None
    """Of the unit's latest heartbeat."""
    commands_sent: str | None = None
    tst_command_topic: str | None = None
    explore: str | None = None
    """What the exploration did (``off``, ``not run``, its summary)."""
    explore_story: str | None = None
    """The story exploration found, one step a line (the HTML report shows it)."""
    rerun: str | None = None
    """The command that repeats the whole run."""
    rerun_of: Mapping[str, str] = field(default_factory=dict)
    """Rule -> the command that reruns a failed or warned rule alone, as the terminal printed
    it (its scenarios, ``--observe``, a stored exploration story); keys ``rerun <RULE>``."""
    exit_status: str | None = None
    """The exit status of a finished certification."""
    # -- a lint's
    source: str | None = None
    """The recording's name, or ``live <topic filters>``."""
    recording_lines: str | None = None
    """Lines of a recording read (present only for a recording: the rerun line reads it)."""
    recording_formats: str | None = None
    recording_problems: str | None = None
    """How many lines of the recording could not be read, and the first of them."""
    recording_problem_lines: str | None = None
    bag_messages_read: str | None = None
    tls_options: str | None = None
    """Live: the TLS options the rerun line repeats, already shell-quoted."""
    unexamined_reason: str | None = None
    duration_s: str | None = None
    """Seconds of traffic read."""
    units: str | None = None
    """The --unit addresses lint was restricted to."""
    not_judged: str | None = None
    """Traffic of units past the bound on units was not judged (why, in words)."""
    provisional: str | None = None
    """A report served while lint runs (``lint --serve``): not the run's last word."""
    # -- any run's
    report_truncated: str | None = None
    """What a report bounded in size left out (``reporting/bounds.py``)."""

    def to_dict(self) -> dict[str, str]:
        """The JSON report's ``meta`` object: every field said, and a ``rerun <RULE>`` each."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "rerun_of"}
        said: dict[str, str] = {k: v for k, v in out.items() if v is not None}
        said.update((RERUN_OF + rule, line) for rule, line in self.rerun_of.items())
        return said

    @classmethod
    def from_dict(cls, d: object) -> RunMeta:
        """The ``meta`` of a JSON report; a key no field has is a newer writer's, ignored (as
        ``RunFacts.from_dict`` does)."""
        if not isinstance(d, dict):
            raise MalformedReport(f"the report's meta is {_json_type(d)}, not an object")
        known = {f.name for f in fields(cls)} - {"rerun_of"}
        said: dict[str, Any] = {}
        rerun_of: dict[str, str] = {}
        for key, value in d.items():
            if not isinstance(value, str):
                raise MalformedReport(f"the report's meta {key!r} is {_json_type(value)}, "
                                      f"not text")
            if key.startswith(RERUN_OF):
                rerun_of[key.removeprefix(RERUN_OF)] = value
            elif key in known:
                said[key] = value
        return cls(**said, rerun_of=rerun_of)


T = TypeVar("T")


@dataclass(frozen=True)
class UnitFacts:
    """What a unit declared and did, for people (the HTML report's unit heading, the count of
    commands a lint row saw): no verdict reads it. Each field is a key of the JSON report's
    unit ``facts``; made by ``checks/rows.py`` from the unit's state."""

    declared_rates: Mapping[str, float] = field(default_factory=dict)
    """Topic kind (heartbeat, sensor_info, ...) -> the rate it declares, Hz."""
    sensors_listed: tuple[str, ...] = ()
    """What its latest sensor_info lists (sensor-data-provided)."""
    sensors_seen: Mapping[str, int] = field(default_factory=dict)
    """Sensor -> messages of it seen."""
    tasks_available: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    """Task name -> the signals it understands (5.3)."""
    tasks_executing: Mapping[str, str] = field(default_factory=dict)
    """task-uuid -> task-name (5.3)."""
    position: tuple[float, float, float | None] | None = None
    """Latest (latitude, longitude, altitude) from sensor/position."""
    message_counts: Mapping[str, int] = field(default_factory=dict)
    """Topic kind -> messages of it seen (``exec/command``...)."""
    conversations_dropped: int = 0
    """Open expectations dropped for bounded memory."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "declared_rates": dict(self.declared_rates),
            "sensors_listed": list(self.sensors_listed),
            "sensors_seen": dict(self.sensors_seen),
            "tasks_available": {k: list(v) for k, v in self.tasks_available.items()},
            "tasks_executing": dict(self.tasks_executing),
            "position": list(self.position) if self.position is not None else None,
            "message_counts": dict(self.message_counts),
            "conversations_dropped": self.conversations_dropped,
        }

    @classmethod
    def from_dict(cls, d: object) -> UnitFacts:
        """A unit's ``facts`` of a JSON report; a missing key is not said (a report of an
        older writer), a key no field has a newer writer's, ignored."""
        if not isinstance(d, dict):
            raise MalformedReport(f"a unit's facts are {_json_type(d)}, not an object")

        def read(key: str, parse: Callable[[Any], T], default: Any) -> T:
            value = d.get(key, default)
            try:
                return parse(value)
            except (TypeError, ValueError) as e:
                raise MalformedReport(f"a unit's facts {key!r}: {e}") from None

        return cls(
            declared_rates=read("declared_rates", lambda v: _mapping(v, _number), {}),
            sensors_listed=read("sensors_listed", lambda v: _items(v, _text), []),
            sensors_seen=read("sensors_seen", lambda v: _mapping(v, _count), {}),
            tasks_available=read("tasks_available",
                                 lambda v: _mapping(v, lambda s: _items(s, _text)), {}),
            tasks_executing=read("tasks_executing", lambda v: _mapping(v, _text), {}),
            position=read("position", _position, None),
            message_counts=read("message_counts", lambda v: _mapping(v, _count), {}),
            conversations_dropped=read("conversations_dropped", _count, 0))


def _json_type(value: object) -> str:
    """What a JSON value is, in words (for a malformed report's error)."""
    names = {dict: "an object", list: "a list", str: "text", bool: "a boolean", int: "a number",
             float: "a number", type(None): "null"}
    return names.get(type(value), type(value).__name__)


def _mapping(value: object, item: Callable[[Any], T]) -> dict[str, T]:
    if not isinstance(value, dict):
        raise TypeError(f"{_json_type(value)}, not an object")
    return {str(k): item(v) for k, v in value.items()}


def _items(value: object, item: Callable[[Any], T]) -> tuple[T, ...]:
    if not isinstance(value, list):
        raise TypeError(f"{_json_type(value)}, not a list")
    return tuple(item(v) for v in value)


def _text(value: object) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{_json_type(value)}, not text")
    return value


def _number(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{_json_type(value)}, not a number")
    return float(value)


def _count(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{_json_type(value)}, not a whole number")
    return value


def _position(value: object) -> tuple[float, float, float | None] | None:
    if value is None:
        return None
    lat, lon, alt = _items(value, lambda v: None if v is None else _number(v))
    if lat is None or lon is None:
        raise TypeError("a position without latitude or longitude")
    return (lat, lon, alt)

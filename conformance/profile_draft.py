"""A starting profile from what a unit declares and publishes (``waraps-conformance profile``).

The unit is observed read-only for a while; its heartbeat (5.1: levels, rate), its
``sensor_info`` (5.2: the sensors it provides), its ``direct_execution_info`` (5.3: the tasks
it offers) and the rates it actually publishes at become a commented YAML profile for the user
to edit (the format: ``schemas/generated/PROFILE.md``). What was measured against what the
unit declares (a rate, a level without its info message) is written as a PROBLEM; each task is
written with the parameters the suite would start it with (section 9's example) or a
placeholder to fill in. Every byte from the wire is quoted or escaped: nothing a unit
publishes can become a key of the profile.
"""

from __future__ import annotations

import json
import math
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from conformance.display import shorten
from conformance.message import Message
from conformance.scenarios.params import task_schema
from conformance.scenarios.safety import MOVES_WITHOUT_TAG
from conformance.taskspec import task_spec
from conformance.topics import LEVELS, MANDATORY_SENSORS, ROLES, TopicKind, UnitAddress, parse_topic
from conformance.validator import Unreadable, decode

MAX_OBSERVED = 100_000
"""Messages kept while observing (a unit at 100 Hz for 15 minutes); past it, the rest are
counted for rates but not read."""
MAX_PAYLOAD = 1 << 20
"""Payloads over 1 MiB are not parsed (no info message is that large)."""


@dataclass
class Observed:
    """What a unit showed while observed: its latest declarations and per-topic arrivals."""

    unit: UnitAddress
    seconds: float
    heartbeat: dict[str, Any] | None = None
    sensor_info: dict[str, Any] | None = None
    dei: dict[str, Any] | None = None
    arrivals: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))

    def feed(self, msg: Message) -> None:
        parsed = parse_topic(msg.topic)
        if parsed.unit is None or parsed.unit.base != self.unit.base:
            return
        label = f"sensor/{parsed.sensor}" if parsed.kind is TopicKind.SENSOR else parsed.kind.value
        times = self.arrivals[label]
        if len(times) < MAX_OBSERVED:
            times.append(msg.time)
        slot = {TopicKind.HEARTBEAT: "heartbeat", TopicKind.SENSOR_INFO: "sensor_info",
                TopicKind.DIRECT_EXECUTION_INFO: "dei"}.get(parsed.kind)
        if slot and len(msg.payload) <= MAX_PAYLOAD:
            try:  # bounded (size, nesting, finite numbers): what the validator reads
                body = decode(msg.payload)
            except Unreadable:
                return
            if isinstance(body, dict):
                setattr(self, slot, body)


def _rate(times: list[float]) -> float | None:
    """Mean rate in Hz over the observed intervals (None with fewer than two arrivals)."""
    if len(times) < 2 or times[-1] <= times[0]:
        return None
    return (len(times) - 1) / (times[-1] - times[0])


def _canonical_level(text: Any) -> str | None:
    """A declared level in 5.1's spelling (ERR-008: 'direct_execution' means the same)."""
    if not isinstance(text, str):
        return None
    word = text.strip().lower().replace("_", " ")
    return word if word in LEVELS else None


def _names(items: Any, key: str | None = None) -> list[str]:
    out = []
    for item in items if isinstance(items, list) else []:
        name = item.get(key) if key and isinstance(item, dict) else item
        if isinstance(name, str) and name and name not in out:
            out.append(name)
    return out


def _moves(task: str) -> bool:
    try:
        return task_spec(task).moves_unit or task in MOVES_WITHOUT_TAG
    except KeyError:
        # A task this suite does not know is treated as moving (docs/ARCHITECTURE.md 'Safety').
        return True


def _q(value: Any) -> str:
    """Wire text as a YAML scalar that is only ever that value: a JSON string with every
    non-ASCII code point escaped (``\\u2028``, ``\\u0085``, bidi and control characters
    included), which YAML reads as a double-quoted scalar (nothing a unit
    publishes becomes a key or a line of the profile)."""
    return json.dumps(str(value), ensure_ascii=True)


def _c(value: Any) -> str:
    """Wire data for a comment: JSON, ASCII only (no code point YAML takes for a line
    break), at most 200 characters."""
    return shorten(json.dumps(value, ensure_ascii=True, default=str), 200)


def _yaml_list(items: list[str]) -> str:
    return "[" + ", ".join(_q(i) for i in items) + "]"


def _example(task: str) -> dict[str, Any] | None:
    """The parameters of section 9's own example for ``task``, or None (not a section 9
    task)."""
    examples = (task_schema(task) or {}).get("examples") or []
    return next((e for e in examples if isinstance(e, dict)), None)


def problems(seen: Observed, tolerance: float = 0.2) -> list[str]:
    """What the unit was measured doing that contradicts what it declares: each a problem
    certification will fail it on, not a neutral note."""
    out = []
    hb = seen.heartbeat or {}
    declared = hb.get("rate")
    measured = _rate(seen.arrivals.get("heartbeat", []))
    if isinstance(declared, (int, float)) and not isinstance(declared, bool) and declared > 0 \
            and measured is not None and abs(measured - declared) > tolerance * declared:
        out.append(f"declares heartbeat rate {float(declared):.1f} Hz, measured "
                   f"{measured:.2f} Hz (HB-003)")
    levels = [lv for lv in (_canonical_level(x) for x in hb.get("levels") or []) if lv] \
        if isinstance(hb.get("levels"), list) else []
    odd = [x for x in hb.get("levels") or [] if _canonical_level(x) is None] \
        if isinstance(hb.get("levels"), list) else []
    if odd:
        out.append(f"declares levels that are not 5.1's: {_c(odd)}")
    if "sensor" in levels and seen.sensor_info is None:
        out.append("declares level sensor, but no sensor_info came (5.2, HB-008)")
    if "direct execution" in levels and seen.dei is None:
        out.append("declares level direct execution, but no direct_execution_info came "
                   "(5.3, HB-008)")
    if hb and "direct execution" not in levels and seen.dei is not None:
        out.append("publishes direct_execution_info but its heartbeat does not declare the "
                   "direct execution level (5.1, HB-013)")
    if seen.sensor_info is not None:
        listed = _names(seen.sensor_info.get("sensor-data-provided"))
        published = {k[len("sensor/"):] for k in seen.arrivals if k.startswith("sensor/")}
        missing = [x for x in listed if x not in published]
        if missing:
            out.append(f"sensor_info lists {_c(missing)}, never published while observed")
        unlisted = sorted(published - set(listed))
        if unlisted:
            out.append(f"publishes sensors {_c(unlisted)} that sensor_info does not list")
    return out


def draft(seen: Observed) -> str:
    """The profile text: every value from what the unit showed, each with a comment saying
    where it came from, the lines a person must decide on left as comments, and what was
    measured against what the unit declares. Wire text is always quoted (``_q``, ``_c``)."""
    u = seen.unit
    lines = [f"# A starting profile for {_c(str(u))}, written by 'waraps-conformance "
             f"profile' from {seen.seconds:.0f} s of its traffic.",
             "# Edit it, then: pytest --unit " + _c(str(u)) + " --profile THIS-FILE "
             "--reboot-cmd 'COMMAND THAT RESTARTS THE UNIT'",
             "# Every key: schemas/generated/PROFILE.md. Keys left out come from 'extends'.",
             "extends: default", f"name: {_q(u.name)}", ""]
    found = problems(seen)
    if found:
        lines += ["# PROBLEMS measured against what the unit declares (certification will "
                  "fail on these):"] + [f"#   PROBLEM: {p}" for p in found] + [""]
    if u.role not in ROLES:
        lines += [f"# Its role {_c(u.role)} is not one of 3.1's ({', '.join(ROLES)}; TOPIC-006 "
                  "warns): the suite treats it as real (no motion, no hostile payloads",
                  "# without opt-in). If it is a simulation, say so:",
                  f"# simulated-roles: [{_q(u.role)}]", ""]
    hb = seen.heartbeat
    if hb is None:
        lines += ["# No heartbeat was seen: is the unit running and the address right?",
                  "# levels: [sensor]"]
    else:
        declared = hb.get("levels")
        levels = [lv for lv in (_canonical_level(x) for x in declared or []) if lv] \
            if isinstance(declared, list) else []
        lines.append(f"# Its heartbeat declares levels {_c(declared)} (5.1).")
        lines.append(f"levels: {_yaml_list(levels)}")
        lines += _rate_comment("heartbeat", hb.get("rate"), seen.arrivals.get("heartbeat", []))
    lines.append("")
    lines += _sensor_lines(seen)
    lines.append("")
    lines += _task_lines(seen)
    lines += ["", "# Timing (seconds); a slow link is better served by --timing-scale.",
              "response-timeout: 5", "feedback-timeout: 30", "reboot-timeout: 30",
              "rate-tolerance: 0.2", *_alive_lines(seen)]
    return "\n".join(lines) + "\n"


ALIVE_PERIODS = 3
"""The first heartbeat is awaited this many of its measured periods where they pass the
suite's default 5 s (a slow heartbeat: a public operator's is 0.2 Hz)."""


def _alive_lines(seen: Observed) -> list[str]:
    rate = _rate(seen.arrivals.get("heartbeat", []))
    if not rate or ALIVE_PERIODS / rate <= 5.0:
        return []
    wait = math.ceil(ALIVE_PERIODS / rate)
    return [f"alive-timeout: {wait}   # the first heartbeat, awaited {ALIVE_PERIODS} of its "
            f"measured periods ({1 / rate:.1f} s)"]


def _sensor_lines(seen: Observed) -> list[str]:
    provided = _names((seen.sensor_info or {}).get("sensor-data-provided"))
    extra = [s for s in provided if s not in MANDATORY_SENSORS]
    lines = []
    if seen.sensor_info is None:
        lines.append("# No sensor_info was seen (5.2): the sensors below are those it published.")
        extra = sorted(k[len("sensor/"):] for k in seen.arrivals if k.startswith("sensor/")
                       and k[len("sensor/"):] not in MANDATORY_SENSORS)
    else:
        lines.append(f"# sensor_info lists {_c(provided)} (5.2); beyond the mandatory "
                     f"four the unit must publish:")
    lines.append(f"sensors: {_yaml_list(extra)}")
    for name in sorted(k for k in seen.arrivals if k.startswith("sensor/")):
        rate = _rate(seen.arrivals[name])
        shown = f"{rate:.2f} Hz" if rate else "once"
        lines.append(f"#   {_c(name)}: published at {shown} while observed")
    return lines


def _task_lines(seen: Observed) -> list[str]:
    """``tasks`` as a mapping: each section 9 task with its example's parameters, every
    other task a commented placeholder saying what to fill in (never invented)."""
    tasks = _names((seen.dei or {}).get("tasks-available"), "name")
    if seen.dei is None:
        return ["# No direct_execution_info was seen (5.3): no tasks to list.", "tasks: []",
                "motion-tasks: []"]
    if not tasks:
        return ["# direct_execution_info offers no task (5.3): none to start.", "tasks: []",
                "motion-tasks: []"]
    moving = [t for t in tasks if _moves(t)]
    known = [(t, _example(t)) for t in tasks]
    lines = [f"# direct_execution_info offers {_c(tasks)} (5.3).",
             "# Tasks the suite may start, with the parameters it starts them with (never",
             "# invented): section 9 tasks have the spec example's (positions are moved near",
             "# the unit when sent); fill in the others. Tasks that move the unit are started",
             "# only on a simulation, or with --allow-motion and listed in motion-tasks.",
             "tasks:"]  # with every entry commented out it reads as none (profile.load)
    for task, example in known:
        if example is not None:
            lines.append(f"  {_q(task)}: {{params: "
                         f"{json.dumps(example, ensure_ascii=True, sort_keys=True)}}}")
        else:
            lines += [f"  # {_c(task)} is not a section 9 task: fill in the parameters the "
                      f"unit needs to start it, then uncomment:",
                      f"  # {_q(task)}: {{params: {{}}}}"]
    if moving:
        lines += ["# These move the unit. Uncomment to let the suite start them on a real "
                  "unit (with --allow-motion):",
                  f"# motion-tasks: {_yaml_list(moving)}", "motion-tasks: []",
                  "safe-radius: 50        # metres from the unit's own position"]
    else:
        lines.append("motion-tasks: []")
    return lines


def _rate_comment(what: str, declared: Any, times: list[float]) -> list[str]:
    rate = _rate(times)
    measured = f"{rate:.2f} Hz over {len(times) - 1} intervals" if rate else "too few arrivals"
    if rate and len(times) - 1 < 10:  # the --observe help's aim
        measured += " (fewer than ten: observe longer for a steadier figure)"
    return [f"# {what}: declares rate {_c(declared)} Hz, measured {measured}."]


def observe(client_factory: Any, unit: UnitAddress, seconds: float,
            say: Any = None) -> Observed:
    """Observe ``unit`` read-only for ``seconds`` through a connected client (its
    ``subscribe``/``get``); ``say`` is told what is awaited, every few seconds."""
    seen = Observed(unit, seconds)
    client = client_factory()
    client.subscribe(f"{unit.base}/#")
    end = time.monotonic() + seconds
    next_say = 0.0
    while (left := end - time.monotonic()) > 0:
        if say and time.monotonic() >= next_say:
            say(f"observing {unit}: {left:.0f} s left, {sum(map(len, seen.arrivals.values()))} "
                f"messages so far")
            next_say = time.monotonic() + 5
        msg = client.get(timeout=min(left, 0.5))
        if msg is not None:
            seen.feed(msg)
    return seen

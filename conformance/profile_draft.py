"""A starting profile from what a unit declares and publishes (``waraps-conformance profile``).

The unit is observed read-only for a while; its heartbeat (5.1: levels, rate), its
``sensor_info`` (5.2: the sensors it provides), its ``direct_execution_info`` (5.3: the tasks
it offers) and the rates it actually publishes at become a commented YAML profile for the user
to edit (the format: ``schemas/generated/PROFILE.md``). Nothing is judged here: a unit that
declares something odd gets it written down with a comment, and certification judges it.
"""

from __future__ import annotations

import json
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from conformance.message import Message
from conformance.taskspec import task_spec
from conformance.topics import LEVELS, MANDATORY_SENSORS, TopicKind, UnitAddress, parse_topic

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
            try:
                body = json.loads(msg.payload)
            except (ValueError, UnicodeDecodeError):
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
    from conformance.scenarios.safety import MOVES_WITHOUT_TAG

    try:
        return task_spec(task).moves_unit or task in MOVES_WITHOUT_TAG
    except KeyError:
        return True  # a task this suite does not know: treated as moving (DESIGN: safety)


def _yaml_list(items: list[str]) -> str:
    return "[" + ", ".join(json.dumps(i) if not i.replace("-", "").replace("_", "").isalnum()
                           else i for i in items) + "]"


def draft(seen: Observed) -> str:
    """The profile text: every value from what the unit showed, each with a comment saying
    where it came from, and the lines a person must decide on left as comments."""
    u = seen.unit
    lines = [f"# A starting profile for {u}, written by 'waraps-conformance profile' from "
             f"{seen.seconds:.0f} s of its traffic.",
             "# Edit it, then: pytest --unit " + str(u) + " --profile THIS-FILE "
             "--reboot-cmd 'COMMAND THAT RESTARTS THE UNIT'",
             "# Every key: schemas/generated/PROFILE.md. Keys left out come from 'extends'.",
             "extends: default", f"name: {u.name}", ""]
    hb = seen.heartbeat
    if hb is None:
        lines += ["# No heartbeat was seen: is the unit running and the address right?",
                  "# levels: [sensor]"]
    else:
        declared = hb.get("levels")
        levels = [lv for lv in (_canonical_level(x) for x in declared or []) if lv]
        odd = [x for x in declared or [] if _canonical_level(x) is None]
        lines.append(f"# Its heartbeat declares levels {json.dumps(declared)} (5.1).")
        if odd:
            lines.append(f"# Not a level of 5.1, left out: {json.dumps(odd)}.")
        lines.append(f"levels: {_yaml_list(levels)}")
        lines += _rate_comment("heartbeat", hb.get("rate"), seen.arrivals.get("heartbeat", []))
    lines.append("")
    provided = _names((seen.sensor_info or {}).get("sensor-data-provided"))
    extra = [s for s in provided if s not in MANDATORY_SENSORS]
    if seen.sensor_info is None:
        lines.append("# No sensor_info was seen (5.2): the sensors below are those it published.")
        extra = sorted(k[len("sensor/"):] for k in seen.arrivals if k.startswith("sensor/")
                       and k[len("sensor/"):] not in MANDATORY_SENSORS)
    else:
        lines.append(f"# sensor_info lists {json.dumps(provided)} (5.2); beyond the mandatory "
                     f"four the unit must publish:")
    lines.append(f"sensors: {_yaml_list(extra)}")
    for name in sorted(k for k in seen.arrivals if k.startswith("sensor/")):
        rate = _rate(seen.arrivals[name])
        shown = f"{rate:.2f} Hz" if rate else "once"
        lines.append(f"#   {name}: published at {shown} while observed")
    lines.append("")
    tasks = _names((seen.dei or {}).get("tasks-available"), "name")
    if seen.dei is None:
        lines += ["# No direct_execution_info was seen (5.3): no tasks to list.", "tasks: []",
                  "motion-tasks: []"]
    else:
        still = [t for t in tasks if not _moves(t)]
        moving = [t for t in tasks if _moves(t)]
        lines += [f"# direct_execution_info offers {json.dumps(tasks)} (5.3).",
                  "# Tasks the suite may start; those that move the unit only where it is not",
                  "# 'real', or with --allow-motion and listed in motion-tasks below.",
                  f"tasks: {_yaml_list(tasks)}"]
        if moving:
            lines += ["# These move the unit. Uncomment to let the suite start them on a real "
                      "unit (with --allow-motion):",
                      f"# motion-tasks: {_yaml_list(moving)}", "motion-tasks: []",
                      "safe-radius: 50        # metres from the unit's own position"]
        elif still:
            lines.append("motion-tasks: []")
    lines += ["", "# Timing (seconds); a slow link is better served by --timing-scale.",
              "response-timeout: 5", "feedback-timeout: 30", "reboot-timeout: 30",
              "rate-tolerance: 0.2"]
    return "\n".join(lines) + "\n"


def _rate_comment(what: str, declared: Any, times: list[float]) -> list[str]:
    rate = _rate(times)
    measured = f"{rate:.2f} Hz over {len(times) - 1} intervals" if rate else "too few arrivals"
    return [f"# {what}: declares rate {json.dumps(declared)} Hz, measured {measured}."]


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

"""One simulated WARA-PS unit: who it is in this life, when it publishes, how it reboots.

``UnitCore`` is the protocol logic of one unit, free of threads and sockets: the runtime
(``conformance.sim.runtime``) calls ``run(now)`` when it is due and ``command(payload, now)``
for each message on its ``exec/command`` topic, and the unit hands what it publishes to
``emit(topic, payload, retain)``. ``SimUnit`` (``conformance.sim.fleet``) is the public face:
one unit on one MQTT connection in a background thread.

Its parts, one module each: ``publisher`` (heartbeat, info messages, sensors: 5, 6),
``executor`` (exec/command: 12), ``runner`` (tasks and their feedback: 9, 12.4), ``tst`` and
``tst_tree`` (the TST level, with ``tst_execution``: 14), ``memory`` (what one life remembers).
Conformant by default on the levels ``sensor`` and ``direct execution``; each fault switch
(``conformance.sim.faults``) bends one behaviour the way a real unit would.
Times: ``now`` is ``time.monotonic()`` seconds; stamps are Unix seconds (5.1).
"""

from __future__ import annotations

import dataclasses
import math
import random
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterable
from typing import Any

import orjson

from conformance.sim.executor import CommandExecutor
from conformance.sim.faults import TST_FAULTS, TST_LEVEL_FAULTS, check_names
from conformance.sim.memory import Resends
from conformance.sim.publisher import CAMERA_URL_EVERY, Publisher, topic_base
from conformance.sim.runner import STEP, TaskRunner
from conformance.sim.tasks import GO_HOME, Task, TaskSpec, tasks_for
from conformance.sim.tst import TstEngine
from conformance.sim.variants import (
    REAL_SPEED_SECONDS,
    REBOOT_AWAY,
    RESPAWN_METRES,
    SLOW_ANSWERS,
    SLOW_PERIODS,
    TWO_SIGNALS,
    check_variants,
)
from conformance.sim.vehicle import LINKOPING, GeoPoint, Vehicle, destination
from conformance.topics import UnitAddress

__all__ = ["CAMERA_URL_EVERY", "Emit", "UnitCore"]  # CAMERA_URL_EVERY: bench/bench_sim.py

Emit = Callable[[str, bytes, bool], None]
HELD = frozenset({"exec/response", "exec/feedback", "tst/response", "tst/feedback"})
"""What variant slow holds back: every answer and every feedback (12.3, 12.4, 14.4, 14.5)."""
VENDOR = {"name": "waraps-conformance reference unit", "variant": "verbose"}
"""Variant verbose: the field of its own it adds to every message (2: more fields are not
forbidden; a reader ignores what it does not know)."""
RENAMES = 3
"""Fault reboot-renames: how many reboots bring a new name (later ones keep the last); the
runtime listens and may publish under every one of them from the start."""
REBOOT_SILENCE = 2.5
"""A reboot is silent for this many heartbeat periods, counted from the last heartbeat: more
than HB-006's two (so the new agent-uuid reads as a reboot), less than HB-010's three."""


class UnitCore:
    """The protocol logic of one simulated unit (no threads, no sockets).

    ``rate`` is the declared rate of heartbeat, info messages and sensors in Hz;
    ``task_seconds`` how long a simulated task takes (time compression, see
    ``conformance.sim.tasks``); ``phase`` delays the first publication by that many seconds
    (a fleet spreads its units over one period). ``tst_execution`` adds the TST level (14),
    listening also to ``tst_operator``'s tst/command (14.1). ``variants`` are conformant
    behaviours (``conformance.sim.variants``), switched on beside the faults.
    """

    def __init__(self, address: UnitAddress, emit: Emit, *, faults: Iterable[str] = (),
                 variants: Iterable[str] = (),
                 rate: float = 1.0, rng: random.Random | None = None,
                 position: GeoPoint | None = None, heading: float = 270.0,
                 task_seconds: float = 3.0, phase: float = 0.0,
                 clock: Callable[[], float] = time.time, tst_execution: bool = False,
                 tst_operator: UnitAddress | None = None) -> None:
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate {rate!r}: a rate is a positive number of Hz")
        self.address = address
        self.faults = check_names(list(faults))
        self.variants = check_variants(list(variants))
        self.rate = float(rate)
        self.period = 1.0 / self.rate
        self.rng = rng or random.Random()
        self.clock = clock
        self.task_seconds = REAL_SPEED_SECONDS if "real-speed" in self.variants \
            else task_seconds
        self._emit = emit
        self.vehicle = Vehicle(address.agent_type, position or GeoPoint(*LINKOPING, 0.0), heading)
        self.specs = self._tasks_offered()
        self.lives = self._lives()
        """The addresses of its lives: its own, then the names it takes after each reboot."""
        self.base = topic_base(address, self.faults)
        self.command_topic = f"{self.base}/exec/command"
        # Identity of one life (12.1: history is lost with a reboot).
        self.boot = 0
        self._counter = 0
        self.agent_uuid = self._new_agent_uuid()
        self.executor_uuid = self.new_uuid()  # faults response/feedback-stale-agent-uuid
        self.runner = TaskRunner(self)
        # The TST level (14), when declared (or a fault declares it). A fault of
        # tst_execution_info bends that message, not the running of trees.
        self.tst = TstEngine(self, tst_operator.base if tst_operator else None) if (
            tst_execution or self.faults & (TST_FAULTS | TST_LEVEL_FAULTS)) else None
        self.executor = CommandExecutor(self)
        self.publisher = Publisher(self)
        self.up = True
        self.crashed = False
        """Fault crash-on-malformed: the command thread died (heartbeats go on)."""
        self.dead = False
        """Fault dies-on-missing-task-uuid: the MQTT thread died; the process lives on (silent)."""
        self.back_at: float | None = None
        self.reboot_requested = False
        self.commands = 0
        self.published = 0
        self.retained_topics: set[str] = set()
        self.held: list[tuple[float, str, Any, str | None]] = []
        """Variant slow: (when, subtopic, body, base) of answers and feedback held back."""
        self._phase = phase
        self.due = 0.0

    def _lives(self) -> tuple[UnitAddress, ...]:
        """Its own address, then (fault reboot-renames) the names it takes after each reboot."""
        address = self.address
        return (address,) + tuple(
            address.with_name(f"{address.name}_{(0x9E37 * n) & 0xFFFF:04x}")
            for n in range(1, RENAMES + 1) if "reboot-renames" in self.faults)

    def _tasks_offered(self) -> dict[str, TaskSpec]:
        """Task name -> its spec: section 9's for its agent type, and the variants' (5.3: a
        task beyond section 9, the signals each task understands)."""
        specs = {t.name: t for t in tasks_for(self.address.agent_type)}
        if "own-task" in self.variants:
            specs[GO_HOME.name] = GO_HOME
        if "two-signals" in self.variants:
            for name in [n for n in specs if n.startswith("look-at-")]:
                specs[name] = dataclasses.replace(specs[name], signals=TWO_SIGNALS)
        return specs

    # --- what one life remembers ------------------------------------------------------------------
    @property
    def tasks(self) -> OrderedDict[str, Task]:
        """task-uuid -> the tasks this life started (TST leaves too)."""
        return self.runner.tasks

    @property
    def history(self) -> Resends[dict[str, Any] | None]:
        """com-uuid -> the response sent to that exec command, for resends."""
        return self.executor.history

    @property
    def heartbeats(self) -> int:
        """Heartbeats sent so far."""
        return self.publisher.heartbeats

    # --- identity -----------------------------------------------------------------------------
    def new_uuid(self) -> str:
        return str(uuid.UUID(int=self.rng.getrandbits(128), version=4))

    def _new_agent_uuid(self) -> str:
        if "agent-uuid-not-uuid" in self.faults:
            return f"{self.address.name}-{self.boot}"
        return self.new_uuid()

    def fresh_uuid(self) -> str:
        """A fresh com-uuid for a message of ours (2: 'Use UUID to identify a message')."""
        return self._counted("msg") if "uuid-counter" in self.faults else self.new_uuid()

    def task_uuid(self) -> str:
        """A task-uuid for a start-task that has none."""
        return self._counted("task") if "uuid-counter" in self.faults else self.new_uuid()

    def _counted(self, kind: str) -> str:
        # Fault uuid-counter (ERR-014): ids from one counter, 'msg-17', 'task-18'.
        self._counter += 1
        return f"{kind}-{self._counter}"

    # --- publishing ---------------------------------------------------------------------------
    def topic(self, sub: str) -> str:
        return f"{self.base}/{sub}"

    def emit(self, sub: str, payload: bytes, retain: bool = False,
             base: str | None = None) -> None:
        """Publish under this unit's base, or another (an operator's TST topics, 14.1)."""
        self.published += 1
        topic = f"{base or self.base}/{sub}"
        if retain:
            self.retained_topics.add(topic)
        self._emit(topic, payload, retain)

    def send(self, sub: str, body: Any, *, retain: bool = False, base: str | None = None) -> None:
        """Publish ``body`` as JSON; sorted keys, like the spec's examples (variant key-order:
        reversed). Variant slow holds answers and feedback back (``send_held``)."""
        if sub in HELD and ("slow" in self.variants or (
                "slow-answers" in self.variants and sub.endswith("/response"))):
            hold = SLOW_PERIODS * self.period if "slow" in self.variants else \
                self.rng.uniform(*SLOW_ANSWERS)
            when = max(self.runner.now + hold, self.held[-1][0] if self.held else 0.0)
            self.held.append((when, sub, body, base))
            self.due = min(self.due, when)
            return
        self._publish(sub, body, retain, base)

    def _publish(self, sub: str, body: Any, retain: bool = False,
                 base: str | None = None) -> None:
        if "verbose" in self.variants and isinstance(body, dict):
            body = {**body, "x-software": VENDOR}
        if "integer-numbers" in self.variants:
            body = _integers(body)
        indent = orjson.OPT_INDENT_2 if "pretty-json" in self.variants else 0
        if "key-order" in self.variants:
            payload = orjson.dumps(_reversed_keys(body), option=indent)
        else:
            payload = orjson.dumps(body, option=orjson.OPT_SORT_KEYS | indent)
        self.emit(sub, payload, retain, base)

    def send_held(self, now: float) -> float | None:
        """Variant slow: send what is due of what was held back, in the order it was made;
        when the next one is due (None: nothing held)."""
        while self.held and self.held[0][0] <= now:
            _, sub, body, base = self.held.pop(0)
            self._publish(sub, body, base=base)
        return self.held[0][0] if self.held else None

    def clear_retained(self) -> None:
        """Remove what this unit left retained on the broker (an empty retained message)."""
        for topic in sorted(self.retained_topics):
            self._emit(topic, b"", True)
        self.retained_topics.clear()

    # --- time ---------------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Schedule the periodic messages; the first ones go out at ``now + phase``."""
        first = now + self._phase
        self.publisher.start(first)
        self.runner.last_step = now
        self.due = first

    def run(self, now: float) -> None:
        """Do what is due at ``now``: come back from a reboot, step the tasks and the vehicle,
        publish the periodic messages. Sets ``due``, when to be called next."""
        if self.reboot_requested:
            self._go_down(now)
        if not self.up:
            if self.back_at is not None and now >= self.back_at:
                self._come_back(now)
            else:
                self.due = self.back_at if self.back_at is not None else now + self.period
                return
        if self.dead:  # publishes nothing until a reboot restarts the process
            self.due = now + self.period
            return
        self.runner.step(now)
        held = self.executor.send_delayed(now)
        slow = self.send_held(now)
        due = self.publisher.publish_due(now)
        for when in (held, slow):
            if when is not None:
                due = min(due, when)
        if self.runner.busy():
            due = min(due, now + STEP)
        self.due = due

    def busy(self) -> bool:
        """Whether a task runs or the vehicle moves (``run`` is then due every STEP)."""
        return self.runner.busy()

    # --- reboot -------------------------------------------------------------------------------
    def request_reboot(self) -> None:
        """Reboot at the next ``run``: silent for a moment, history lost, new agent-uuid."""
        self.reboot_requested = True

    def _go_down(self, now: float) -> None:
        self.reboot_requested = False
        self.up = False
        self.executor.delayed.clear()  # what the old process held back dies with it
        self.held.clear()
        last = self.publisher.last_heartbeat
        last = now if last is None else last
        self.back_at = max(now + 0.1 * self.period, last + REBOOT_SILENCE * self.period)
        if "reboot-away" in self.variants:  # a reboot as long as a real unit's
            self.back_at = now + REBOOT_AWAY
        self.vehicle.stop()
        self.vehicle.speed = 0.0
        self.vehicle.look_at = None

    def _come_back(self, now: float) -> None:
        self.boot += 1
        if len(self.lives) > 1:  # fault reboot-renames: a new name for the new life
            self.address = self.lives[min(self.boot, len(self.lives) - 1)]
            self.base = topic_base(self.address, self.faults)
            self.command_topic = f"{self.base}/exec/command"
        if "reboot-keeps-agent-uuid" not in self.faults:
            self.agent_uuid = self._new_agent_uuid()
        if "reboot-remembers-history" not in self.faults:
            self.executor.history.clear()
            self.runner.tasks.clear()
        else:  # history kept on disk, but what ran has stopped
            for t in self.runner.tasks.values():
                if not t.ended:
                    t.status, t.fail_reason = "failed", "interrupted by a reboot"
        if self.tst is not None:
            self.tst.forget()
        if "respawn" in self.variants:  # a new life starts where its simulator spawns it
            # A bearing of its own per life (the golden angle), not drawn from rng: the
            # identifiers of the new life stay those of a unit without the variant.
            self.vehicle.position = destination(self.vehicle.position, self.boot * 137.5,
                                                RESPAWN_METRES)
        self.crashed = False
        self.dead = False
        self.up = True
        self.back_at = None
        self.runner.last_step = now
        self.publisher.restart(now)

    # --- commands -----------------------------------------------------------------------------
    def command(self, payload: bytes, now: float, size: int | None = None) -> None:
        """Handle one message from ``exec/command``; ``size`` is its length in bytes when
        ``payload`` is only its head. Never raises on hostile input."""
        if not self.up or self.crashed or self.dead:
            return  # rebooting, or the command thread died (faults crash-on-malformed, dies-...)
        self.commands += 1
        self.runner.step(now)
        self.executor.command(payload, now, len(payload) if size is None else size)

    def tst_command(self, payload: bytes, now: float, topic: str) -> None:
        """Handle one message from a ``tst/command`` topic (14; ``conformance.sim.tst``)."""
        if self.tst is None or not self.up or self.crashed:
            return
        self.runner.step(now)
        self.tst.command(payload, now, topic)


def _integers(value: Any) -> Any:
    """``value`` with every whole float written as an integer (variant integer-numbers)."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 2 ** 53:
        return int(value)
    if isinstance(value, dict):
        return {k: _integers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_integers(v) for v in value]
    return value


def _reversed_keys(value: Any) -> Any:
    """``value`` with every object's keys in reverse alphabetical order (variant key-order)."""
    if isinstance(value, dict):
        return {k: _reversed_keys(value[k]) for k in sorted(value, reverse=True)}
    if isinstance(value, list):
        return [_reversed_keys(v) for v in value]
    return value

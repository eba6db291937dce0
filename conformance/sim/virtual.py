"""The reference pair in virtual time (``--broker virtual``, for the test suite's matrices only):
an in-memory broker double and the reference unit, both driven by one ``VirtualClock``.

The unit is the same ``UnitCore`` the real runtime drives (``conformance.sim.runtime``): run
when it is due, handed each command, its stamps read from the clock. The broker delivers each
message ``LATENCY`` seconds after it was published, in publishing order, keeps retained
messages for later subscribers, and applies the suite's publish policy as ``MqttClient`` does
(docs/ARCHITECTURE.md 'Safety'), and can stop for a while (``outage``: what is published meanwhile
is lost, the suite's side is told its link went and came back), so that an outage at an exact moment
of a conversation is a deterministic test. Nothing here touches a socket or a thread: the
real-broker behaviours (reconnects, freezes, QoS) stay tested on amqtt and Mosquitto.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from conformance.client import PayloadPolicy, PublishPolicy, PublishRefused
from conformance.clock import VirtualClock
from conformance.message import Gap, Message
from conformance.sim.command_reading import MAX_COMMAND_BYTES
from conformance.sim.publisher import topic_base
from conformance.sim.reference import ReferenceUnit
from conformance.sim.runtime import OVERSIZE_KEEP
from conformance.sim.unit import UnitCore

LATENCY = 0.002
"""Seconds from a publish to its delivery (a loopback broker's order of magnitude)."""
RETAINED = 10_000
"""Retained topics the double keeps at most (bounded: the unit's own are a handful)."""
TAPS: list[Callable[[Message], None]] = []
"""Handed every message any double carries, at its delivery time, as a recorder subscribed
to ``#`` would get it (the variant matrix records its certifications to lint them). Whoever
adds one removes it."""


def matches(pattern: str, topic: str) -> bool:
    """MQTT topic filter matching (``+`` one level, ``#`` the rest)."""
    want, have = pattern.split("/"), topic.split("/")
    for i, part in enumerate(want):
        if part == "#":
            return True
        if i >= len(have) or (part != "+" and part != have[i]):
            return False
    return len(want) == len(have)


@dataclass(eq=False)
class VirtualBroker:
    """An in-memory MQTT broker double on a ``VirtualClock``."""

    clock: VirtualClock
    _subscribers: list[tuple[str, Callable[[Message], None]]] = field(default_factory=list)
    _retained: dict[str, bytes] = field(default_factory=dict)
    down: bool = False
    """Stopped (``outage``): what is published, or due for delivery, meanwhile is lost."""
    _watchers: list[Callable[[bool], None]] = field(default_factory=list)
    held_until: float = 0.0
    """Frozen (``freeze``) until then: deliveries due meanwhile wait for it."""
    drain: float = 0.0
    """Seconds per held message as a freeze's backlog is worked off (``freeze``)."""
    delay: float = 0.0
    """Seconds every delivery takes beyond ``LATENCY``: a loaded broker, late but in order."""
    _backlog: deque[Callable[[], None]] = field(default_factory=deque)
    _releasing: bool = False

    def outage(self, seconds: float) -> None:
        """Stop now and start again ``seconds`` later, as a broker killed and restarted: every
        client is told at both ends (its link lost, back), retained messages survive."""
        self._set_down(True)
        self.clock.at(self.clock.now() + seconds, lambda: self._set_down(False))

    def freeze(self, seconds: float, drain: float = 0.0) -> None:
        """Hold every delivery for ``seconds``, then deliver what was held in order, as a
        broker stopped (SIGSTOP) and continued: no client is told anything. ``drain``: seconds
        per held message (0: all at once; more: a loaded broker working off its backlog, with
        what is published meanwhile queued behind it)."""
        self.held_until, self.drain = self.clock.now() + seconds, drain

    def _set_down(self, down: bool) -> None:
        self.down = down
        for watcher in list(self._watchers):
            watcher(not down)

    def watch(self, connected: Callable[[bool], None]) -> None:
        """Call ``connected(False)`` when the broker stops, ``connected(True)`` when back."""
        self._watchers.append(connected)

    def subscribe(self, pattern: str, deliver: Callable[[Message], None]) -> None:
        self._subscribers.append((pattern, deliver))
        for topic, payload in list(self._retained.items()):
            if matches(pattern, topic):
                self._later(deliver, topic, payload, retain=True)

    def publish(self, topic: str, payload: bytes, retain: bool = False, qos: int = 0) -> None:
        if self.down:
            return  # lost: nobody is there to take it
        if retain:
            if not payload:
                self._retained.pop(topic, None)
            elif topic in self._retained or len(self._retained) < RETAINED:
                self._retained[topic] = payload
        for pattern, deliver in list(self._subscribers):
            if matches(pattern, topic):
                self._later(deliver, topic, payload, retain=False, qos=qos)
        for tap in list(TAPS):
            self._later(tap, topic, payload, retain=False, qos=qos)

    def _later(self, deliver: Callable[[Message], None], topic: str, payload: bytes, *,
               retain: bool, qos: int = 0) -> None:
        when = self.clock.now() + LATENCY + self.delay

        def now() -> None:
            if not self.down:  # in flight when it stopped: lost
                deliver(Message(self.clock.now(), topic, payload, qos, retain))

        def delivery() -> None:
            if self.clock.now() < self.held_until or self._backlog:
                self._backlog.append(now)  # frozen, or still working off its backlog
                self._release_later()
            else:
                now()
        self.clock.at(when, delivery)

    def _release_later(self) -> None:
        if not self._releasing:
            self._releasing = True
            self.clock.at(self.held_until, self._release)

    def _release(self) -> None:
        """Deliver the oldest held message; the next one ``drain`` seconds later."""
        if self._backlog:
            self._backlog.popleft()()
        if self._backlog:
            self.clock.at(self.clock.now() + self.drain, self._release)
        else:
            self._releasing = False


@dataclass(eq=False)
class VirtualClient:
    """The suite's side of the double, with ``MqttClient``'s interface as ``Connection`` uses
    it, and the same publish policy. ``on_connection_change(connected, reason)`` is told when
    the broker stops and comes back (``VirtualBroker.outage``), as ``MqttClient`` tells it."""

    broker: VirtualBroker
    on_message: Callable[[Message], None]
    may_publish: PublishPolicy
    refuse_payload: PayloadPolicy | None = None
    on_connection_change: Callable[[bool, str], None] | None = None
    gaps: list[Gap] = field(default_factory=list)
    is_connected: bool = True

    def __post_init__(self) -> None:
        self.broker.watch(self._connection)
        if self.on_connection_change is not None:  # connected at once, as MqttClient says
            self.on_connection_change(True, "connected")

    def _connection(self, connected: bool) -> None:
        if not self.is_connected and connected and self.gaps and self.gaps[-1].end is None:
            self.gaps[-1] = Gap(self.gaps[-1].start, self.broker.clock.now(),
                                self.gaps[-1].reason)
        elif self.is_connected and not connected:
            self.gaps.append(Gap(self.broker.clock.now(), None, "the broker stopped"))
        self.is_connected = connected
        if self.on_connection_change is not None:
            self.on_connection_change(connected, "connected" if connected
                                      else "the broker stopped")

    def subscribe(self, topic: str, qos: int = 0, timeout: float = 5.0) -> None:
        self.broker.subscribe(topic, self.on_message)

    def publish(self, topic: str, payload: bytes | str, qos: int = 1, retain: bool = False,
                timeout: float = 5.0) -> None:
        data = payload.encode() if isinstance(payload, str) else bytes(payload)
        if not self.may_publish(topic):
            raise PublishRefused(f"refusing to publish to {topic!r}: not a command topic of "
                                 f"the unit under test (docs/ARCHITECTURE.md 'Safety')")
        why = self.refuse_payload(topic, data) if self.refuse_payload is not None else None
        if why:
            raise PublishRefused(f"refusing to publish to {topic!r}: {why}")
        self.broker.publish(topic, data, retain, qos)

    def wait_connected(self, timeout: float) -> bool:
        clock = self.broker.clock
        end = clock.now() + timeout
        while not self.is_connected and clock.now() < end:
            clock.wait(None, end - clock.now())
        return self.is_connected

    def reconnect_backoff(self, seconds: float) -> None:
        pass

    def close(self) -> None:
        self.is_connected = False


@dataclass(eq=False)
class VirtualReference(ReferenceUnit):
    """The reference unit on a ``VirtualBroker``: ``Reference``'s interface, in virtual time
    on ``clock``."""

    clock: VirtualClock = field(kw_only=True)
    task_seconds: float = 3.0
    """How long a simulated task takes (``UnitCore``'s)."""
    reconnect_delay: float = field(default=0.0, kw_only=True)
    """Seconds after the broker double comes back (``outage``) before the unit is back on it
    too, as a real unit reconnects by its own backoff: until then it hears and says nothing."""
    broker: VirtualBroker = field(init=False)
    core: UnitCore = field(init=False)
    _away_until: float = field(default=0.0, init=False)
    url = "virtual"

    def start(self) -> VirtualReference:
        self.broker = VirtualBroker(self.clock)
        self.broker.watch(self._connection)
        # Seeded as SimUnit seeds it: the same uuids as the unit on a real broker.
        rng = random.Random(f"{self.seed}:{self.unit.name}") if self.seed is not None \
            else random.Random()
        self.core = UnitCore(self.unit, self._publish, faults=self.faults,
                             variants=self.variants, rate=self.rate, rng=rng,
                             clock=self.clock.now, tst_execution=self.tst,
                             tst_operator=self.tst_operator, task_seconds=self.task_seconds)
        core = self.core
        for life in core.lives:  # as the runtime listens: every name of every life
            self.broker.subscribe(f"{topic_base(life, core.faults)}/exec/command", self._command)
        if core.tst is not None:
            for topic in core.tst.topics:
                self.broker.subscribe(topic, self._tst_command)
        core.start(self.clock.monotonic())
        self._schedule()
        return self

    def _schedule(self) -> None:
        due = self.core.due
        self.clock.at(due, lambda: self._run(due))

    def _run(self, due: float) -> None:
        if due != self.core.due:
            return  # superseded by an earlier wake-up
        self.core.run(self.clock.monotonic())
        self._schedule()

    def _connection(self, up: bool) -> None:
        self._away_until = self.clock.now() + self.reconnect_delay if up else math.inf

    def _here(self) -> bool:
        """Whether the unit is on the broker (not away since an ``outage``)."""
        return self.clock.now() >= self._away_until

    def _publish(self, topic: str, payload: bytes, retain: bool = False) -> None:
        if self._here():  # variant mqtt5-qos1: the double carries its QoS (not MQTT 5)
            qos = 1 if "mqtt5-qos1" in self.core.variants else 0
            self.broker.publish(topic, payload, retain, qos)

    def _command(self, message: Message) -> None:
        if not self._here():
            return
        payload, size = message.payload, len(message.payload)
        if size > MAX_COMMAND_BYTES:  # refused as too large; the head names its com-uuid
            payload = payload[:OVERSIZE_KEEP]
        self._deliver(self.core.command, payload, self.clock.monotonic(), size)

    def _tst_command(self, message: Message) -> None:
        if not self._here():
            return
        self._deliver(self.core.tst_command, message.payload, self.clock.monotonic(),
                      message.topic)

    def _deliver(self, handler: Callable[..., object], *args: object) -> None:
        core, now = self.core, self.clock.monotonic()
        before = core.due
        handler(*args)
        if core.due != before or core.busy():
            core.due = min(core.due, now)
            self._schedule()

    def reboot(self) -> None:
        self.core.request_reboot()
        self.core.run(self.clock.monotonic())
        self._schedule()

    def stop(self) -> None:
        pass

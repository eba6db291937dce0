"""The runtime of simulated units: one MQTT connection and one thread for any number of them.

The thread keeps a heap of when each unit is next due and runs it then (periodic messages,
simulation steps); commands arrive on paho's network thread, wait in a bounded inbox and are
handed to their unit on the runtime thread, so a unit's state is only ever touched by one
thread. One connection for a whole fleet is what lets 500 units at 1 Hz run on one core
(docs/FIELD-NOTES.md 'MQTT on loopback': per-message cost is what counts).

Safety (docs/ARCHITECTURE.md 'Safety'): the client may publish only under the bases of its own
units (and of the TST operator whose tst/command they were told to listen to, 14.1), and never
to a command topic.
"""

from __future__ import annotations

import heapq
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from conformance.client import BrokerURL, Message, MqttClient
from conformance.sim.command_reading import MAX_COMMAND_BYTES
from conformance.sim.publisher import topic_base

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

INBOX_BYTES = 32 << 20
"""Commands waiting to be handled may hold at most this many bytes (32 MiB): under a flood the
newest are dropped and counted, so memory stays bounded."""
OVERSIZE_KEEP = 65536
"""Of a command over MAX_COMMAND_BYTES only the head is kept: enough to read its com-uuid and
refuse it."""
BATCH = 256
"""Commands handled between two looks at the schedule, so a flood cannot delay heartbeats."""
HOLD_MARK = 0.25
"""A wait that returns this many seconds or more late was held by the host (a loaded machine),
not by the units' own code: ``on_hold`` is told (a unit at 2 Hz is then half a period late)."""


class Runtime:
    """Drives ``UnitCore`` objects over one MQTT connection in a background thread."""

    def __init__(self, broker: str | BrokerURL, *, client_id: str | None = None) -> None:
        self.broker = broker if isinstance(broker, BrokerURL) else BrokerURL.parse(broker)
        self.units: list[UnitCore] = []
        self._by_topic: dict[str, int] = {}
        self._tst_by_topic: dict[str, list[int]] = {}
        """tst/command topic -> the units listening (an operator's is shared: 14.1)."""
        self._bases: set[str] = set()
        self._client_id = client_id
        self.client: MqttClient | None = None
        self._inbox: deque[tuple[str, bytes, int]] = deque()
        self._inbox_bytes = 0
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._control: deque[tuple[str, int]] = deque()
        self._stopping = False
        self._thread: threading.Thread | None = None
        self._heap: list[tuple[float, int]] = []
        self._started: set[int] = set()
        self._all_started = threading.Event()
        self.dropped = 0
        """Commands dropped because the inbox was full (a flood)."""
        self.errors = 0
        """Exceptions raised by unit code (a bug: the tests require zero)."""
        self.last_error = ""
        self._qos = 0
        self.held = 0.0
        """The most seconds a unit's step ran after it was due: how long the host held this
        thread (a loaded machine), so that a silence it caused is not taken for the unit's."""
        self.on_hold: Callable[[float, float], None] | None = None
        """Told each time the host held this thread ``HOLD_MARK`` or more past the end of a wait:
        from when to when (Unix seconds). A certification of the bundled unit in its own
        process marks that time as the observer's (``suite/connection.py``)."""

    def add(self, unit: UnitCore) -> int:
        """Add a unit before ``start``; returns its index."""
        if self._thread is not None:
            raise RuntimeError("add units before start()")
        self.units.append(unit)
        index = len(self.units) - 1
        for life in unit.lives:  # one, or the names a renaming unit takes (reboot-renames)
            base = topic_base(life, unit.faults)
            self._by_topic[f"{base}/exec/command"] = index
            self._bases.add(base)
        if unit.tst is not None:
            for topic in unit.tst.topics:
                self._tst_by_topic.setdefault(topic, []).append(index)
            if unit.tst.operator:  # it answers there too (14.1; ERR-016)
                self._bases.add(unit.tst.operator)
        return index

    @property
    def mqtt5_qos1(self) -> bool:
        """Variant mqtt5-qos1 on any of its units: MQTT 5, every message at QoS 1 (2)."""
        return any("mqtt5-qos1" in unit.variants for unit in self.units)

    def publish(self, topic: str, payload: bytes, retain: bool) -> None:
        """What a unit emits, at QoS 0 while connected (the ``emit`` of each ``UnitCore``);
        at QoS 1 with variant mqtt5-qos1, never waiting on the broker's ack (this thread
        keeps every unit's schedule)."""
        client = self.client
        if client is not None:
            client.publish(topic, payload, qos=self._qos, retain=retain, wait=False)

    # --- safety -------------------------------------------------------------------------------
    def may_publish(self, topic: str) -> bool:
        """Only under one of our units' bases, never to a command topic (docs/ARCHITECTURE.md
        'Safety')."""
        lead = 1 if topic.startswith("/") else 0
        parts = topic.split("/", 5 + lead)
        if len(parts) <= 5 + lead or topic.endswith(("/exec/command", "/tst/command")):
            return False
        return "/".join(parts[:5 + lead]) in self._bases

    def subscriptions(self) -> list[str]:
        """The command topics to subscribe: one wildcard for a fleet sharing prefix, type and
        role (``<prefix>/unit/<type>/<role>/+/exec/command``), plus any unit outside it; the
        same for ``tst/command`` (and an operator's, as it is)."""
        return (_compress(list(self._by_topic), "exec/command")
                + _compress(list(self._tst_by_topic), "tst/command"))

    # --- lifecycle ----------------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> None:
        """Connect, subscribe, start the thread; return once every unit has sent its first
        heartbeat (a fleet spreads its units over one period)."""
        if not self.units:
            raise ValueError("no units to run")
        self._qos = 1 if self.mqtt5_qos1 else 0
        client = MqttClient(self.broker, client_id=self._client_id, on_message=self.receive,
                            may_publish=self.may_publish, mqtt5=self.mqtt5_qos1)
        client.connect(timeout=min(timeout, 5.0))
        self.client = client
        try:
            for topic in self.subscriptions():
                client.subscribe(topic, qos=1, timeout=min(timeout, 5.0))
            now = time.monotonic()
            for i, unit in enumerate(self.units):
                unit.start(now)
                self._heap.append((unit.due, i))
            heapq.heapify(self._heap)
            self._thread = threading.Thread(target=self._run, name="waraps-sim", daemon=True)
            self._thread.start()
            if not self._all_started.wait(timeout):
                raise TimeoutError(f"{len(self.units) - len(self._started)} of "
                                   f"{len(self.units)} units sent no heartbeat within "
                                   f"{timeout:.1f} s")
        except BaseException:
            self.stop()
            raise

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread, clear what was retained, disconnect."""
        self._stopping = True
        self._wake.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        client, self.client = self.client, None
        if client is not None:
            for unit in self.units:
                try:
                    unit.clear_retained()
                except Exception:  # the broker may already be gone
                    pass
            client.close()

    def reboot(self, index: int | None = None, *, wait: bool = False,
               timeout: float = 30.0) -> None:
        """Reboot one unit (by index) or all; with ``wait``, return once they are back."""
        indexes = range(len(self.units)) if index is None else [index]
        boots = {i: self.units[i].boot for i in indexes}
        with self._lock:
            self._control.extend(("reboot", i) for i in indexes)
        self._wake.set()
        if not wait:
            return
        deadline = time.monotonic() + timeout
        while any(self.units[i].boot == b or not self.units[i].up for i, b in boots.items()):
            if time.monotonic() > deadline:
                raise TimeoutError(f"units did not come back from a reboot within {timeout} s")
            time.sleep(0.01)  # a poll inside a deadline, not a fixed sleep

    def kill(self, index: int) -> None:
        """Kill one unit (by index) as a process whose MQTT thread died: it publishes nothing
        from its next step on, until a reboot restarts it (``reboot``)."""
        with self._lock:
            self._control.append(("kill", index))
        self._wake.set()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive() and not self._stopping

    # --- inbound ------------------------------------------------------------------------------
    @property
    def inbox_bytes(self) -> int:
        """Bytes of commands received and not yet handled (at most ``INBOX_BYTES``)."""
        return self._inbox_bytes

    def receive(self, message: Message) -> None:
        """A message for the units (called on paho's network thread): queued, bounded (never
        blocks, never grows); ``dropped`` counts what did not fit."""
        payload = message.payload
        size = len(payload)
        if size > MAX_COMMAND_BYTES:
            payload = payload[:OVERSIZE_KEEP]  # refused as too large; the head names its com-uuid
        with self._lock:
            if self._inbox_bytes + len(payload) > INBOX_BYTES:
                self.dropped += 1
                return
            self._inbox.append((message.topic, payload, size))
            self._inbox_bytes += len(payload)
        self._wake.set()

    # --- the runtime thread -----------------------------------------------------------------------
    def _run(self) -> None:
        heap = self._heap
        while not self._stopping:
            self._wake.clear()
            now = time.monotonic()
            self._handle_control(now)
            self._handle_inbox(now)
            now = time.monotonic()
            while heap and heap[0][0] <= now and not self._stopping:
                due, i = heapq.heappop(heap)
                unit = self.units[i]
                if due != unit.due:
                    continue  # superseded by an earlier entry for this unit
                self.held = max(self.held, now - due)
                self._guarded(unit.run, now)
                self._reschedule(i)
            if self._inbox:
                continue
            wait = (heap[0][0] - time.monotonic()) if heap else 0.5
            if wait > 0:
                self._sleep(min(wait, 0.5))

    def _sleep(self, seconds: float) -> None:
        """Wait ``seconds`` or until woken. A wait that ran out and returned ``HOLD_MARK`` or
        more late was the host's (the thread was ready and not run), never the units' own work
        (a reboot, a flood of commands): ``on_hold`` is told."""
        began = time.monotonic()
        if self._wake.wait(seconds) or self.on_hold is None:
            return
        late = time.monotonic() - began - seconds
        if late >= HOLD_MARK:
            wall = time.time()
            self.on_hold(wall - late, wall)

    def _reschedule(self, i: int) -> None:
        unit = self.units[i]
        heapq.heappush(self._heap, (unit.due, i))
        if i not in self._started and unit.heartbeats > 0:
            self._started.add(i)
            if len(self._started) == len(self.units):
                self._all_started.set()

    def _guarded(self, fn: Callable[..., object], *args: object) -> None:
        try:
            fn(*args)
        except Exception as e:  # a bug must not stop the other units: count and report it
            self.errors += 1
            self.last_error = f"{type(e).__name__}: {e}"
            if self.errors <= 5:
                import traceback

                print(f"waraps-conformance sim: internal error {self.last_error}",
                      file=sys.stderr)
                traceback.print_exc()

    def _handle_control(self, now: float) -> None:
        while True:
            with self._lock:
                if not self._control:
                    return
                what, i = self._control.popleft()
            if what == "reboot":
                self.units[i].request_reboot()
                self._guarded(self.units[i].run, now)
                self._reschedule(i)
            elif what == "kill":
                self.units[i].dead = True

    def _handle_inbox(self, now: float) -> None:
        for _ in range(BATCH):
            with self._lock:
                if not self._inbox:
                    return
                topic, payload, size = self._inbox.popleft()
                self._inbox_bytes -= len(payload)
            i = self._by_topic.get(topic)
            if i is not None:
                self._deliver(i, now, self.units[i].command, payload, now, size)
                continue
            for i in self._tst_by_topic.get(topic, ()):  # else: a unit that is not ours
                self._deliver(i, now, self.units[i].tst_command, payload, now, topic)

    def _deliver(self, i: int, now: float, handler: Callable[..., object],
                 *args: object) -> None:
        unit = self.units[i]
        before = unit.due
        self._guarded(handler, *args)
        if unit.due != before or unit.busy():
            unit.due = min(unit.due, now)
            self._reschedule(i)


def _compress(topics: list[str], tail: str) -> list[str]:
    """``<head>/+/<tail>`` for the largest group of topics sharing a head, plus the others."""
    if len(topics) <= 2:
        return topics
    shared: dict[str, int] = {}
    for t in topics:
        head = t.rsplit("/", 3)[0]
        shared[head] = shared.get(head, 0) + 1
    head = max(shared, key=lambda h: shared[h])
    if shared[head] < 2:
        return topics
    return [f"{head}/+/{tail}"] + [t for t in topics if t.rsplit("/", 3)[0] != head]


def spread(count: int, period: float) -> Sequence[float]:
    """Phases that spread ``count`` units evenly over one period (seconds), so a fleet does not
    publish in bursts (Mosquitto drops past 1000 queued messages per client:
    docs/FIELD-NOTES.md 'MQTT on loopback')."""
    return [period * i / count for i in range(count)] if count > 1 else [0.0]

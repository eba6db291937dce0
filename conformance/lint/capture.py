"""Live capture: subscribe read-only and hold what arrives in a bounded buffer.

paho's network thread only appends each message to a bounded queue (a few microseconds), so it
keeps reading the socket however slow the examination is; Mosquitto would otherwise drop
messages silently once 1000 are queued for us (docs/FIELD-NOTES.md 'MQTT on loopback'), and healthy
units would look too
slow. When the queue is full the *oldest* messages are dropped and counted: the consumer is
told with an ``unexamined`` event, so rate checks for that window are not judged instead of
reporting false rate violations. Connection losses become ``disconnected`` / ``connected``
events (MqttClient reconnects with backoff).

Shared by ``waraps-conformance lint`` and ``waraps-conformance record``.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

from conformance.client import BrokerURL, Message, MqttClient, publish_nowhere
from conformance.recording import Event
from conformance.topics import TopicError, UnitAddress, filter_problem

DEFAULT_TOPIC = "waraps/#"
MAX_QUEUED_MESSAGES = 200_000
MAX_QUEUED_BYTES = 256 << 20
"""Bounds of the capture queue: about 10 s of a loaded 20k messages/s broker, or 256 MiB of
payloads, whichever comes first (a flood of 10 MB payloads must not exhaust memory)."""
MESSAGE_OVERHEAD = 200
"""Bytes a queued message costs besides its payload and topic (object headers)."""
WAKE_AT = 256
"""Queued messages at which the consumer is woken before its timeout. Waking it for every
message made the two threads hand the GIL back and forth per message, which halved what paho
could receive (bench/bench_lint.py live); a batch per wake costs the linter nothing but a
fraction of a second of latency."""


class CaptureOptionsError(ValueError):
    """Capture options that cannot be used; the message says which and how to fix them."""


@dataclass(frozen=True)
class CaptureOptions:
    """What to capture: the broker, the subscriptions, the units of interest, for how long."""

    broker: BrokerURL | None
    topics: tuple[str, ...]
    units: tuple[UnitAddress, ...] = ()
    duration: float | None = None
    """Seconds; None until Ctrl-C (or the end of a recording)."""

    def wants(self, topic: str) -> bool:
        """Whether a message on ``topic`` is about one of the units asked for (all if none)."""
        if not self.units:
            return True
        t = topic.lstrip("/")
        return any(t.startswith(u.base + "/") for u in self.units)

    def with_broker(self, broker: BrokerURL) -> CaptureOptions:
        """The same capture from ``broker`` (e.g. with its TLS files)."""
        return replace(self, broker=broker)


def capture_options(broker: str | None, *, topics: Sequence[str] = (),
                    units: Sequence[str] = (), duration: float | None = None,
                    need_broker: bool = True) -> CaptureOptions:
    """Capture options from the broker URL, filters and unit addresses as a person gives
    them (``broker`` None: from the environment, when ``need_broker``), for ``duration``
    seconds (None: until stopped); CaptureOptionsError says what to fix."""
    addresses: list[UnitAddress] = []
    for text in units:
        try:
            addresses.append(UnitAddress.parse(text))
        except TopicError as e:
            raise CaptureOptionsError(f"--unit: {e}") from None
    filters = tuple(topics or ([f"{u.base}/#" for u in addresses] or [DEFAULT_TOPIC]))
    for t in filters:
        problem = filter_problem(t)
        if problem:
            raise CaptureOptionsError(problem)
    url = None
    if need_broker:
        try:
            url = BrokerURL.parse(broker) if broker else BrokerURL.from_env()
        except ValueError as e:
            raise CaptureOptionsError(str(e)) from None
        if url is None:
            raise CaptureOptionsError("no broker: pass --broker mqtt://host:port (or set "
                                      "WARAPS_BROKER), or --from FILE to read a recording")
        if url.scheme == "embedded":
            raise CaptureOptionsError("--broker embedded: an embedded broker has no fleet to "
                                      "observe; pass its mqtt:// URL instead")
    return CaptureOptions(url, filters, tuple(addresses), duration)


class LiveCapture:
    """Subscribes (never publishes) and buffers messages and connection events.

    ``take(timeout)`` returns what arrived, oldest first: ``(messages, events)``. The buffer
    holds at most ``max_messages`` messages and ``max_bytes`` bytes; on overflow the oldest
    are dropped, ``dropped`` counts them and an ``unexamined`` event reports them.
    """

    def __init__(self, broker: BrokerURL, topics: tuple[str, ...] | list[str], *,
                 max_messages: int = MAX_QUEUED_MESSAGES, max_bytes: int = MAX_QUEUED_BYTES,
                 client_id: str | None = None) -> None:
        self.broker = broker
        self.topics = tuple(topics)
        self.max_messages = max_messages
        self.max_bytes = max_bytes
        self.wake_at = WAKE_AT
        self._queue: deque[Message] = deque()
        self._nonempty = threading.Event()
        self._events: list[Event] = []
        self._events_lock = threading.Lock()
        # Byte accounting without a lock: each counter has a single writer thread.
        self._in_bytes = 0        # paho thread
        self._dropped_bytes = 0   # paho thread
        self._out_bytes = 0       # consumer thread
        self.dropped = 0          # paho thread
        self._dropped_reported = 0  # consumer thread
        self.received = 0
        self._connected_once = False
        self.client = MqttClient(broker, client_id=client_id, on_message=self._enqueue,
                                 may_publish=publish_nowhere,
                                 on_connection_change=self._connection_changed)

    # --- paho's network thread ------------------------------------------------------------------
    def _enqueue(self, message: Message) -> None:
        q = self._queue
        cost = len(message.payload) + len(message.topic) + MESSAGE_OVERHEAD
        self.received += 1
        if (len(q) >= self.max_messages
                or self._in_bytes - self._out_bytes - self._dropped_bytes + cost > self.max_bytes):
            # Fell behind: drop the oldest (their window is already past), count them.
            while q and (len(q) >= self.max_messages or self._in_bytes - self._out_bytes
                         - self._dropped_bytes + cost > self.max_bytes):
                try:
                    old = q.popleft()
                except IndexError:  # the consumer took it meanwhile
                    break
                self.dropped += 1
                self._dropped_bytes += len(old.payload) + len(old.topic) + MESSAGE_OVERHEAD
        self._in_bytes += cost
        q.append(message)
        if len(q) >= self.wake_at and not self._nonempty.is_set():
            self._nonempty.set()

    def _connection_changed(self, connected: bool, reason: str) -> None:
        if connected and not self._connected_once:
            self._connected_once = True
            return
        event = Event(time.time(), "connected" if connected else "disconnected",
                      "" if connected else reason)
        with self._events_lock:
            self._events.append(event)
        self._nonempty.set()

    # --- the consumer -----------------------------------------------------------------------------
    def start(self, timeout: float = 5.0) -> LiveCapture:
        """Connect and subscribe; BrokerError says what failed and how to fix it."""
        self.client.connect(timeout)
        try:
            for topic in self.topics:
                self.client.subscribe(topic, qos=0, timeout=timeout)
        except BaseException:
            self.client.close()
            raise
        return self

    def take(self, timeout: float, max_messages: int = 2000) -> tuple[list[Message], list[Event]]:
        """What arrived, oldest first. Waits at most ``timeout`` seconds, returning sooner
        once ``wake_at`` messages (or a connection event) are there: a batch per call."""
        q = self._queue
        if len(q) < self.wake_at and not self._events and not self._has_new_drops():
            self._nonempty.clear()
            if len(q) < self.wake_at and not self._events:  # re-check: the producer may
                self._nonempty.wait(max(0.0, timeout))     # have just appended
        events: list[Event] = []
        if self._events:
            with self._events_lock:
                events, self._events = self._events, []
        if self._has_new_drops():
            n = self.dropped - self._dropped_reported
            self._dropped_reported += n
            events.append(Event(time.time(), "unexamined", "the linter fell behind", n))
        batch: list[Message] = []
        popleft = q.popleft
        out = 0
        try:
            for _ in range(max_messages):
                m = popleft()
                out += len(m.payload) + len(m.topic) + MESSAGE_OVERHEAD
                batch.append(m)
        except IndexError:
            pass
        self._out_bytes += out
        return batch, events

    def _has_new_drops(self) -> bool:
        return self.dropped != self._dropped_reported

    @property
    def queued(self) -> int:
        return len(self._queue)

    @property
    def is_connected(self) -> bool:
        return self.client.is_connected

    def stop(self) -> None:
        """Disconnect; what is still queued can be taken afterwards."""
        self.client.close()

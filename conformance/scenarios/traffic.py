"""What the unit under test publishes, decoded and kept for a while, so scenarios can wait for it.

The MQTT network thread calls ``add``; scenarios call ``wait_for`` with a predicate and a
deadline (never a fixed sleep). Memory is bounded in count and in bytes, whatever the unit
sends: the newest ``capacity`` messages are kept; each keeps a digest and an
excerpt of its payload, never the payload; its decoded body is kept whole only while it is
small and recent (``BODY_BYTES``, ``FULL_BODIES_BYTES``), else only the top-level fields an
answer is read by (``answer_fields``).
Every wait says what it waits for: ``Waits`` lets the suite show it while it lasts (progress)
and end it when the whole run is out of time (``--max-duration``). Waits read the time and wait
through ``clock`` (``conformance.clock``: the real one, or the test suite's virtual time).
"""

from __future__ import annotations

import dataclasses
import hashlib
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from itertools import islice
from typing import Any

import orjson

from conformance.clock import REAL, Clock
from conformance.message import Message
from conformance.topics import UnitAddress

EXCERPT_BYTES = 256
"""Of each payload, the first bytes are kept (evidence, ``describe``)."""
BODY_BYTES = 64 << 10
"""A payload larger than this keeps only its top-level answer fields, never its whole body."""
FULL_BODIES_BYTES = 4 << 20
"""Payload bytes whose decoded bodies are kept whole at once; past it the oldest are reduced
to their answer fields (a 64 KiB payload can decode to about 1.4 MB of objects)."""
ANSWER_FIELDS = 32
ANSWER_CHARS = 256


@dataclass(frozen=True)
class Entry:
    """One message of the unit: ``subtopic`` relative to the unit (``heartbeat``,
    ``exec/response``, ``sensor/position``), ``body`` the decoded JSON (None if it was not
    JSON; only its answer fields when ``whole`` is False), ``time`` the arrival time in Unix
    seconds, ``seq`` its arrival order; of the payload only ``size`` (bytes), ``digest``
    (BLAKE2b, 16 bytes) and ``excerpt`` (its first ``EXCERPT_BYTES``) are kept."""

    seq: int
    time: float
    subtopic: str
    body: Any
    excerpt: bytes
    size: int = 0
    digest: bytes = b""
    whole: bool = True

    def get(self, key: str, default: Any = None) -> Any:
        """A field of an object body, or ``default`` (the body may be anything)."""
        return self.body.get(key, default) if isinstance(self.body, dict) else default


def answer_fields(body: Any) -> Any:
    """What is kept of a large or old body: its top-level scalars (at most ``ANSWER_FIELDS``,
    strings cut to ``ANSWER_CHARS``), which is what answers are read by (12.1, 12.4:
    response, response-to, status, task-uuid, ...). A body that is not an object keeps None."""
    if not isinstance(body, dict):
        return None
    kept: dict[str, Any] = {}
    for key, value in body.items():
        if len(kept) >= ANSWER_FIELDS:
            break
        if isinstance(value, str):
            kept[key[:ANSWER_CHARS]] = value[:ANSWER_CHARS]
        elif value is None or isinstance(value, (bool, int, float)):
            kept[key[:ANSWER_CHARS]] = value
    return kept


Predicate = Callable[[Entry], bool]
TICK = 1.0
"""Seconds between two progress reports of a wait that lasts."""
STREAK_GAP = 0.5
"""Seconds between two waits that still belong to one busy stretch: a scenario that waits a
second in short waits shows them too (every second says what it waits for)."""
LAG_SLACK = 0.1
"""Seconds the broker may take to deliver the suite's command back before a wait on the unit
is lengthened by as much (``Traffic.command_lag``)."""


class OutOfTime(Exception):
    """The run's time (``--max-duration``) is up; the message says what was being waited for."""


@dataclass(frozen=True)
class Wait:
    """A wait in progress: what for, since when (monotonic seconds) and for how long at most."""

    what: str
    started: float
    timeout: float
    clock: Clock = REAL

    @property
    def elapsed(self) -> float:
        return self.clock.monotonic() - self.started


class Waits:
    """What the suite is waiting for: ``on_tick(wait)`` hears about a wait about once a second
    while it lasts (on the waiting thread); past ``deadline`` (monotonic seconds) a wait raises
    ``OutOfTime``, once: the waits of the teardown that follows run to their own deadlines."""

    def __init__(self, clock: Clock = REAL) -> None:
        self.clock = clock
        self.on_tick: Callable[[Wait], None] | None = None
        self.on_end: Callable[[Wait], None] | None = None
        self.deadline: float | None = None
        self.current: Wait | None = None
        self.expired: str | None = None
        """What was being waited for when the time ran out."""
        self.busy_since: float | None = None
        """When the current stretch of waits began (monotonic seconds)."""
        self.ticked_at = float("-inf")
        self.ended_at = float("-inf")

    def due(self, wait: Wait, now: float) -> bool:
        """Whether a wait in progress is to be shown now: a second into it, or a second into
        a stretch of short waits, and at most once a ``TICK``."""
        busy = self.busy_since if self.busy_since is not None else wait.started
        return now - self.ticked_at >= TICK and now - min(busy, wait.started) >= TICK

    def began(self, wait: Wait) -> None:
        if self.busy_since is None or wait.started - self.ended_at > STREAK_GAP:
            self.busy_since = wait.started

    def check(self, what: str) -> None:
        if self.deadline is not None and self.clock.monotonic() >= self.deadline:
            self.deadline = None
            self.expired = what
            raise OutOfTime(what)


class Traffic:
    """The unit's messages in arrival order, with the latest of each subtopic at hand."""

    def __init__(self, unit: UnitAddress, capacity: int = 20_000, *,
                 tst_operator: str | None = None, clock: Clock = REAL) -> None:
        self.unit = unit
        self.clock = clock
        """Where the suite reads the time and waits (``RealClock`` but in virtual time)."""
        self._base = unit.base + "/"
        self._operator = f"{tst_operator}/tst/" if tst_operator else None
        """An operator's topic base whose tst/response and tst/feedback carry this unit's TST
        answers (14.1): kept under the same subtopics as the unit's own."""
        self._entries: deque[Entry] = deque(maxlen=capacity)
        self._latest: dict[str, Entry] = {}
        self._whole: deque[Entry] = deque()
        """Entries whose body is kept whole, oldest first, and their payload bytes in total."""
        self._whole_bytes = 0
        self._seq = 0
        self._cond = threading.Condition()
        self.waits = Waits(clock)
        self.command_lag = 0.0
        """How late the broker delivered the suite's latest command back to it (its echo),
        in seconds: the unit took it as late (``wait_for``)."""

    def add(self, message: Message) -> Entry | None:
        """Keep a message if it is the unit's; return its entry."""
        if message.topic.startswith(self._base):
            subtopic = message.topic[len(self._base):]
        elif self._operator is not None and message.topic.startswith(self._operator):
            subtopic = message.topic[len(self._operator) - 4:]  # tst/...
        else:
            return None
        payload = message.payload
        try:
            body = orjson.loads(payload)
        except (orjson.JSONDecodeError, TypeError, ValueError):
            body = None
        size = len(payload)
        whole = size <= BODY_BYTES
        if not whole:
            body = answer_fields(body)
        view = memoryview(payload) if isinstance(payload, bytes) else memoryview(b"")
        digest = hashlib.blake2b(view, digest_size=16).digest()
        with self._cond:
            self._seq += 1
            entry = Entry(self._seq, message.time, subtopic, body,
                          bytes(view[:EXCERPT_BYTES]), size, digest, whole)
            self._entries.append(entry)
            self._latest[subtopic] = entry
            if whole:
                self._whole.append(entry)
                self._whole_bytes += size
                self._reduce_oldest()
            self._cond.notify_all()
        return entry

    def _reduce_oldest(self) -> None:
        """Past ``FULL_BODIES_BYTES`` of whole bodies, the oldest keep only their answer
        fields (in the store and as the latest of their subtopic); under the lock."""
        while self._whole_bytes > FULL_BODIES_BYTES and len(self._whole) > 1:
            old = self._whole.popleft()
            self._whole_bytes -= old.size
            first = self._entries[0].seq
            if old.seq < first:
                continue  # already out of the store
            reduced = dataclasses.replace(old, body=answer_fields(old.body), whole=False)
            self._entries[old.seq - first] = reduced
            if self._latest.get(old.subtopic) is old:
                self._latest[old.subtopic] = reduced

    def mark(self) -> int:
        """The sequence number of the newest message: wait for what comes after it."""
        with self._cond:
            return self._seq

    def latest(self, subtopic: str) -> Entry | None:
        with self._cond:
            return self._latest.get(subtopic)

    def since(self, mark: int, subtopic: str | None = None) -> list[Entry]:
        """Every kept message after ``mark`` (optionally of one subtopic), oldest first."""
        with self._cond:
            return [e for e in self._entries
                    if e.seq > mark and (subtopic is None or e.subtopic == subtopic)]

    def subtopics(self) -> set[str]:
        with self._cond:
            return set(self._latest)

    def wait_for(self, predicate: Predicate, timeout: float, *, after: int = 0,
                 subtopic: str | None = None, what: str = "") -> Entry | None:
        """The first message after ``after`` (a ``mark``) that satisfies ``predicate``, waiting
        up to ``timeout`` seconds for it to arrive; None when the deadline passes. ``what``
        says what is awaited, for a person (``the response to ping``). Raises ``OutOfTime``
        when the run's own deadline passes first."""
        waits = self.waits
        what = what or (f"{subtopic} of {self.unit.name}" if subtopic else "the unit")
        waits.check(what)
        clock = self.clock
        wait = Wait(what, clock.monotonic(), max(0.0, timeout), clock)
        deadline = wait.started + wait.timeout
        checked = after
        lagged = False
        waits.began(wait)
        try:
            with self._cond:
                waits.current = wait
                while True:
                    first = self._entries[0].seq if self._entries else checked + 1
                    for entry in islice(self._entries, max(0, checked + 1 - first), None):
                        checked = entry.seq
                        if (subtopic is None or entry.subtopic == subtopic) \
                                and predicate(entry):
                            return entry
                    now = clock.monotonic()
                    left = deadline - now
                    if left <= 0:
                        late = 0.0 if lagged else min(self.command_lag, wait.timeout)
                        lagged = True
                        if late < LAG_SLACK:
                            return None
                        # The broker delivered the suite's command late, so the unit took it
                        # late: what it sends in answer is due as much later (lint measures
                        # from the command's arrival too). Once, at most the wait's budget.
                        deadline += late
                        wait = waits.current = dataclasses.replace(
                            wait, timeout=wait.timeout + late)
                        continue
                    if waits.due(wait, now):
                        waits.ticked_at = now
                        if waits.on_tick is not None:
                            waits.on_tick(wait)
                        waits.check(what)
                    stop = waits.deadline
                    clock.wait(self._cond,
                               min(left, TICK, max(0.0, stop - now) if stop else TICK))
                    if stop is not None and clock.monotonic() >= stop:
                        waits.check(what)
        finally:
            waits.current = None
            waits.ended_at = clock.monotonic()
            if waits.on_end is not None:
                waits.on_end(wait)

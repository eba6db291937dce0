"""The time a certification waits in: the real one, or a simulated one the tests' matrices run in.

Every wait of the suite (``Traffic.wait_for``, the commander, the observation, the session)
reads ``now`` and waits through a ``Clock``. ``RealClock`` is the wall clock and a
``threading.Condition``'s wait. ``VirtualClock`` is a discrete-event scheduler on one thread:
what the simulated unit and the in-memory broker (``conformance.sim.virtual``) will do is
queued at a time, and when the suite waits, time jumps to the next queued event and runs it;
nothing happens between events, so a certification of a unit at 2 Hz that lasts 100 s of its
time takes only the CPU its messages cost.
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from collections.abc import Callable
from typing import Protocol


class Clock(Protocol):
    """Where a certification reads the time and waits."""

    def now(self) -> float:
        """Unix seconds (the time of a message's arrival, of an event)."""
        ...

    def monotonic(self) -> float:
        """Seconds that never go back (deadlines)."""
        ...

    def wait(self, condition: threading.Condition, timeout: float) -> None:
        """Wait, holding ``condition``, until it is notified or ``timeout`` seconds pass (as
        ``Condition.wait``: the caller checks again what it waits for)."""
        ...


class RealClock:
    """The wall clock."""

    def now(self) -> float:
        return time.time()

    def monotonic(self) -> float:
        return time.monotonic()

    def wait(self, condition: threading.Condition, timeout: float) -> None:
        condition.wait(max(0.0, timeout))


REAL = RealClock()

EVENTS_PER_WAIT = 10_000
"""Events one wait runs at most before it returns (bounded: a handler that keeps queuing events
at the same instant cannot hold the waiter forever)."""


class VirtualClock:
    """Simulated time on one thread: ``at(when, action)`` queues an action; ``wait`` runs the
    queued actions up to its deadline, moving ``now`` to each one's time, and returns after
    the first instant that ran any (the waiter checks again) or at its deadline."""

    def __init__(self, start: float | None = None) -> None:
        self._now = time.time() if start is None else start
        self._queue: list[tuple[float, int, Callable[[], None]]] = []
        self._order = itertools.count()
        self._running = False

    def now(self) -> float:
        return self._now

    monotonic = now

    def at(self, when: float, action: Callable[[], None]) -> None:
        """Run ``action`` at ``when`` (at once if that has passed: on the next wait)."""
        heapq.heappush(self._queue, (max(when, self._now), next(self._order), action))

    def next_event(self) -> float | None:
        return self._queue[0][0] if self._queue else None

    def wait(self, condition: threading.Condition | None, timeout: float) -> None:
        deadline = self._now + max(0.0, timeout)
        if self._running or not self._queue or self._queue[0][0] > deadline:
            # Nothing happens before the deadline (or an action itself waits: it cannot run
            # the others under it, so its wait simply passes).
            self._now = max(self._now, deadline)
            return
        self._now = instant = self._queue[0][0]
        self._running = True
        try:
            for _ in range(EVENTS_PER_WAIT):
                if not self._queue or self._queue[0][0] > instant:
                    break
                _, _, action = heapq.heappop(self._queue)
                action()
        finally:
            self._running = False

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass, running what falls due meanwhile."""
        end = self._now + max(0.0, seconds)
        while self._now < end:
            self.wait(None, end - self._now)

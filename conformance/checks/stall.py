"""A broker that stalls (frozen, overloaded, a link that holds traffic) is the broker's fault,
never the unit's (docs/ARCHITECTURE.md 'Safety'): found from the traffic and marked as a gap of
the observer, so that rates, silences, uuid changes and deadlines over it are not judged.

A stall shows as a silence of every topic of every unit followed by a burst: what the broker
held arrives within milliseconds. It is told from a unit's own silence by either of:
- a periodic topic (heartbeat, an info message, a sensor) that arrives twice in the burst, as
  no unit publishes a periodic message twice within a few ms after a silence of seconds
  unless something held the first (stamps, where the unit has them, must agree: two stamps
  as close as their arrivals were sent together, the unit's burst, not the broker's);
- a message whose stamp lags its arrival by far more than that topic's stamps did before
  (the unit published it on time; the broker delivered it late). The lag is compared per
  topic, so a unit whose clock is off by a constant (MSG-005's) is not taken for a stall.

The gap runs from the last arrival before the silence to the end of the burst. Memory is
bounded: the latest message of at most MAX_TOPICS periodic topics, the topics of one
burst.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from conformance.topics import TopicKind

if TYPE_CHECKING:
    from conformance.checks.base import CheckContext

STALL_SILENCE = 2.0
"""Seconds every topic must have been silent before a burst reads as a stall (decision: twice
the 1 Hz period of most units; a fleet is never silent that long while the broker works)."""
BURST_SPACING = 0.05
"""Seconds between consecutive arrivals of a burst (docs/FIELD-NOTES.md 'Timing jitter': loaded
jitter 1-7 ms, single
outliers to 47 ms)."""
LAG_JUMP = STALL_SILENCE / 2
"""Seconds by which a stamp's lag must exceed that topic's previous lag to be a held message."""
STAMP_APART = 0.1
"""Seconds two stamps of one topic must be apart, beyond their arrivals', to have been held."""
STAMP_PLAUSIBLE = 86_400.0
"""A stamp further than a day from its arrival is not seconds since the epoch (MSG-005's):
its differences say nothing."""
MAX_TOPICS = 4096
HB, SENSOR, SI = TopicKind.HEARTBEAT, TopicKind.SENSOR, TopicKind.SENSOR_INFO
DEI, TEI = TopicKind.DIRECT_EXECUTION_INFO, TopicKind.TST_EXECUTION_INFO


def stamp_of(message: Any, t: float) -> float | None:
    """The message's ``stamp`` (5.1: "time.time()", Unix seconds as a double) when it reads as
    one near its arrival ``t``, else None. A whole number of seconds is not used: its
    differences are off by up to a second."""
    stamp = message.get("stamp") if type(message) is dict else None
    if type(stamp) is float and abs(stamp - t) < STAMP_PLAUSIBLE and stamp != int(stamp):
        return stamp
    return None


class StallWatch:
    """Finds stalls of the broker in the arrival times of every message the observer sees.
    ``feed`` runs on every message of a fleet: the usual case (no silence of everything
    before it) costs a comparison and a dict store."""

    __slots__ = ("ctx", "last", "silence_from", "burst", "stalled", "previous", "found", "count")

    def __init__(self, ctx: CheckContext) -> None:
        self.ctx = ctx
        """Where the stalls found are marked as gaps (and ``quiet`` is kept)."""
        self.last: float | None = None
        self.silence_from: float | None = None
        """The last arrival before the silence that opened the current burst (None: no
        burst after a silence is going on)."""
        self.burst: dict[str, tuple[float, float | None]] = {}
        """Periodic topics of the current burst: (arrival, stamp)."""
        self.stalled = False
        self.previous: dict[str, tuple[float, Any]] = {}
        """Per periodic topic, its latest message: (arrival, decoded body)."""
        self.found: list[tuple[float, float]] = []
        """The stalls found, (start, end) in Unix seconds (the latest 16)."""
        self.count = 0
        """How many stalls were found."""

    def feed(self, t: float, topic: str, kind: TopicKind, message: Any) -> None:
        """One message arrived at ``t``; a stall found is added to ``ctx``'s gaps at once,
        before the checks judge this message."""
        last = self.last
        periodic = kind is HB or kind is SENSOR or kind is SI or kind is DEI or kind is TEI
        before = None
        if periodic:
            previous = self.previous
            before = previous.get(topic)
            previous[topic] = (t, message)
            if len(previous) > MAX_TOPICS:  # bounded: start again (a lag is then unknown)
                previous.clear()
        if last is not None and t - last <= BURST_SPACING and self.silence_from is None:
            if t > last:  # the usual case: traffic flows
                self.last = t
            return
        self._after_silence(t, topic, periodic, message, before)

    def _after_silence(self, t: float, topic: str, periodic: bool, message: Any,
                       before: tuple[float, Any] | None) -> None:
        """A message after a silence of every topic, or in the burst that followed one."""
        ctx, last = self.ctx, self.last
        if last is None or t > last:
            self.last = t
        if last is None:
            return
        if t - last > BURST_SPACING:
            if t - last < STALL_SILENCE:
                self.silence_from = ctx.quiet = None
                return
            self.silence_from, self.stalled = last, False
            ctx.quiet = last
            self.burst = {}
        silence_from = self.silence_from
        assert silence_from is not None
        stamp = stamp_of(message, t) if periodic else None
        if not self.stalled:
            self.stalled = periodic and (self._held(t, stamp, before)
                                         or self._repeated(topic, t, stamp))
            if not self.stalled:
                return
            self.found.append((silence_from, t))
            del self.found[:-16]
            self.count += 1
        # 1 us after the last arrival before it: an interval ending there is not the stall's.
        ctx.add_gap(silence_from + 1e-6, t)
        self.found[-1] = (self.found[-1][0], t)

    @staticmethod
    def _held(t: float, stamp: float | None, before: tuple[float, Any] | None) -> bool:
        """Whether the message's stamp lags its arrival by LAG_JUMP more than the topic's
        previous message's did: published on time, delivered late."""
        if stamp is None or before is None:
            return False
        stamp0 = stamp_of(before[1], before[0])
        return stamp0 is not None and (t - stamp) - (before[0] - stamp0) >= LAG_JUMP

    def _repeated(self, topic: str, t: float, stamp: float | None) -> bool:
        """Whether ``topic`` came already in this burst, published apart (by the stamps)."""
        seen = self.burst.get(topic)
        if seen is None:
            if len(self.burst) < MAX_TOPICS:
                self.burst[topic] = (t, stamp)
            return False
        t0, stamp0 = seen
        return stamp is None or stamp0 is None or stamp - stamp0 >= (t - t0) + STAMP_APART

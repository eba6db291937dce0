"""What an observer sees, whatever the source (live MQTT, a recording, a bag): ``Message``, and
``Gap``, a time it could not see. Kept apart from ``client`` so that the checks, the linter and
the recording formats never import paho."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple


class Message(NamedTuple):
    """One received message. ``time`` is the arrival time in Unix seconds, taken by paho on
    receipt (docs/FIELD-NOTES.md 'MQTT on loopback': a time taken in the callback lags by up to 2
    ms), or the recorded one.

    Immutable. A NamedTuple, not a frozen dataclass: it is made for every message, and a
    frozen dataclass costs 2-3 times as much to create (bench/bench_lint.py)."""

    time: float
    topic: str
    payload: bytes
    qos: int = 0
    retain: bool = False


@dataclass(frozen=True)
class Gap:
    """A time the observer was not connected: from ``start`` to ``end`` (Unix seconds; None
    while it lasts), and why."""

    start: float
    end: float | None
    reason: str = ""

    @property
    def duration(self) -> float | None:
        return None if self.end is None else self.end - self.start

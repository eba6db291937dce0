"""``Message``: one message as observed, whatever the source (live MQTT, a recording, a bag).

Kept apart from ``client`` so that the checks, the linter and the recording formats never
import paho."""

from __future__ import annotations

from typing import NamedTuple


class Message(NamedTuple):
    """One received message. ``time`` is the arrival time in Unix seconds, taken by paho on
    receipt (FIELD-NOTES: timing inside the callback lags by up to 2 ms), or the recorded one.

    Immutable. A NamedTuple, not a frozen dataclass: it is made for every message, and a
    frozen dataclass costs 2-3 times as much to create (bench/bench_lint.py)."""

    time: float
    topic: str
    payload: bytes
    qos: int = 0
    retain: bool = False

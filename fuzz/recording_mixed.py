"""Fuzz target: the raw bytes of a recording, seeded with every format and mixes of them
(JSON Lines, ``mosquitto_sub -F %j``, ``-F %J``, ``-v``), read by ``RecordingReader`` and judged
by the ``Monitor`` (``lint --from``): what a line-level mutation of any capture does.

Invariant (``fuzz.recorded``): the reader never raises and yields only messages and events
within the bounds; a bad line is a one-line problem; payloads stay proportional to the input;
the Monitor judges every message without raising; time proportional to the input.
"""

from __future__ import annotations

from fuzz.recorded import check


def prepare() -> None:
    """Nothing to build: the input is the recording."""


def test_one_input(data: bytes) -> None:
    check(data)

"""Fuzz target: a recording in mosquitto_sub -F %J output (the payload embedded as a JSON value; an empty line for one that is not JSON), built from fuzzed fields, read by
``RecordingReader`` and judged by the ``Monitor`` (``lint --from``).

Invariant (``fuzz.recorded``): the reader never raises and yields only messages and events
within the bounds; a bad line is a one-line problem; payloads stay proportional to the input;
the Monitor judges every message without raising; time proportional to the input.
"""

from __future__ import annotations

import atheris

from fuzz.recorded import check, lines, mosquitto_jj_line


def prepare() -> None:
    """Nothing to build: the recording is made from the input."""


def test_one_input(data: bytes) -> None:
    check(lines(atheris.FuzzedDataProvider(data), mosquitto_jj_line))

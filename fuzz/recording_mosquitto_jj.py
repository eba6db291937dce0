"""Fuzz target: a recording in mosquitto_sub -F %J output (the payload embedded as a JSON value; an empty line for one that is not JSON), built from fuzzed fields, read by
``RecordingReader`` and judged by the ``Monitor`` (``lint --from``).

Invariant (``fuzz.recorded``): the reader never raises and yields only messages and events
within the bounds; a bad line is a one-line problem; payloads stay proportional to the input;
the Monitor judges every message without raising; time proportional to the input.
"""

from __future__ import annotations

from fuzz.recorded import mosquitto_jj_line, target

prepare, test_one_input = target(mosquitto_jj_line)

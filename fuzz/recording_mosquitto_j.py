"""Fuzz target: a recording in mosquitto_sub -F %j output (tst, topic, payloadlen, the payload copied byte for byte), built from fuzzed fields, read by
``RecordingReader`` and judged by the ``Monitor`` (``lint --from``).

Invariant (``fuzz.recorded``): the reader never raises and yields only messages and events
within the bounds; a bad line is a one-line problem; payloads stay proportional to the input;
the Monitor judges every message without raising; time proportional to the input.
"""

from __future__ import annotations

from fuzz.recorded import mosquitto_j_line, target

prepare, test_one_input = target(mosquitto_j_line)

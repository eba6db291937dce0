"""Fuzz target: a recording in JSON Lines as 'waraps-conformance record' writes (ts, topic, payload or payload_b64, qos, retain; events), built from fuzzed fields, read by
``RecordingReader`` and judged by the ``Monitor`` (``lint --from``).

Invariant (``fuzz.recorded``): the reader never raises and yields only messages and events
within the bounds; a bad line is a one-line problem; payloads stay proportional to the input;
the Monitor judges every message without raising; time proportional to the input.
"""

from __future__ import annotations

from fuzz.recorded import jsonl_line, target

prepare, test_one_input = target(jsonl_line)

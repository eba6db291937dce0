"""Fuzz target: what ``waraps-conformance profile --unit`` reads off the wire, the drafter's
feed (``profile_draft.Observed.feed``), and the draft written from it (``draft``,
``problems``).

Input: messages separated by NUL bytes, each ``TOPIC-SUFFIX SPACE PAYLOAD`` (the suffix under
the observed unit: ``heartbeat``, ``sensor_info``, ``direct_execution_info``, ``sensor/...``).

Invariant: feeding never raises (a payload it cannot read within the bounds is no
declaration); the draft is YAML the profile loader reads back (``profile.from_dict``) without
a key of the unit's making, and the problems are lines of bounded length. Time proportional
to the input.
"""

from __future__ import annotations

import yaml

from conformance import profile
from conformance.message import Message
from conformance.profile_draft import Observed, draft, problems
from conformance.topics import UnitAddress
from fuzz.harness import Broken, within_time

UNIT = UnitAddress.parse("waraps/unit/air/simulation/dji0")
KEYS = {"extends", "name", "levels", "sensors", "tasks", "motion-tasks", "safe-radius",
        "response-timeout", "feedback-timeout", "reboot-timeout", "rate-tolerance",
        "alive-timeout"}
"""The keys the drafter writes (never one of the unit's making)."""


def prepare() -> None:
    """Nothing to build."""


def test_one_input(data: bytes) -> None:
    with within_time(len(data)):
        seen = Observed(UNIT, 10.0)
        for i, part in enumerate(data.split(b"\x00")[:200]):
            suffix, _, payload = part.partition(b" ")
            topic = f"{UNIT.base}/{suffix.decode('utf-8', 'replace')}"
            seen.feed(Message(1_763_700_000.0 + i * 0.5, topic, payload))
        text = draft(seen)
        for line in problems(seen):
            if "\n" in line or len(line) > 2000:
                raise Broken(f"a problem that is not one bounded line: {line[:200]!r}")
    loaded = yaml.safe_load(text)
    if not isinstance(loaded, dict) or not set(loaded) <= KEYS:
        raise Broken(f"the draft has keys {sorted(map(str, loaded or {}))[:10]}")
    profile.from_dict(loaded, "<draft>")

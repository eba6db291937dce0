"""Fuzz target: ``validate``'s input: a topic and a payload of at most the bytes ``validate``
reads, validated (``Validator.validate``, or ``validate_tst`` for ``--tst``) and explained as
text and as JSON (``conformance.explanation``, what ``cli/validate.py`` prints).

Invariant: the validator never raises on any payload (every problem is a violation of the
rule that names it, MSG-001..MSG-004); the text and the JSON are written without raising and
stay proportional to the input; time proportional to the input.
"""

from __future__ import annotations

import json

import atheris

from conformance.explanation import overall_verdict, render, to_dict, validate_tst
from conformance.profile import Profile
from conformance.validator import Validator
from fuzz.harness import proportional, within_time
from fuzz.recorded import T0, TOPICS

PROFILE = Profile()
VALIDATOR = Validator(PROFILE)


def prepare() -> None:
    """Compile the schemas once (instrumented) before fuzzing."""
    VALIDATOR.validate(TOPICS[0], b"{}", T0)


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    tst = fdp.ConsumeProbability() < 0.2
    topic = (fdp.PickValueInList(TOPICS) if fdp.ConsumeBool()
             else fdp.ConsumeUnicode(fdp.ConsumeIntInRange(0, 120)))
    payload = fdp.ConsumeBytes(fdp.remaining_bytes())
    with within_time(len(data)):
        if tst:
            validation = validate_tst(VALIDATOR, payload)
        else:
            validation = VALIDATOR.validate(topic, payload, T0)
        text = render(validation, PROFILE)
        out = json.dumps(to_dict(validation, PROFILE))
        overall_verdict(validation, PROFILE)
        proportional(len(text) + len(out), len(data), what="the explanation")

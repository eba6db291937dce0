"""What the validator works out once per topic (its plan) changes nothing: a validator that has
seen the topic before decides exactly what a fresh one decides, and a payload given as text
what the same payload given as bytes: the same kind, message and violations."""

from __future__ import annotations

import orjson
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_spec_hypothesis import TOPIC_OF, UNIT, message_strategy

from conformance.validator import Validator

T0 = 1_763_700_000.0
SUBTOPICS = [*TOPIC_OF.values(), "sensor/speed", "sensor/heading", "sensor/camera_url",
             "sensor/battery", "sensor.info", "foo/bar"]
JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-2**63, 2**64 - 1) | st.floats(allow_nan=False,
                                                                         allow_infinity=False)
    | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["name", "stamp", "rate", "agent-uuid", "levels", "type", "com-uuid",
                         "response-to", "status", "command", "task", "x", ""]) | st.text(max_size=5),
        inner, max_size=6),
    max_leaves=12)


def _same(topic: str, payload: bytes, t: float) -> None:
    seen = Validator()
    seen.validate(topic, b"{}", t)  # the topic's plan is made and kept
    fresh = Validator().validate(topic, payload, t)
    assert seen.validate(topic, payload, t) == fresh, (topic, payload)
    text = payload.decode("utf-8", "surrogateescape")
    if text.encode("utf-8", "surrogatepass") == payload:  # a str that says the same bytes
        assert Validator().validate(topic, text, t) == fresh, (topic, payload)


@settings(database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(kind=st.sampled_from(sorted(TOPIC_OF)), data=st.data(), late=st.sampled_from([0, 45, 4e9]))
def test_schema_messages_and_their_variants(kind: str, data: st.DataObject, late: float) -> None:
    message = data.draw(message_strategy(kind))
    if isinstance(message, dict) and data.draw(st.booleans()):
        key = data.draw(st.sampled_from(sorted(message) or [""]))
        message = {**message, key: data.draw(JSON)}
    _same(f"{UNIT}/{TOPIC_OF[kind]}", orjson.dumps(message), T0 + late)


@settings(database=None)
@given(sub=st.sampled_from(SUBTOPICS), value=JSON, stamp=st.booleans())
def test_any_json_on_any_topic(sub: str, value: object, stamp: bool) -> None:
    if stamp and isinstance(value, dict):
        value = {**value, "stamp": T0 + 100, "name": "dji0"}
    _same(f"{UNIT}/{sub}", orjson.dumps(value), T0)
    _same(f"/Waraps/unit/air/Simulation/dji 0/{sub}", orjson.dumps(value), T0)


@settings(database=None)
@given(raw=st.binary(max_size=40) | st.just(b"[" * 70 + b"]" * 70) | st.just(b'{"a": NaN}'))
def test_payloads_that_are_not_well_formed(raw: bytes) -> None:
    for sub in ("heartbeat", "exec/command", "sensor/speed"):
        _same(f"{UNIT}/{sub}", raw, T0)

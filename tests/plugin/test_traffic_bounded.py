"""The suite's message store (``scenarios/traffic.py``) stays bounded in bytes whatever the
unit sends: a digest and an excerpt per message, whole bodies only while small
and recent, and the answers scenarios wait for still readable."""

from __future__ import annotations

import hashlib
import sys

import orjson

from conformance.message import Message
from conformance.scenarios import traffic as traffic_module
from conformance.scenarios.traffic import BODY_BYTES, EXCERPT_BYTES, Traffic
from conformance.topics import UnitAddress

UNIT = UnitAddress.parse("waraps/unit/air/simulation/dji0")
T0 = 1_700_000_000.0


def _kept_bytes(entry) -> int:
    """Bytes an entry holds of the wire: its excerpt and its body's strings."""
    size = len(entry.excerpt)
    if isinstance(entry.body, dict):
        size += sum(len(k) + (len(v) if isinstance(v, str) else 8)
                    for k, v in entry.body.items())
    elif isinstance(entry.body, str):
        size += len(entry.body)
    return size


def test_a_5_mib_payload_keeps_a_digest_an_excerpt_and_its_answer_fields():
    store = Traffic(UNIT)
    huge = "A" * (5 << 20)
    payload = orjson.dumps({"response": "ok", "response-to": "c1", "image": huge})
    entry = store.add(Message(T0, UNIT.topic("exec/response"), payload))
    assert entry is not None and not entry.whole
    assert entry.size == len(payload)
    assert entry.digest == hashlib.blake2b(payload, digest_size=16).digest()
    assert entry.excerpt == payload[:EXCERPT_BYTES]
    assert entry.get("response") == "ok" and entry.get("response-to") == "c1"
    assert len(entry.get("image")) <= traffic_module.ANSWER_CHARS  # cut, not kept whole
    assert _kept_bytes(entry) < 4096
    # A scenario waiting for this answer still finds it.
    found = store.wait_for(lambda e: e.get("response-to") == "c1", 0.0,
                           subtopic="exec/response")
    assert found is entry


def test_non_json_payloads_keep_no_body():
    store = Traffic(UNIT)
    entry = store.add(Message(T0, UNIT.topic("sensor/camera"), b"\xff" * (BODY_BYTES + 1)))
    assert entry.body is None and len(entry.excerpt) == EXCERPT_BYTES


def test_the_store_is_bounded_in_bytes_not_only_in_count(monkeypatch):
    monkeypatch.setattr(traffic_module, "FULL_BODIES_BYTES", 1 << 20)
    store = Traffic(UNIT, capacity=5000)
    filler = "x" * (BODY_BYTES - 200)  # just under the whole-body bound: kept whole at first
    for i in range(400):
        store.add(Message(T0 + i, UNIT.topic("heartbeat"), orjson.dumps(
            {"agent-uuid": "u1", "rate": 1.0, "stamp": T0 + i, "filler": filler})))
        store.add(Message(T0 + i, UNIT.topic("sensor/camera"),
                          orjson.dumps({"image": "B" * (5 << 20)})))
    entries = store.since(0)
    assert len(entries) == 800  # every message is still there, in order
    whole = [e for e in entries if e.whole]
    assert 0 < sum(e.size for e in whole) <= 1 << 20
    assert whole[-1] is entries[-2]  # the newest stay whole
    assert sum(_kept_bytes(e) for e in entries if not e.whole) < 800 * 2 * EXCERPT_BYTES \
        + 800 * traffic_module.ANSWER_CHARS * 4
    # What scenarios read of reduced entries is still there.
    oldest = entries[0]
    assert not oldest.whole and oldest.get("agent-uuid") == "u1" and oldest.get("rate") == 1.0
    # The latest heartbeat is whole (scenarios read its levels, rates and uuid).
    latest = store.latest("heartbeat")
    assert latest is not None and latest.whole and latest.get("filler") == filler


def test_memory_stays_flat_for_a_unit_publishing_5_mib_payloads():
    """RSS-free: the objects the store holds, summed, stay under a bound however many arrive
    (the RSS curve of a real certification is bench/bench_memory.py's)."""
    store = Traffic(UNIT)
    huge = orjson.dumps({"image": "C" * (5 << 20), "stamp": T0})
    for i in range(200):  # 1 GiB sent
        store.add(Message(T0 + i, UNIT.topic("sensor/camera"), huge))
    held = sum(sys.getsizeof(e.excerpt) + sys.getsizeof(e.body) for e in store.since(0))
    assert held < 200 * 2048

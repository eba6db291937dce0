"""The suite's watch on a unit's life (``conformance/suite/observation.py``), in virtual time."""

from __future__ import annotations

from contextlib import nullcontext
from types import SimpleNamespace

import orjson

from conformance.checks import Monitor
from conformance.clock import VirtualClock
from conformance.message import Message
from conformance.scenarios import Traffic
from conformance.suite.observation import Observation
from conformance.topics import UnitAddress

UNIT = UnitAddress.parse("waraps/unit/ground/simulation/slow0")


def test_a_unit_far_slower_than_it_declares_is_not_dead_before_its_next_heartbeat() -> None:
    """The drone operator (found certifying it): declares 5 Hz, heartbeats every 5.002 s.
    Before two intervals give its own period, the wait for its next heartbeat was the
    declared one's (10 periods or the 5 s response deadline), 2 ms short: 'fell silent and
    did not come back (HB-012)', and the rules after it could-not-test. Twice the longest
    interval it has shown is waited for too."""
    clock = VirtualClock(start=1000.0)
    traffic = Traffic(UNIT, clock=clock)

    def beat(t: float) -> None:
        traffic.add(Message(t, UNIT.topic("heartbeat"), orjson.dumps(
            {"agent-uuid": "a1", "rate": 5.0, "type": "HeartBeat", "stamp": t}), 0, False))

    for t in (1000.0, 1005.002, 1010.004):
        clock.at(t, lambda t=t: beat(t))
    clock.sleep(6.002)  # 1 s after its second heartbeat: 5 declared periods, past HB-012's 3
    context = SimpleNamespace(unit=UNIT, traffic=traffic, notes={},
                              timing=SimpleNamespace(scale=1.0, response=5.0),
                              rate_of=lambda kind: 5.0 if kind == "heartbeat" else None)
    watch = Observation(context, Monitor(), nullcontext(), observe=0.0)  # type: ignore[arg-type]
    assert watch.unit_died() == ""
    assert clock.now() < 1010.1  # it returned as the heartbeat came, not at its deadline
    clock.sleep(30.0)  # then silent for good: dead, within twice its longest interval
    assert "fell silent at" in watch.unit_died()

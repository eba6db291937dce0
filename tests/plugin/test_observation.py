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


def test_a_wait_is_lengthened_once_by_as_much_as_the_broker_delivered_the_command_late() -> None:
    """``Traffic.command_lag`` (the echo of the suite's last command, ``Connection``): an
    answer 1.8 s after the wait began, the command 1.0 s late, a 1.5 s wait: found; the same
    answer with the command in time, or 3 s later with the lag, is not (once, at most the
    wait's own budget)."""
    def answer_after(seconds: float, lag: float) -> bool:
        clock = VirtualClock(start=1000.0)
        traffic = Traffic(UNIT, clock=clock)
        traffic.command_lag = lag
        clock.at(1000.0 + seconds, lambda: traffic.add(Message(
            clock.now(), UNIT.topic("exec/response"), b'{"response-to": "c1"}', 0, False)))
        found = traffic.wait_for(lambda e: e.get("response-to") == "c1", 1.5,
                                 subtopic="exec/response")
        return found is not None

    assert answer_after(1.8, lag=1.0)
    assert not answer_after(1.8, lag=0.05)  # under LAG_SLACK: the deadline is the wait's own
    assert not answer_after(3.1, lag=1.0)
    assert not answer_after(3.1, lag=5.0)  # lengthened by the wait's budget at most

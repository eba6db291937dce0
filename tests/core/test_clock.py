"""The clocks a certification waits in (``conformance.clock``): the virtual one jumps to its
next event when the suite waits, and ``Traffic.wait_for`` waits in whichever it is given."""

from __future__ import annotations

import threading

from conformance.clock import REAL, VirtualClock
from conformance.message import Message
from conformance.scenarios import Traffic
from conformance.topics import UnitAddress

UNIT = UnitAddress.parse("waraps/unit/air/simulation/dji0")


def test_a_virtual_wait_jumps_to_the_next_event_and_runs_it() -> None:
    clock = VirtualClock(start=1000.0)
    ran: list[float] = []
    clock.at(1030.0, lambda: ran.append(clock.now()))
    clock.at(1030.0, lambda: ran.append(clock.now()))  # the same instant: both run
    clock.at(1050.0, lambda: ran.append(clock.now()))
    clock.wait(threading.Condition(), 60.0)
    assert ran == [1030.0, 1030.0] and clock.now() == 1030.0
    clock.wait(threading.Condition(), 5.0)  # nothing due within 5 s: the deadline
    assert ran == [1030.0, 1030.0] and clock.now() == 1035.0
    clock.sleep(100.0)
    assert ran == [1030.0, 1030.0, 1050.0] and clock.now() == 1135.0


def test_an_event_in_the_past_runs_at_the_next_wait_without_going_back() -> None:
    clock = VirtualClock(start=10.0)
    ran: list[float] = []
    clock.at(5.0, lambda: ran.append(clock.now()))
    clock.wait(None, 0.0)
    assert ran == [10.0] and clock.monotonic() == 10.0


def test_traffic_waits_in_virtual_time() -> None:
    clock = VirtualClock(start=2000.0)
    traffic = Traffic(UNIT, clock=clock)
    topic = UNIT.topic("exec/response")
    clock.at(2040.0, lambda: traffic.add(Message(clock.now(), topic, b'{"response": "ok"}')))
    # 40 s of the unit's time pass at once; a wait with a shorter deadline gives up at it.
    assert traffic.wait_for(lambda e: True, 30.0, subtopic="exec/response") is None
    assert clock.now() == 2030.0
    entry = traffic.wait_for(lambda e: True, 30.0, subtopic="exec/response")
    assert entry is not None and entry.time == 2040.0 and clock.now() == 2040.0


def test_the_real_clock_is_the_default() -> None:
    assert Traffic(UNIT).clock is REAL

"""Hostile commands never crash the reference unit; where a com-uuid can be read it answers
'failed' with a fail-reason; its memory stays bounded under a flood."""

from __future__ import annotations

import threading
import time
import uuid

import pytest

from conformance.client import Message
from conformance.sim import SimUnit, memory
from conformance.sim.runtime import INBOX_BYTES, Runtime
from conformance.topics import UnitAddress


def hostile(com: str) -> dict[str, bytes]:
    """Commands as a careless or hostile commander sends them (each carries ``com`` where
    the form allows it)."""
    c = com.encode()
    return {
        "non-utf8": b'{"com-uuid": "' + c + b'", "command": "ping\xff\xfe"}',
        "invalid-json (12.2.2's example)": b'{"com-uuid": "' + c + b'", "command": '
                                           b'"signal-task", signal: $abort}',
        "nan": b'{"com-uuid": "' + c + b'", "command": "ping", "x": NaN}',
        "10MB": b'{"com-uuid": "' + c + b'", "command": "ping", "pad": "' + b"x" * 10_000_000
                + b'"}',
        "missing-command": b'{"com-uuid": "' + c + b'"}',
        "unknown-command": b'{"com-uuid": "' + c + b'", "command": "self-destruct"}',
        "signal-executor (ERR-007)": b'{"com-uuid": "' + c + b'", "command": "signal-executor",'
                                     b' "signal": "battery-is-charged", "uuid": "x"}',
        "start-task-no-task": b'{"com-uuid": "' + c + b'", "command": "start-task"}',
        "start-task-params-array": b'{"com-uuid": "' + c + b'", "command": "start-task", '
                                   b'"task": {"name": "move-to", "params": [1, 2]}}',
        "signal-no-signal": b'{"com-uuid": "' + c + b'", "command": "signal-task"}',
        "query-no-task-uuid": b'{"com-uuid": "' + c + b'", "command": "query-status"}',
        "query-task-uuid-number": b'{"com-uuid": "' + c + b'", "command": "query-status", '
                                  b'"task-uuid": 42}',
        "params-wrong-types": b'{"com-uuid": "' + c + b'", "command": "start-task", "task": '
                              b'{"name": "move-to", "params": {"waypoint": "home", "speed": 7}}}',
    }


UNREADABLE = {
    "deep-100000": b"[" * 100_000 + b"]" * 100_000,
    "array": b'[{"com-uuid": "not-read-from-an-array"}]',
    "scalar": b"42",
    "string": b'"ping"',
    "null": b"null",
    "empty": b"",
    "com-uuid-number": b'{"com-uuid": 17, "command": "ping"}',
    "no-com-uuid": b'{"command": "ping"}',
}


@pytest.mark.parametrize("broker", ["embedded", "mosquitto"])
def test_hostile_commands_are_refused_and_the_unit_lives_on(
        broker: str, request: pytest.FixtureRequest, observe, unit_address: UnitAddress) -> None:
    url = request.getfixturevalue("embedded_broker").url if broker == "embedded" else \
        request.getfixturevalue("mosquitto")
    obs = observe(url, f"{unit_address.base}/#", (unit_address.topic("exec/command"),))
    with SimUnit(unit_address, url, rate=5.0) as unit:
        coms = {name: str(uuid.uuid4()) for name in hostile("")}
        for name, com in coms.items():
            obs.send(hostile(com)[name])
        for payload in UNREADABLE.values():
            obs.send(payload)
        # It still answers (EXEC-ROBUST-001) ...
        ping = obs.request({"command": "ping"})
        assert ping["response"] == "pong"
        # ... and answered each readable one 'failed' with a reason, once (EXEC-ROBUST-002).
        for name, com in coms.items():
            r = obs.response(com)
            assert r["response"] == "failed" and r["fail-reason"], (name, r)
            if name == "10MB":
                assert "larger than" in r["fail-reason"]
            assert len(obs.responses_to(com)) == 1, name
        mark = obs.mark()
        obs.count("/heartbeat", 3, mark=mark)  # and keeps heartbeating
        responses = obs.json("/exec/response")
        assert len(responses) == len(coms) + 1, "nothing unreadable was answered"
        assert unit.errors == 0, unit.runtime.last_error
    assert obs.violations() == []


def test_memory_stays_bounded_under_a_flood(mosquitto: str, observe, unit_address: UnitAddress,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(memory, "MAX_HISTORY", 100)
    obs = observe(mosquitto, f"{unit_address.base}/exec/response",
                  (unit_address.topic("exec/command"),))
    with SimUnit(unit_address, mosquitto, rate=5.0) as unit:
        for i in range(600):
            if i % 2:
                obs.send({"command": "ping"}, qos=0)
            else:
                obs.send({"command": "start-task", "task-uuid": str(uuid.uuid4()),
                          "task": {"name": "move-to", "params": {}}}, qos=0)  # no waypoint
        last = obs.send({"command": "ping"})
        obs.response(last, timeout=30)
        assert len(unit.core.history) <= 100 and len(unit.core.tasks) <= 101
        assert unit.errors == 0


def test_inbox_is_bounded_in_bytes() -> None:
    rt = Runtime("mqtt://127.0.0.1:1")
    big = b"x" * (1 << 20)  # at the limit: kept whole
    for _ in range(64):
        rt.receive(Message(0.0, "a/unit/air/simulation/x/exec/command", big))
    assert rt.inbox_bytes <= INBOX_BYTES
    assert rt.dropped > 0


def test_a_step_the_host_held_is_told_with_its_times(mosquitto: str,
                                                     unit_address: UnitAddress) -> None:
    """A loaded machine that does not run the runtime's thread when its wait runs out is
    told to ``on_hold`` (from when, to when), so that a certification of the bundled unit in
    its own process does not take the silence for the unit's."""
    holds: list[tuple[float, float]] = []
    with SimUnit(unit_address, mosquitto, rate=5.0) as unit:
        runtime = unit.runtime
        runtime.on_hold = lambda start, end: holds.append((start, end))
        wake = runtime._wake

        class HeldOnce(threading.Event):  # the host runs the thread 0.8 s after its wait
            def wait(self, timeout: float | None = None) -> bool:
                runtime._wake = wake
                woken = wake.wait(timeout)
                time.sleep(0.8)
                return woken

        runtime._wake = HeldOnce()
        deadline = time.monotonic() + 10
        while not any(end - start >= 0.6 for start, end in holds) and \
                time.monotonic() < deadline:
            time.sleep(0.05)
    assert any(end - start >= 0.6 for start, end in holds), holds  # the 0.8 s, in Unix time
    assert all(abs(end - time.time()) < 15 for _, end in holds)

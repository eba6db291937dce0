"""Hand-written command sequences that reach the reference unit's sequence faults (imported as
``sim_sequences``; also by tests/lint): a pause before an abort, a second task while one is
paused, a resend after the end. ``drive(broker, unit, faults, sequence)`` runs one against a
``SimUnit`` and returns every message under the unit, in arrival order."""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable

import orjson

from conformance.client import BrokerURL, Message, MqttClient
from conformance.sim import SimUnit

WAIT = 10.0
RATE = 2.0
BEARING = "look-at-bearing"
"""Camera tasks that run until they are ended: nothing moves."""


class Driver:
    """A commander of one unit that records everything under it."""

    def __init__(self, broker: str, unit: str) -> None:
        self.unit = unit
        self.messages: list[Message] = []
        self.holds: list[tuple[float, float]] = []
        """When the host held the unit (it runs in this process: ``Runtime.on_hold``)."""
        self._new = threading.Condition()
        self.client = MqttClient(BrokerURL.parse(broker), on_message=self._keep,
                                 may_publish=lambda t: t == f"{unit}/exec/command")
        self.client.connect()
        self.client.subscribe(f"{unit}/#", qos=1)

    def _keep(self, m: Message) -> None:
        with self._new:
            self.messages.append(m)
            self._new.notify_all()

    def wait_for(self, found: Callable[[], object], what: str, timeout: float = WAIT) -> object:
        deadline = time.monotonic() + timeout
        with self._new:
            while not (got := found()):
                left = deadline - time.monotonic()
                assert left > 0, f"no {what} within {timeout} s"
                self._new.wait(min(left, 0.2))
            return got

    def on(self, sub: str) -> list[dict]:
        return [orjson.loads(m.payload) for m in list(self.messages)
                if m.topic == f"{self.unit}/{sub}"]

    def statuses(self, task: str) -> list[str]:
        return [f["status"] for f in self.on("exec/feedback") if f.get("task-uuid") == task]

    def send(self, body: dict) -> dict:
        """Publish a command and wait for its answer (a resend: its second answer)."""
        com = body["com-uuid"]
        n = len([r for r in self.on("exec/response") if r.get("response-to") == com])
        self.client.publish(f"{self.unit}/exec/command", orjson.dumps(body), qos=1)
        answers = self.wait_for(lambda: (a := [r for r in self.on("exec/response")
                                               if r.get("response-to") == com])[n:] and a,
                                f"an answer to {body['command']}")
        return answers[-1]  # type: ignore[index]

    def command(self, command: str, **extra: object) -> dict:
        body = {"com-uuid": str(uuid.uuid4()), "command": command, "sender": "commander",
                **extra}
        return body

    def start(self, bearing: float = 45.0) -> tuple[str, dict]:
        task = str(uuid.uuid4())
        body = self.command("start-task", **{"task-uuid": task, "task": {
            "name": BEARING, "params": {"bearing": bearing}}})
        assert self.send(body)["response"] == "running"
        self.until(task, "running")
        return task, body

    def signal(self, task: str, signal: str, status: str | None = None) -> dict:
        answer = self.send(self.command("signal-task", signal=signal, **{"task-uuid": task}))
        if status is not None:
            self.until(task, status)
        return answer

    def until(self, task: str, status: str) -> None:
        self.wait_for(lambda: status in self.statuses(task), f"'{status}' for task {task}")

    def heartbeats(self, n: int) -> None:
        """Wait ``n`` more heartbeats (deadlines pass; tasks-executing is published)."""
        have = len(self.on("heartbeat"))
        self.wait_for(lambda: len(self.on("heartbeat")) >= have + n, f"{n} heartbeats",
                      timeout=WAIT + n / RATE)

    def close(self) -> None:
        self.client.close()


def abort_paused(d: Driver) -> None:
    a, _ = d.start()
    d.signal(a, "$pause", "paused")
    d.signal(a, "$abort", "aborted")


def pause_one_of_two(d: Driver) -> None:
    a, _ = d.start()
    b = str(uuid.uuid4())  # another group (the detector): both run
    assert d.send(d.command("start-task", **{"task-uuid": b, "task": {
        "name": "image-object-detection", "params": {}}}))["response"] == "running"
    d.until(b, "running")
    d.signal(b, "$pause", "paused")
    d.heartbeats(1)
    d.signal(a, "$abort", "aborted")
    d.signal(b, "$abort", "aborted")


def resend_after_end(d: Driver) -> None:
    a, start = d.start()
    d.signal(a, "$enough", "finished")
    assert d.send(start)["response"] == "running"  # the resend: answered as before
    d.heartbeats(2)
    d.signal(a, "$abort")  # whatever runs under its uuid ends


def second_task_while_paused(d: Driver) -> None:
    a, _ = d.start()
    d.signal(a, "$pause", "paused")
    d.heartbeats(2)  # tasks-executing lists the paused task
    b, _ = d.start(bearing=90.0)  # the camera's again: the paused one is pre-empted
    d.heartbeats(4)  # past the response timeout: its final feedback is due
    d.signal(b, "$abort", "aborted")


def query_paused(d: Driver) -> None:
    a, _ = d.start()
    d.signal(a, "$pause", "paused")
    d.send(d.command("query-status", **{"task-uuid": a}))
    d.signal(a, "$abort", "aborted")


def pause_listed_then_waited(d: Driver) -> None:
    a, _ = d.start()
    d.signal(a, "$pause", "paused")
    d.heartbeats(6)  # tasks-executing lists it paused; the lint profile's deadlines pass
    # left paused: a final status after it left the list would be EXEC-FB-004's as well


def pause_resent_after_continue(d: Driver) -> None:
    a, _ = d.start()
    pause = d.command("signal-task", signal="$pause", **{"task-uuid": a})
    assert d.send(pause)["response"] == "ok"
    d.until(a, "paused")
    d.signal(a, "$continue")
    d.wait_for(lambda: d.statuses(a)[-1] == "running", "'running' again")
    assert d.send(pause)["response"] == "ok"  # the resend: answered as before
    d.heartbeats(1)
    d.signal(a, "$abort", "aborted")


def abort_one_of_two(d: Driver) -> None:
    a, _ = d.start()
    b = str(uuid.uuid4())  # another group (the detector): both run
    assert d.send(d.command("start-task", **{"task-uuid": b, "task": {
        "name": "image-object-detection", "params": {}}}))["response"] == "running"
    d.until(b, "running")
    d.heartbeats(3)  # past the response timeout of b's start (no pre-emption: EXEC-SEQ-002)
    d.signal(b, "$abort", "aborted")
    d.heartbeats(1)
    d.signal(a, "$abort")  # ended already where the fault aborted it with b


SEQUENCES: dict[str, Callable[[Driver], None]] = {
    "abort-paused-resumes": abort_paused,
    "pause-pauses-all": pause_one_of_two,
    "resend-after-end-runs-again": resend_after_end,
    "preempt-paused-silently": second_task_while_paused,
    "query-paused-unknown": query_paused,
    "feedback-after-abort-paused": abort_paused,
    "query-paused-finished": query_paused,
    "paused-dropped-from-list": pause_listed_then_waited,
    "resend-signal-reapplied": pause_resent_after_continue,
    "abort-aborts-all": abort_one_of_two,
}
"""Sequence fault -> the command order that shows it."""


def drive(broker: str, unit: str, faults: tuple[str, ...],
          sequence: Callable[[Driver], None]) -> Driver:
    """Run ``sequence`` against the reference unit with ``faults``; the driver holds the
    traffic (two heartbeats after the last step, so the last answers are in)."""
    with SimUnit(unit, broker, faults=faults, rate=RATE, seed=1, task_seconds=1.0) as sim:
        d = Driver(broker, unit)
        sim.runtime.on_hold = lambda start, end: d.holds.append((start, end))
        try:
            d.heartbeats(2)
            sequence(d)
            d.heartbeats(2)
        finally:
            d.close()
    return d

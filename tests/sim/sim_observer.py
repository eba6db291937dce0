"""A small commander and observer of the tests' own, to drive the reference unit over a real
broker: it records every message under the unit's topics (validating each one) and sends
commands to the unit's exec/command only."""

from __future__ import annotations

import bisect
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

import orjson
import pytest

from conformance.client import BrokerURL, Message, MqttClient
from conformance.clock import VirtualClock
from conformance.sim.virtual import VirtualBroker, VirtualClient
from conformance.validator import validate

_UNPARSED = object()
_INVALID = object()


class Observer:
    """Subscribes ``<topic filter>`` and keeps every message; waits are deadlines, never
    sleeps. ``command_topics`` are the only topics it may publish to."""

    def __init__(self, broker: str, topic_filter: str, command_topics: tuple[str, ...] = ()
                 ) -> None:
        self._keep(command_topics)
        self.client = MqttClient(BrokerURL.parse(broker), on_message=self._on_message,
                                 may_publish=lambda t: t in self.command_topics)
        self.client.connect()
        self.client.subscribe(topic_filter, qos=1)

    def _keep(self, command_topics: tuple[str, ...]) -> None:
        self.messages: list[Message] = []
        self._parsed: list[Any] = []
        self._by_topic: dict[str, list[int]] = {}
        self._notified = 0.0
        self.sent = 0
        """Commands published (each should come back to us on the unit's exec/command)."""
        self._cond = threading.Condition()
        self.command_topics = command_topics

    def _on_message(self, m: Message) -> None:
        with self._cond:
            self._by_topic.setdefault(m.topic, []).append(len(self.messages))
            self.messages.append(m)
            self._parsed.append(_UNPARSED)
            # Waiters also look every 30 ms: waking them for each of thousands of messages a
            # second would starve this client's own network thread (and the simulator) of the
            # GIL, and Mosquitto drops what a slow subscriber leaves queued
            # (docs/FIELD-NOTES.md 'MQTT on loopback').
            now = time.monotonic()
            if now - self._notified > 0.02:
                self._notified = now
                self._cond.notify_all()

    def json_all(self) -> list[Any]:
        """Every payload decoded (None where it is not JSON), index by index."""
        with self._cond:
            return [self._decode(i) for i in range(len(self.messages))]

    def _decode(self, i: int) -> Any:
        value = self._parsed[i]
        if value is _UNPARSED:
            try:
                value = orjson.loads(self.messages[i].payload)
            except orjson.JSONDecodeError:
                value = _INVALID
            self._parsed[i] = value
        return None if value is _INVALID else value

    def json_on(self, topic: str, mark: int = 0) -> list[Any]:
        """The decoded payloads on exactly ``topic`` from index ``mark`` on (each decoded once;
        what is not JSON is left out)."""
        with self._cond:
            indexes = self._by_topic.get(topic, [])
            out = []
            for i in indexes[bisect.bisect_left(indexes, mark):]:
                value = self._parsed[i]
                if value is _UNPARSED:
                    try:
                        value = orjson.loads(self.messages[i].payload)
                    except orjson.JSONDecodeError:
                        value = _INVALID
                    self._parsed[i] = value
                if value is not _INVALID:
                    out.append(value)
            return out

    def close(self) -> None:
        self.client.close()

    # --- waiting --------------------------------------------------------------------------------
    def wait_for(self, predicate: Callable[[list[Message]], Any], timeout: float = 10.0,
                 what: str = "a condition", fail: bool = True) -> Any:
        """Wait until ``predicate(messages)`` is truthy; return its value, or fail the test
        (with ``fail=False``: return None)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                value = predicate(self.messages)
                if value:
                    return value
                left = deadline - time.monotonic()
                if left <= 0:
                    if not fail:
                        return None
                    topics = sorted({m.topic for m in self.messages})
                    pytest.fail(f"timed out after {timeout} s waiting for {what}; "
                                f"seen {len(self.messages)} messages on {topics[:12]}")
                self._cond.wait(min(left, 0.03))

    def since(self, mark: int, suffix: str) -> list[Message]:
        with self._cond:
            return [m for m in self.messages[mark:] if m.topic.endswith(suffix)]

    def on(self, suffix: str) -> list[Message]:
        return self.since(0, suffix)

    def mark(self) -> int:
        with self._cond:
            return len(self.messages)

    def count(self, suffix: str, n: int, timeout: float = 10.0, mark: int = 0) -> list[Message]:
        """Wait for ``n`` messages on topics ending with ``suffix`` after ``mark``."""
        return self.wait_for(lambda ms: (got := [m for m in ms[mark:] if m.topic.endswith(
            suffix)]) and len(got) >= n and got, timeout, f"{n} messages on *{suffix}")

    def json(self, suffix: str) -> list[Any]:
        return [orjson.loads(m.payload) for m in self.on(suffix)]

    # --- commanding -----------------------------------------------------------------------------
    def send(self, body: dict[str, Any] | bytes, topic: str | None = None, qos: int = 1) -> str:
        """Publish a command (a dict gets a com-uuid if it has none); returns the com-uuid."""
        topic = topic or self.command_topics[0]
        if isinstance(body, dict):
            body = {"sender": "tests", **body}
            body.setdefault("com-uuid", str(uuid.uuid4()))
            self.client.publish(topic, orjson.dumps(body), qos=qos)
            self.sent += 1
            return str(body["com-uuid"])
        self.client.publish(topic, body, qos=qos)
        self.sent += 1
        return ""

    def responses_to(self, com_uuid: str) -> list[dict[str, Any]]:
        return [r for r in self.json("/exec/response") if isinstance(r, dict)
                and r.get("response-to") == com_uuid]

    def response(self, com_uuid: str, timeout: float = 10.0, n: int = 1) -> dict[str, Any]:
        """The ``n``-th response whose response-to is ``com_uuid``."""
        def found(ms: list[Message]) -> Any:
            got = [r for m in ms if m.topic.endswith("/exec/response")
                   for r in [orjson.loads(m.payload)] if r.get("response-to") == com_uuid]
            return got[n - 1] if len(got) >= n else None
        return self.wait_for(found, timeout, f"response {n} to {com_uuid}")

    def response_on(self, base: str, task_uuid: str, timeout: float = 10.0) -> dict[str, Any]:
        """The first response on ``<base>/exec/response`` carrying ``task_uuid``."""
        return self.wait_for(lambda _: next((r for r in self.json_on(f"{base}/exec/response")
                                             if isinstance(r, dict)
                                             and r.get("task-uuid") == task_uuid), None),
                             timeout, f"a response about task {task_uuid}")

    def request(self, body: dict[str, Any], timeout: float = 10.0) -> dict[str, Any]:
        return self.response(self.send(body), timeout)

    def feedback(self, task_uuid: str) -> list[str]:
        return [f["status"] for f in self.json("/exec/feedback") if f.get("task-uuid") ==
                task_uuid]

    def wait_status(self, task_uuid: str, status: str, timeout: float = 15.0) -> list[str]:
        """Wait for feedback ``status`` of a task; returns the task's feedback so far."""
        def found(ms: list[Message]) -> Any:
            got = [f["status"] for m in ms if m.topic.endswith("/exec/feedback")
                   for f in [orjson.loads(m.payload)] if f.get("task-uuid") == task_uuid]
            return got if status in got else None
        return self.wait_for(found, timeout, f"feedback {status!r} for task {task_uuid}")

    def wait_feedback(self, task_uuid: str, n: int, timeout: float = 15.0) -> list[str]:
        """Wait until a task has had ``n`` feedback messages; returns their statuses."""
        return self.wait_for(lambda ms: len(got := self.feedback(task_uuid)) >= n and got,
                             timeout, f"{n} feedback messages for task {task_uuid}")

    def violations(self, ignore: tuple[str, ...] = ()) -> list[tuple[str, str]]:
        """(rule, topic) of every violation the validator finds in what the unit published
        (the tests' own commands are not judged)."""
        with self._cond:
            messages = [m for m in self.messages if not m.topic.endswith("/exec/command")]
        return [(v.rule, m.topic) for m in messages for v in validate(m.topic, m.payload,
                                                                        m.time).violations
                if v.rule not in ignore]


class VirtualObserver(Observer):
    """The same observer on a ``VirtualBroker`` (``conformance.sim.virtual``): its waits run
    the virtual clock up to their deadline, so a workout takes no real time (one thread)."""

    def __init__(self, broker: VirtualBroker, clock: VirtualClock, topic_filter: str,
                 command_topics: tuple[str, ...] = ()) -> None:
        self._keep(command_topics)
        self.clock = clock
        self.client = VirtualClient(broker, self._on_message,  # type: ignore[assignment]
                                    may_publish=lambda t: t in self.command_topics)
        self.client.subscribe(topic_filter, qos=1)

    def wait_for(self, predicate: Callable[[list[Message]], Any], timeout: float = 10.0,
                 what: str = "a condition", fail: bool = True) -> Any:
        deadline = self.clock.now() + timeout
        while True:
            value = predicate(self.messages)
            if value:
                return value
            left = deadline - self.clock.now()
            if left <= 0:
                if fail:
                    pytest.fail(f"timed out after {timeout} s (virtual) waiting for {what}")
                return None
            self.clock.wait(None, left)

"""The suite as the sender of commands (spec 12's and spec 14's commanders alike): publish a
command to the one command topic allowed (docs/ARCHITECTURE.md 'Safety'), never under
``--dry-run``, and wait for the response whose ``response-to`` is its com-uuid (12.3, 14.4)."""

from __future__ import annotations

import threading
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import orjson

from conformance.checks.suite_commands import SENDER  # the suite's name: lint knows it too
from conformance.scenarios.traffic import Entry, Traffic
from conformance.topics import UnitAddress

ANSWER_TIMES_KEPT = 32
"""Answer times kept per sender (the latest: a unit's pace, bounded memory)."""


class NotSent(Exception):
    """A command was not published; the message says why. What the scenario would have
    judged with it is could-not-test, with that reason."""


class DryRun(NotSent):
    """Raised instead of publishing under ``--dry-run``; the message says what would be sent."""


class Refused(NotSent):
    """The publish policy refused the payload (docs/ARCHITECTURE.md 'Safety': e.g. a motion task
    named to a real unit without --allow-motion); the message says why."""


@dataclass
class Sent:
    """A command as published: its ``com_uuid``, body, and the traffic mark taken just before
    it went out (answers arrive after ``mark``)."""

    com_uuid: str
    body: dict[str, Any]
    payload: bytes
    mark: int
    gaps_before: int = 0
    time: float = 0.0
    """When it went out, Unix seconds (the traffic clock's)."""


def new_uuid() -> str:
    # Fresh, not seeded: a com-uuid repeated across runs would look like a resend (12.1).
    return str(uuid.uuid4())


class Sender:
    """Publishes commands for ``unit`` to ``topic`` and waits for their responses on the
    ``responses`` subtopic. ``publish(topic, payload)`` does the MQTT publish; ``gaps()``
    counts the connection gaps lived through; ``away()`` says since when the unit is not heard
    again after one (None: it is); ``wait_connected(seconds)`` waits for the link.
    A subclass remembers what it must abort later in ``_remember``, before the publish."""

    responses = ""
    """The subtopic the responses come on (``exec/response``, ``tst/response``)."""
    refuse: Callable[[str, bytes], str | None] | None = None
    """The publish policy's payload half (``Connection.refuse_payload``), asked under
    --dry-run too, so that a dry run shows what the policy would refuse."""

    def __init__(self, unit: UnitAddress, topic: str, traffic: Traffic,
                 publish: Callable[[str, bytes], None], *, dry_run: bool,
                 say: Callable[[str], None], wait_connected: Callable[[float], bool],
                 gaps: Callable[[], int] = lambda: 0,
                 away: Callable[[], object] = lambda: None) -> None:
        self.unit = unit
        self.topic = topic
        self.traffic = traffic
        self._publish = publish
        self.dry_run = dry_run
        self._say = say
        self._wait_connected = wait_connected
        self._gaps = gaps
        self._away = away
        self._lock = threading.Lock()
        self.sent_count = 0
        self.would_publish: list[tuple[str, bytes]] = []
        """Under --dry-run: what would have been published."""
        self.answer_times: deque[float] = deque(maxlen=ANSWER_TIMES_KEPT)
        """Seconds the latest answers took, from the publish to the response's arrival."""

    def gaps(self) -> int:
        """How many connection gaps the client has lived through: a wait across one saw
        nothing of what the unit sent meanwhile (an outage of the observer, not the unit's)."""
        return self._gaps()

    def broken_since(self, gaps_before: int) -> bool:
        """Whether the path to the unit broke since ``gaps()`` read ``gaps_before`` (a link
        lost, or mended), or the unit is not back on the broker yet: a silence meanwhile is
        the broker's, no habit of the unit."""
        return self._gaps() != gaps_before or self._away() is not None

    @staticmethod
    def compose(body: dict[str, Any], com_uuid: str | None = None
                ) -> tuple[bytes, dict[str, Any]]:
        """The payload of a command and its body, ``com-uuid`` and ``sender`` filled in when
        missing."""
        body = dict(body)
        body.setdefault("com-uuid", com_uuid or new_uuid())
        body.setdefault("sender", SENDER)
        return orjson.dumps(body, option=orjson.OPT_SORT_KEYS), body

    def publish_command(self, payload: bytes, body: dict[str, Any], *,
                        com_uuid: str = "") -> Sent:
        """Publish ``payload`` (whose decoded ``body`` it is) to the command topic; under
        --dry-run say what would be published and raise ``DryRun``."""
        if self.dry_run:
            why = self.refuse(self.topic, payload) if self.refuse is not None else None
            if why is not None:
                self._say(f"dry run: would not publish to {self.topic}: {why}")
                raise Refused(why)
            self.would_publish.append((self.topic, payload))
            shown = payload.decode("utf-8", "backslashreplace")
            self._say(f"dry run: would publish to {self.topic}: {shown}")
            raise DryRun(f"dry run: would publish to {self.topic}: {shown[:200]}")
        self._wait_connected(5.0)  # a command sent into a gap is lost; wait for the link
        sent = Sent(str(body.get("com-uuid", com_uuid)), body, payload, self.traffic.mark(),
                    self._gaps(), self.traffic.clock.now())
        # Remembered before it goes out: a Ctrl-C between publish and answer must not leave
        # a task or tree running that abort_all does not know about.
        self._remember(sent)
        try:
            self._publish(self.topic, payload)
        except PermissionError as e:  # the client's PublishRefused: nothing went out
            self._forget(sent)
            self._say(str(e))
            raise Refused(str(e)) from None
        with self._lock:
            self.sent_count += 1
        return sent

    def _remember(self, sent: Sent) -> None:
        """What a command about to be published may start (to abort it at the end)."""

    def _forget(self, sent: Sent) -> None:
        """A command ``_remember``ed was not published after all: it started nothing."""

    def await_response(self, sent: Sent, timeout: float, *, after: int | None = None,
                       what: str = "") -> Entry | None:
        """The response whose response-to is the command's com-uuid (12.3, 14.4), after
        ``after`` (default: the command's mark), waiting up to ``timeout`` seconds."""
        com_uuid = sent.com_uuid
        answer = self.traffic.wait_for(
            lambda e: e.get("response-to") == com_uuid, timeout,
            after=sent.mark if after is None else after, subtopic=self.responses, what=what)
        if answer is not None and after is None and sent.time:
            self.answer_times.append(max(0.0, answer.time - sent.time))
        return answer

    def answer_time(self) -> float | None:
        """The median of the latest answer times, seconds (None before any answer): the
        unit's pace, which the default exploration budget scales with."""
        times = sorted(self.answer_times)
        return times[len(times) // 2] if times else None

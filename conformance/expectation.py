"""What direct execution's commands may get back (spec 12), as data: the tables of signals and
query answers, a ``Command`` as the model reads it, an ``Expectation`` and its ``Outcome``s, and
a ``Finding`` of the sequence rules. The model that holds the state they are read in is
``conformance/protocol.py`` (``Model``), which re-exports every name here; pure, like it."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import orjson

from conformance.status import FINAL_STATUSES, accepts_signal
from conformance.taskrecord import State

BUILTIN_SIGNALS = ("$abort", "$continue", "$enough", "$pause")
"""12.2.2: 'The buildtin signals are $enough, $pause, $continue and $abort.'"""
NO_SUCH_TASK = "waraps-conformance-no-such-task"
"""A task name no unit offers: what the suite starts to see a refusal (12.2.1, TST-011)."""
COMMANDS = ("ping", "start-task", "signal-task", "query-status")  # 12.1
NEW_TASK = ""
"""The key, in ``Outcome.states``, of the task a start-task without task-uuid begins."""

FINAL = {status: State(status) for status in FINAL_STATUSES}  # 12.4: finished, failed, aborted
SIGNAL_EFFECT: dict[str, tuple[str, State]] = {
    "$abort": ("aborted", State.ABORTED), "$enough": ("finished", State.FINISHED),
    "$pause": ("paused", State.PAUSED), "$continue": ("running", State.RUNNING)}
"""12.2.2: the feedback an accepted signal implies, and the state it leads to."""
SIGNAL_RULE = {"$abort": "EXEC-SIG-002", "$enough": "EXEC-SIG-004", "$pause": "EXEC-SIG-003",
               "$continue": "EXEC-SIG-003"}
"""The rule that feedback proves (12.2.2)."""
UNCHANGED = frozenset({("$pause", State.PAUSED), ("$continue", State.RUNNING)})
"""(signal, state) pairs that change nothing: no feedback is owed (EXEC-SEQ-001's decision,
docs/MODEL.md). A State is its str: ``("$pause", "paused")`` is in it too."""
STOP_SIGNALS = ("$abort", "$enough")
"""The signals that end a task (12.2.2); once $abort is accepted nothing may run it on
(EXEC-SEQ-001), $enough lets it wind down its own way until 'finished' (EXEC-SIG-004)."""
QUERY_ANSWERS: dict[State, tuple[str, ...]] = {
    State.RUNNING: ("running",), State.PAUSED: ("running", "paused"),
    State.FINISHED: ("finished", "success"), State.FAILED: ("failed",),
    State.ABORTED: ("failed", "aborted"), State.UNKNOWN: ("unknown",)}
"""12.1: query-status answers 'running, failed, success, unknown'; 'paused' and 'aborted' are
12.4's words for what that list calls running and failed, 'success' is ERR-006's reading of
finished. In the order a finding lists them."""
REFUSED_QUERY = frozenset({"failed", "unknown"})
"""A task-uuid whose start-task was refused: 'failed' (it failed to start) or 'unknown' (it
never ran); the spec does not say which (docs/MODEL.md)."""


@dataclass(frozen=True)
class Command:
    """One command on exec/command. ``content`` identifies its content: a 16-byte digest of
    its canonical JSON (a resend is the same content under the same com-uuid, 12.1; a command
    may be 1 MiB, and thousands are kept)."""

    com_uuid: str
    name: str
    task_uuid: str | None = None
    signal: str | None = None
    task_name: str | None = None
    content: bytes = b""

    @classmethod
    def read(cls, payload: bytes | Mapping[str, Any]) -> Command | None:
        """The command in a payload (JSON bytes or a dict); None without a com-uuid string."""
        m: Any = payload
        if isinstance(payload, bytes | bytearray | memoryview):
            try:
                m = orjson.loads(bytes(payload))
            except orjson.JSONDecodeError:
                return None
        if not isinstance(m, Mapping):
            return None
        com = str_at(m, "com-uuid")
        if not com:
            return None
        name = str_at(m, "command") or "(malformed)"
        task = m.get("task")
        content = hashlib.blake2b(orjson.dumps(dict(m), option=orjson.OPT_SORT_KEYS),
                                  digest_size=16).digest()
        return cls(com, name, str_at(m, "task-uuid"), str_at(m, "signal"), str_at(task, "name"),
                   content)


@dataclass(frozen=True)
class Outcome:
    """What follows when the unit answers a command with ``response``."""

    response: str
    states: Mapping[str, State] = field(default_factory=dict)
    """task-uuid -> its state after this answer (only the tasks it changes)."""
    implies: Mapping[str, frozenset[str]] = field(default_factory=dict)
    """task-uuid -> feedback statuses of which one must follow (12.2.2)."""


@dataclass(frozen=True)
class Expectation:
    """What a command may get back in the model's current state."""

    command: Command
    resend: bool
    outcomes: tuple[Outcome, ...]
    rule: str  # the rule an answer outside ``responses`` breaks
    may_end: frozenset[str] = frozenset()  # live tasks it may end, each with a final status
    untouched: frozenset[str] = frozenset()  # tasks whose state it must not change
    why: str = ""

    @property
    def responses(self) -> frozenset[str]:
        return frozenset(o.response for o in self.outcomes)

    def outcome(self, response: str | None) -> Outcome | None:
        if self.command.name == "signal-task" and response not in self.responses \
                and accepts_signal(response):
            response = "ok"
        return next((o for o in self.outcomes if o.response == response), None)


@dataclass(frozen=True)
class Finding:
    """The unit disagrees with the model: ``rule`` is broken."""

    rule: str
    task_uuid: str | None
    com_uuid: str | None
    expected: str
    observed: str
    time: float
    condition: str = ""  # which condition of ``rule`` (rules.toml), "" its own words



def str_at(m: Any, key: str) -> str | None:
    """``m[key]`` if ``m`` is a mapping and it is a string, else None."""
    x = m.get(key) if isinstance(m, Mapping) else None
    return x if isinstance(x, str) else None

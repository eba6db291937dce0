"""One task as the traffic showed it (12.4): its state, its statuses, and the evidence the
conversation checks judge it by. The one task record of the suite, in one store: the protocol
model's (``conformance.protocol.Model.tasks``, which the exec conversations of
``conformance.checks.conversation`` read and annotate). The model owns the state and the
statuses; the conversations own the fields they judge by (``life`` and below). Pure: no
MQTT, no clock."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

STATUSES_KEPT = 16


class State(str, enum.Enum):
    """A task's state (12.4's statuses; 12.1's query-status words)."""

    UNKNOWN = "unknown"
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"
    ABORTED = "aborted"
    FAILED = "failed"

    @property
    def live(self) -> bool:
        return self in (State.RUNNING, State.PAUSED)

    @property
    def ended(self) -> bool:
        return self in (State.FINISHED, State.ABORTED, State.FAILED)


@dataclass(eq=False, slots=True)
class TaskRecord:
    """One task as the traffic showed it: its state and statuses (the model's), and the
    evidence the conversation checks judge it by (``checks/conversation.py``)."""

    task_uuid: str
    name: str | None = None
    state: State = State.RUNNING
    started_by: str | None = None
    """The com-uuid of the start-task that began it (None: seen only in feedback)."""
    refused: bool = False
    """Its start-task was answered 'failed': it never ran."""
    statuses: list[tuple[float, str]] = field(default_factory=list)
    """(time, status) of its latest feedback (``STATUSES_KEPT``), every one the model heard."""
    ended_at: float | None = None
    acked: tuple[tuple[float, str, str], ...] = ()
    """(time, signal, com-uuid) of the signals to it answered 'ok', at most 8 (a tuple: most
    tasks get none, and an empty one costs nothing)."""
    lost: bool = False
    """Of a life before the model's current one: unknown to the model (12.1: a new life lost
    its history), kept for the conversations, which judge it by its ``life``."""
    # --- the conversations' evidence (``checks/conversation.py``) ---------------------------
    life: str | None = None
    """The agent-uuid of the life the conversations followed it in."""
    followed: float | None = None
    """Since when the conversations follow it (None: not): a start-task answered 'running'
    began it, or its feedback came (not a start-task only refused, nor one a new start-task
    of its uuid is to begin anew). They judge it by the statuses said since."""
    listed: bool = False
    left_at: float | None = None
    """When it left tasks-executing while it was held open (no final status yet)."""
    listed_at: float | None = None
    """When tasks-executing last listed it (5.3)."""
    listed_paused: bool = False
    """Whether tasks-executing listed it while it was paused: then its unit lists paused
    tasks, and its leaving while paused is an end too (5.3 'currently executing' allows
    either reading; a unit keeps to one)."""
    command: Any = None
    """The start-task that began it, as the conversation checks keep it (its evidence)."""
    final: tuple[str, str | None, float] | None = None
    """(status, com-uuid, time) of its final feedback, or ('left tasks-executing', None,
    time) when it left tasks-executing with none."""
    resent: float | None = None
    """When its start-task was last resent."""
    running_feedback: int = 0
    """How many 'running' feedbacks it sent (EXEC-RESEND-001: started twice)."""
    said_failed: tuple[tuple[str, Any], ...] = ()
    """(rule, message) of the latest two that said 'failed' while it may run on (the answer
    to its resent start-task, its feedback): the findings once it does (EXEC-RESEND-003,
    EXEC-FB-004)."""

    @property
    def last_status(self) -> str | None:
        return self.statuses[-1][1] if self.statuses else None

    @property
    def last_time(self) -> float | None:
        """When its latest status came."""
        return self.statuses[-1][0] if self.statuses else None

    def said(self, status: str, t: float, kept: int = STATUSES_KEPT) -> None:
        """Its feedback said ``status`` at ``t`` (the latest ``kept`` are kept)."""
        self.statuses.append((t, status))
        del self.statuses[:-kept]

    def acked_since(self, t: float, signals: tuple[str, ...]) -> tuple[float, str, str] | None:
        return next((a for a in reversed(self.acked) if a[0] >= t and a[1] in signals), None)

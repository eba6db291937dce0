"""The steps an exploration takes, as typed data: the commands of 12.1 and waiting, as the state
machine chooses them, the explorer runs them, a story stores them and a replay reads them.

Tasks are named by their slot (the n-th start-task of the example) and commands by the step
that first sent them, so a stored step means the same thing when it is run again with fresh
uuids. The JSON form (``to_json``) is the stored story's: ``{"do": "start", "task": ...}``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar


@dataclass(frozen=True)
class Start:
    """start-task ``task`` as the task of ``slot``; without a task-uuid of the suite's when
    ``task_uuid`` is False (12.1: the unit then makes one)."""

    task: str
    task_uuid: bool = True
    slot: int | None = None
    """None only in a stored story that did not say (the explorer counts the starts itself)."""
    do: ClassVar[str] = "start"


@dataclass(frozen=True)
class Signal:
    """signal-task ``signal`` (12.2) to the task of ``slot``, or to a task-uuid never used
    (None); ``teardown``: the abort that ends an example, not a step the story chose."""

    signal: str
    slot: int | None = None
    teardown: bool = False
    do: ClassVar[str] = "signal"


@dataclass(frozen=True)
class Query:
    """query-status (12.1) of the task of ``slot``, or of a task-uuid never used (None)."""

    slot: int | None = None
    do: ClassVar[str] = "query"


@dataclass(frozen=True)
class Resend:
    """The command of step ``step`` sent again with its com-uuid (12.1)."""

    step: int
    do: ClassVar[str] = "resend"


@dataclass(frozen=True)
class Ping:
    """A ping (12.1)."""

    do: ClassVar[str] = "ping"


@dataclass(frozen=True)
class Wait:
    """Waiting ``periods`` heartbeats (1 to 5 are waited: ``Explorer``)."""

    periods: int = 1
    do: ClassVar[str] = "wait"


Action = Start | Signal | Query | Resend | Ping | Wait
KINDS: dict[str, type[Action]] = {kind.do: kind for kind in (Start, Signal, Query, Resend,
                                                             Ping, Wait)}


def slot_of(action: Action) -> int | None:
    """The slot of the task a step is about, None for a step about none."""
    return action.slot if isinstance(action, (Start, Signal, Query)) else None


def is_teardown(action: Action) -> bool:
    """Whether a step is the example's own teardown (not replayed, not counted)."""
    return isinstance(action, Signal) and action.teardown


def to_json(action: Action) -> dict[str, Any]:
    """The step as a stored story holds it: ``do`` and its fields; a start's unknown slot and
    a signal's ``teardown`` only when they say something."""
    out: dict[str, Any] = {"do": action.do}
    for f in fields(action):
        value = getattr(action, f.name)
        if (f.name == "slot" and value is None and isinstance(action, Start)) \
                or (f.name == "teardown" and not value):
            continue
        out[f.name] = value
    return out


def from_json(data: dict[str, Any]) -> Action:
    """The step a stored story holds (its fields already checked: ``story.load``); fields
    its kind does not have are ignored, as the explorer always ignored them."""
    kind = KINDS[data["do"]]
    own = {f.name for f in fields(kind)}
    return kind(**{k: v for k, v in data.items() if k in own})

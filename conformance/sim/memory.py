"""What the reference unit remembers of one life, bounded so that a flood of commands cannot
grow it: the answers it sent (for resends, 12.1) and what it ran (tasks, TST trees).

A reboot forgets it all (12.1: 'history is lost with a reboot').
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Generic, Protocol, TypeVar

MAX_HISTORY = 5000
"""Commands (and ended tasks) remembered per life; the oldest are forgotten first."""

Answer = TypeVar("Answer")


class Ended(Protocol):
    @property
    def ended(self) -> bool: ...


Item = TypeVar("Item", bound=Ended)


class Resends(Generic[Answer]):
    """com-uuid -> the answer sent to that command, the oldest forgotten first: a command resent
    with the same com-uuid is answered again, not run twice (12.1)."""

    def __init__(self) -> None:
        self._answers: OrderedDict[str, Answer] = OrderedDict()

    def __contains__(self, com: object) -> bool:
        return com in self._answers

    def __len__(self) -> int:
        return len(self._answers)

    def get(self, com: str) -> Answer | None:
        return self._answers.get(com)

    def remember(self, com: str, answer: Answer) -> None:
        self._answers[com] = answer
        if len(self._answers) > MAX_HISTORY:
            self._answers.popitem(last=False)

    def resent(self, com: str) -> Answer:
        """The answer to a command seen again; it is now the most recently used."""
        self._answers.move_to_end(com)
        return self._answers[com]

    def clear(self) -> None:
        self._answers.clear()


def forget_oldest_ended(memory: OrderedDict[str, Item], limit: int | None = None) -> Item | None:
    """Over ``limit`` items (default ``MAX_HISTORY``): forget the oldest one that has ended (what
    runs is never forgotten) and return it; else None."""
    if len(memory) <= (MAX_HISTORY if limit is None else limit):
        return None
    key = next((k for k, item in memory.items() if item.ended), None)
    return None if key is None else memory.pop(key)

"""Systematic deviations of the unit under test, seen once and then adapted to.

A unit that runs tasks under a task-uuid of its own, ends them with a word outside 12.4's
status list, sends feedback without a task-uuid or never sends a final status does so for
every task. Waiting the full feedback deadline again and again for a deviation already seen
proves nothing more and stalls the run, so the first evidence of each is noted here (once,
with its rule), and the scenarios adapt:

- another task-uuid: the suite follows the one the unit answered with;
- a final-looking status outside the vocabulary (``done``, ``completed``, ...): taken as the
  end it means (its violation is the passive check's: EXEC-FB-002);
- feedback without task-uuid: later waits for a task's feedback end at the next such message,
  and what they would judge is could-not-test with the reason;
- no final feedback for a task that ends on its own: later waits for one are could-not-test;
- a command of one kind (start-task, signal-task, query-status) never answered: later ones of
  that kind get a short deadline (a fifth of the response deadline) for their answer.

TST (14) the same way (``tst_commander``): a node status outside 14.5's list that plainly means
one in it (``finished``) is read as what it means (TST-003's to judge); a signal answered 'ok'
and not done (TST-012) is waited for the full feedback deadline once, then later ones of it a
fifth of the response deadline; a tree answered with a root-uuid other than the root's
node-uuid, but reported under that node-uuid (TST-004), is followed under the one its
feedback uses. A seq or conc is waited for only until its task nodes ended
(nothing of it runs then): whether it reports its own end is the Monitor's (TST-009).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from conformance.status import FINAL_STATUSES, STANDARD_STATUSES, meaning

__all__ = ["FINAL_STATUSES", "STANDARD_STATUSES", "Deviation", "Deviations", "Kind", "meaning"]

class Kind(Enum):
    """The deviations the scenarios adapt to, each with the rule whose evidence it is."""

    TASK_UUID_IGNORED = "EXEC-START-002"
    STATUS_VOCABULARY = "EXEC-FB-002"
    FEEDBACK_WITHOUT_TASK_UUID = "EXEC-FB-001"
    NO_FINAL_FEEDBACK = "EXEC-START-003"
    START_UNANSWERED = "EXEC-START-001"
    SIGNAL_UNANSWERED = "EXEC-SIG-001"
    QUERY_UNANSWERED = "EXEC-QUERY-001"
    TST_STATUS_VOCABULARY = "TST-003"
    TST_ROOT_UUID = "TST-004"
    TST_SIGNAL_IGNORED = "TST-012"

    @property
    def rule(self) -> str:
        return self.value


UNANSWERED: dict[str, Kind] = {"start-task": Kind.START_UNANSWERED,
                               "signal-task": Kind.SIGNAL_UNANSWERED,
                               "query-status": Kind.QUERY_UNANSWERED}
"""Commands whose going unanswered is adapted to (12.1: every command is answered)."""
SHORT = 0.2
"""Share of the response deadline a command of a kind never answered so far is given."""


@dataclass(frozen=True)
class Deviation:
    """The first evidence of a systematic deviation, and how the suite adapts to it."""

    kind: Kind
    evidence: str
    adaptation: str

    def __str__(self) -> str:
        return f"{self.kind.rule}: {self.evidence}; {self.adaptation}"


class Deviations:
    """The deviations seen so far (each kind once). ``on_new`` hears of each the first time."""

    def __init__(self, on_new: Callable[[Deviation], None] | None = None) -> None:
        self._seen: dict[Kind, Deviation] = {}
        self._lock = threading.Lock()
        self._on_new = on_new

    def note(self, kind: Kind, evidence: str, adaptation: str) -> bool:
        """Remember the first evidence of ``kind``; True when it is new."""
        with self._lock:
            if kind in self._seen:
                return False
            found = self._seen[kind] = Deviation(kind, evidence, adaptation)
        if self._on_new is not None:
            self._on_new(found)
        return True

    def get(self, kind: Kind) -> Deviation | None:
        with self._lock:
            return self._seen.get(kind)

    def reason(self, kind: Kind) -> str | None:
        """Why a wait for this deviation is could-not-test, or None when not seen."""
        found = self.get(kind)
        return None if found is None else f"{found.evidence} ({kind.rule}), seen earlier in " \
            "this run: not waited for again"

    def all(self) -> list[Deviation]:
        with self._lock:
            return list(self._seen.values())

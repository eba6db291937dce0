"""What a certification gathers for the judge, rule by rule: what its scenarios recorded (into
the Monitor's row, a death or an outage noted as the excuse), which rules' tests were
selected, ran and showed which verdict, which scenarios ran, and which rules exploration's
stories repeat. The judge decides on it (``conformance/judge.py``); this only keeps it."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from conformance.checks import Monitor
from conformance.checks.conversation import answered
from conformance.rules import CATALOGUE, Mode
from conformance.suite.connection import Connection
from conformance.suite.events import clock
from conformance.topics import UnitAddress
from conformance.violation import Observed, Verdict


def outage(lost: float) -> str:
    """Why nothing the unit should have sent since ``lost`` is its fault."""
    return f"the broker link was lost at {clock(lost)}: no answer could arrive"


def not_back(since: float) -> str:
    """Why nothing the unit should have sent while it was not back on the broker (after
    a reconnect or a stall at ``since``) is its fault."""
    return (f"the unit was not heard again after the broker's outage or stall "
            f"({clock(since)}): the command may never have reached it")


class Evidence:
    """One run's evidence per rule, beside the Monitor's rows."""

    def __init__(self, unit: UnitAddress, monitor: Monitor, lock: threading.RLock,
                 connection: Connection, unit_died: Callable[[], str]) -> None:
        self.unit, self.monitor, self._lock = unit, monitor, lock
        self.connection = connection
        self._unit_died = unit_died
        """Why the unit counts as dead now, or "" (``Observation.unit_died``, settled)."""
        self.selected: list[str] = []
        """The rules whose tests were selected to run (after -k, -m, --rule)."""
        self.ran: set[str] = set()
        """The rules whose tests ran (a test that never ran judged nothing)."""
        self.enacted: dict[str, Verdict] = {}
        """The verdict each rule's test showed when it ran (``suite.verdict.enact``)."""
        self.scenarios_done: dict[str, bool] = {}
        """Scenario -> whether it ran (False: its rules could not be tested)."""
        self.replays: dict[str, tuple[float, str]] = {}
        """Rule -> (when exploration began, the replay line of the story that found it)."""

    def record(self, rule: str, *, violation: Any = None, seen: Observed | None = None,
               reason: str = "", missing: bool = True) -> None:
        """Where scenarios report what they saw (``Context.record``): into the Monitor, for
        the judge. What a scenario found missing from a unit that has died, or while the
        broker was away, is not a fault of its own: the death (HB-012) or the outage is the
        finding, so the rule could not be tested (the excuse is recorded with it)."""
        excused = ""  # ``missing`` False: a finding of what came (a new name), not of silence
        if violation is not None and missing and CATALOGUE[rule].mode is not Mode.PASSIVE:
            lost, back = self.connection.lost_since(), self.connection.away_since()
            if lost is not None:
                excused = outage(lost)
            elif back is not None:
                excused = not_back(back)
            else:
                excused = self._unit_died()
        with self._lock:
            if violation is not None and violation.command and answered(
                    self.monitor.state(self.unit), violation.command):
                return  # answered meanwhile: late (the Monitor's own finding), not unanswered
            self.monitor.record(self.unit, rule, violation=violation, seen=seen,
                                reason=reason, excused=excused)

    def judged_rules(self) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
        """For the run's facts: the rules selected, the rules that ran, and those whose test
        showed no failure. A rule the exploration (or its replay) judged was judged, selected
        or not (``selected`` stays empty for a run of every rule)."""
        selected = tuple(dict.fromkeys([*self.selected, *self.replays]))
        ran = tuple(sorted(self.ran | set(self.replays)))
        passed = tuple(sorted(r for r, shown in self.enacted.items() if shown is not Verdict.FAIL))
        return selected, ran, passed

"""A certification's report, judged: the whole run's under the run's facts (what the JSON,
HTML and JUnit reports and the exit status show), and each rule's as its test enacts it
mid-run, made once per change of what the Monitor knows. The verdicts are the judge's
(``conformance/judge.py``); this only asks it, at the right moments and not too often."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from conformance.checks import Monitor
from conformance.facts import RunFacts
from conformance.judge import judge, unexamined
from conformance.results import RunReport
from conformance.topics import UnitAddress
from conformance.violation import RuleResult


class Judging:
    """The judged report of one certification, and each rule's result in it."""

    def __init__(self, unit: UnitAddress, monitor: Monitor, lock: threading.RLock,
                 facts: Callable[[], RunFacts], meta: Callable[[], dict[str, Any]]) -> None:
        self.unit, self.monitor, self._lock = unit, monitor, lock
        self.facts, self.meta = facts, meta
        self._judged_at: tuple[tuple[int, float | None], RunReport] | None = None
        self.final: RunReport | None = None
        """The finished run's report (``conclude``): what was written, what the terminal and
        the exit status say, however late a message still comes."""

    def report(self, **extra: Any) -> RunReport:
        """The run's report, judged (``conformance.judge``) under the run's facts: every rule's
        verdict and the conclusion every output shows; once the run is finished, its final
        report."""
        if self.final is not None and not extra:
            return self.final
        with self._lock:
            report = self.monitor.report(**self.meta(), **extra)
        return judge(report, self.facts())

    def conclude(self, finished: float) -> RunReport:
        """Judge the finished run once: every output reads this report from now on (judged
        again later, the end of the observation would move and with it what a rule saw)."""
        self.final = self.report(finished=finished)
        return self.final

    def judged(self) -> RunReport:
        """The report as each rule's test enacts it: judged under the facts known mid-run (a
        selection and a cut short run mark rules not run only in ``report``). Made once per
        change of what the Monitor knows: a hundred rule tests in a row read the same one."""
        facts = self.facts()
        with self._lock:
            key = (self.monitor.version, facts.broker_lost)
            if self._judged_at is not None and self._judged_at[0] == key:
                return self._judged_at[1]
            report = self.monitor.report(**self.meta())
        judged = judge(report, RunFacts(kind=facts.kind, unit=facts.unit, strict=facts.strict,
                                        broker_lost=facts.broker_lost))
        self._judged_at = (key, judged)
        return judged

    def result(self, rule: str) -> RuleResult:
        """``rule``'s result for the unit, as its test enacts it (unexamined if none)."""
        unit = self.judged().units.get(str(self.unit))
        if unit is None or rule not in unit.rules:
            return unexamined(rule)
        return unit.rules[rule]

    def violation_total(self, rule: str) -> int:
        """How many violations of ``rule`` the unit committed in all (not only those kept)."""
        unit = self.judged().units.get(str(self.unit))
        return unit.violation_counts.get(rule, 0) if unit is not None else 0

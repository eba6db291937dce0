"""What lint saw of each unit and commander: one ``LintRow`` each, made here only, live from
the ``Linter`` or at the end from the run report, and rendered by the terminal scorecard
(``lint.scorecard``) and the fleet page (``lint.fleetview``) alike, so the two cannot
disagree on a row's type, role, levels, messages, last seen, findings or status.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

from conformance.conclusion import facts_of, triage_rank
from conformance.lint.linter import NOT_A_UNIT, OTHER_UNITS
from conformance.results import Party
from conformance.rules import CATALOGUE
from conformance.violation import Verdict, Violation

STATUS_ORDER = {"silent": 0, "FAIL": 1, "warn": 2, "ok": 3, "-": 4}
"""Rows worst first: a unit gone silent first (death first, ``conclusion.TRIAGE``)."""
STATUS_WORDS = {"silent": "silent", "FAIL": "fail", "warn": "warn", "ok": "clean",
                "-": "unheard"}
"""Each status in words, the same on the page, in the terminal and in ``/metrics``: silent
(its heartbeat stopped, now), fail, warn, clean, unheard (nothing of its own seen)."""


@dataclass(frozen=True)
class Finding:
    """A rule a row fails or warns: its verdict (fail, warn), how many violations, and the
    first one (when it was kept)."""

    rule: str
    verdict: str
    count: int
    first: Violation | None = None
    reason: str = ""

    @property
    def title(self) -> str:
        rule = CATALOGUE.get(self.rule)
        return rule.title if rule else ""


@dataclass(frozen=True)
class LintRow:
    """A unit or commander (``party``) as lint saw it; times Unix seconds, None in a capture
    without times. ``levels`` None: a unit sent messages but no levels yet."""

    unit: str
    party: Party = Party.UNIT
    agent_type: str = ""
    role: str = ""
    levels: tuple[str, ...] | None = None
    messages: int = 0
    first_seen: float | None = None
    last_seen: float | None = None
    findings: tuple[Finding, ...] = ()
    """Worst first (``severity``)."""
    live: tuple[str, ...] = ()
    """Failing rules off right now over their latest intervals (rates:
    ``Monitor.live_findings``; judged over the whole run at the end)."""
    silent_since: float | None = None
    """The unit's last heartbeat while it is silent right now (``Linter.watch_silences``:
    more than 3 heartbeat periods), else None; at the end HB-010 or HB-012 judge it."""

    @property
    def status(self) -> str:
        """silent (now), FAIL, warn, ok (messages seen, or a commander) or - (nothing seen)."""
        if self.silent_since is not None:
            return "silent"
        if self.live or any(f.verdict == "fail" for f in self.findings):
            return "FAIL"
        if self.findings:
            return "warn"
        return "ok" if self.messages or self.party == Party.COMMANDER else "-"

    @property
    def failing(self) -> bool:
        """Fails a rule so far as the judge will say (or a rate is off right now), silent or
        not: what the terminal and ``/metrics`` call failing. A silence alone is no verdict
        yet (HB-010 judges it when it ends, HB-012 when it never does): it is ``status``
        silent, and ``waraps_lint_unit_up`` 0."""
        return bool(self.live) or any(f.verdict == "fail" for f in self.findings)

    @property
    def pseudo(self) -> bool:
        """Not a unit of the protocol: what no unit sent, or the units past the bound."""
        return self.unit in (NOT_A_UNIT, OTHER_UNITS)


def seen_fields(row: LintRow) -> dict[str, Any]:
    """A ``LintRow``'s fields, for a view's row that adds its own to them."""
    return {f.name: getattr(row, f.name) for f in dataclasses.fields(LintRow)}


def severity(f: Finding) -> tuple[int, int, str]:
    """Most severe first (``conclusion.TRIAGE``), then most violations."""
    return (triage_rank(f.rule, Verdict.FAIL if f.verdict == "fail" else Verdict.WARN),
            -f.count, f.rule)


def _levels(levels: Any, party: Party, messages: int) -> tuple[str, ...] | None:
    """None only for a unit that sent messages and no levels (no heartbeat yet)."""
    if levels:
        return tuple(levels)
    return None if party == Party.UNIT and messages else ()


def live_rows(linter: Any, evidence: Mapping[tuple[str, str], Violation] | None = None,
              *, live: bool = True) -> list[LintRow]:
    """Every unit and commander seen so far, from the ``Linter``: a violation fails as the
    judge will say at the end (``Linter.is_error``). ``evidence``: (unit, rule) -> the first
    violation; ``live`` False: no live findings (the rates over the whole run)."""
    monitor = linter.monitor
    # As the judge will: a rule of whose unit only decided conditions were found warns
    # (``Linter.is_error(rule, unit)``); a live finding by its own condition (``fails``).
    fails: Callable[[str, str | None], bool] = cache(linter.is_error)
    fails_now: Callable[[Violation], bool] = getattr(linter, "fails", lambda v: fails(v.rule,
                                                                                     None))
    untimed = bool(getattr(monitor, "untimed", False))  # a capture without times
    rows: dict[str, LintRow] = {}
    silent: Mapping[str, float] = getattr(linter, "silent", {}) if live else {}
    for unit in list(monitor.units()):
        state: Any = monitor.state(unit)
        address = getattr(state, "address", None)
        key = str(address if address is not None else unit)
        count = int(getattr(state, "message_count", 0) or 0)
        rows[key] = LintRow(
            key, Party.UNIT, str(getattr(state, "agent_type", "") or ""),
            str(getattr(address, "role", "") or ""),
            _levels(getattr(state, "levels", None), Party.UNIT, count), count,
            None if untimed else getattr(state, "first_seen", None),
            None if untimed else getattr(state, "last_seen", None),
            live=tuple(v.rule for v in monitor.live_findings(unit) if fails_now(v))
            if live else (), silent_since=silent.get(key))
    for label in getattr(monitor, "commanders", list)():  # a row each, clean or not
        rows[label] = LintRow(label, Party.COMMANDER, "commander", levels=())
    for unit, counts in list(linter.by_unit.items()):
        party = Party.UNIT if unit in (NOT_A_UNIT, OTHER_UNITS) else Party.COMMANDER
        row = rows.get(unit) or LintRow(unit, party, "" if party == Party.UNIT else "commander",
                                        levels=())
        found = (Finding(rule, "fail" if fails(rule, unit) else "warn", n,
                         (evidence or {}).get((unit, rule))) for rule, n in counts.items())
        rows[unit] = dataclasses.replace(row, findings=tuple(sorted(found, key=severity)))
    return list(rows.values())


def report_rows(report: Any) -> list[LintRow]:
    """Every unit and commander of a ``RunReport``, every verdict final: a finding per rule
    that fails or warns, with its counted violations (else those the verdict holds)."""
    untimed = facts_of(report).untimed  # the reading's times are not the traffic's
    rows = []
    for unit, u in report.units.items():
        found = [Finding(rule, res.verdict.value,
                         u.violation_counts.get(rule, len(res.violations)),
                         res.violations[0] if res.violations else None, res.reason)
                 for rule, res in u.rules.items() if res.verdict.value in ("fail", "warn")]
        rows.append(LintRow(
            unit, u.party, "commander" if u.party == Party.COMMANDER else u.agent_type, u.role,
            _levels(u.levels, u.party, u.message_count), u.message_count,
            None if untimed else u.first_seen, None if untimed else u.last_seen,
            tuple(sorted(found, key=severity))))
    return rows

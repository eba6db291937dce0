"""What a run concludes: the one verdict model (docs/ARCHITECTURE.md 'Verdicts').

The judge (``conformance.judge.judge``) calls ``conclude`` once, on the judged report and the
run's typed facts (``report.facts``: ``conformance.facts.RunFacts``), and stores the result in
``report.conclusion``; every output (the suite's terminal summary and JUnit properties, the
JSON, HTML and JUnit reports, lint's text) and the exit status read that one (``of``).

A level is **certified** only when the run is a complete certification (``RunFacts.complete``)
and every rule of that level (the catalogue's ``level``) was judged on evidence: none failed,
none could not be tested; a rule that holds for every level (no ``level``: topics,
heartbeat, death, reboot) failing or not tested denies every level (REBOOT-* without
--reboot-cmd: no level is certified). Skips (not claimed, not applicable) do not count
against a level; a rule of a claimed level that needs a command and saw none it applies to
is no skip but could-not-test (the judge's: the suite did not provoke its evidence). A
complete run in which no rule failed exits 0 only when every level its unit claims is
certified, else ``EXIT_UNTESTED`` (7: a gate must not read it as certified). A run that
selected rules or was cut short is **partial**: its verdict is never
``pass``. Lint observes traffic it never caused: it says what it saw ("clean for 10 min,
never commanded"), never "certified".
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

from conformance.exits import (  # noqa: F401 (their one home; read here by the outputs)
    EXIT_CERTIFIED,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_LINT_PARTIAL,
    EXIT_NOT_CERTIFIED,
    EXIT_UNTESTED,
)
from conformance.facts import Gate, RunFacts, RunKind, iso
from conformance.results import Party, RunReport, UnitReport
from conformance.rules import CATALOGUE, Mode
from conformance.topics import level_name
from conformance.violation import RuleResult, Verdict


class RunVerdict(enum.StrEnum):
    """A run's verdict, and a row's, in the words every output shows: a rule's verdict
    (``Verdict``'s words), or a word only a run has. A ``StrEnum``: it prints, serialises and
    compares as that word."""

    PASS = "pass"
    SKIP = "skip"
    COULD_NOT_TEST = "could-not-test"
    WARN = "warn"
    FAIL = "fail"
    NOT_CERTIFIED = "not certified"
    """The broker or the unit could not be reached, or the broker was lost for good."""
    INTERRUPTED = "interrupted"
    PARTIAL = "partial"
    """Selected rules ran and none failed: not a certificate."""
    CLEAN = "clean"
    """Lint's verdict when nothing failed or warned: what was observed, not a certificate."""

    @classmethod
    def of(cls, verdict: Verdict) -> RunVerdict:
        return cls(verdict.value)


CERTIFIED = "certified"
"""What a level is when the run earned it (a level's status, a unit's summary)."""
NOT_CERTIFIED = RunVerdict.NOT_CERTIFIED
INTERRUPTED = RunVerdict.INTERRUPTED
PARTIAL = RunVerdict.PARTIAL
NOT_RUN = "not run"
"""The count of the rules that never ran (a selection, a run cut short)."""
CLEAN = RunVerdict.CLEAN

LINT_NEVER_CERTIFIES = "lint observes; only a complete pytest --unit run certifies"


@dataclass(frozen=True)
class LevelStatus:
    """One level a unit declares: certified, or not and why."""

    level: str
    certified: bool
    why: str = ""

    def __str__(self) -> str:
        return (f"{self.level} — {CERTIFIED}" if self.certified
                else f"{self.level} — {NOT_CERTIFIED}: {self.why}")

    def to_dict(self) -> dict[str, Any]:
        return {"level": self.level, "certified": self.certified, "why": self.why}


@dataclass(frozen=True)
class UnitStatus:
    """One row of the report: its worst rule verdict, a sentence for people, its levels."""

    unit: str
    party: Party
    verdict: RunVerdict
    summary: str
    """``certified: sensor, direct execution``; ``not certified: 1 failed, 2 could not be
    tested; the unit died at ...``; lint: ``clean for 10 min, never commanded``."""
    levels: tuple[LevelStatus, ...] = ()
    died_at: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "summary": self.summary, "died_at": self.died_at,
                "levels": [lv.to_dict() for lv in self.levels]}


@dataclass(frozen=True)
class Conclusion:
    """A run's conclusion: its verdict, whether it is partial and why, its exit status."""

    kind: RunKind
    verdict: RunVerdict
    partial: bool
    why: tuple[str, ...]
    """Why the run is partial or not certified (empty for a complete run)."""
    exit_code: int
    units: dict[str, UnitStatus] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    """(unit, rule) results per verdict, the rules that never ran apart as ``not run``: the
    counts every output shows."""
    strict: bool = False
    """Decided rules failed instead of warning (``--strict-rules``, ``strict: true``)."""
    judged_after_test: tuple[str, ...] = ()
    """Rules that failed on the whole run although their test passed when it ran (traffic
    after it is evidence too)."""

    def certified_levels(self, unit: str) -> list[str]:
        found = self.units.get(unit)
        return [lv.level for lv in found.levels if lv.certified] if found else []

    def headline(self) -> str:
        """The verdict and, when the run is partial or not certified, why (one line, each
        word once: ``interrupted (Ctrl-C)``, ``partial (only the selected rules ran: -k
        HB-003)``)."""
        return self.verdict + (f" ({'; '.join(self.why)})" if self.why else "")

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "partial": self.partial, "why": list(self.why),
                "exit_code": self.exit_code, "counts": dict(self.counts),
                "strict": self.strict, "judged_after_test": list(self.judged_after_test),
                "units": {name: u.to_dict() for name, u in self.units.items()}}


def of(report: RunReport) -> Conclusion:
    """The conclusion the judge stored in ``report`` (or, for a report made without the judge,
    such as one read back from an older file, the same computation)."""
    found = report.conclusion
    return found if isinstance(found, Conclusion) else conclude(report)


def facts_of(report: RunReport) -> RunFacts:
    """The run's facts (the defaults of its kind when it was never judged)."""
    return report.facts if report.facts is not None else RunFacts(kind=report.kind)


def conclude(report: RunReport) -> Conclusion:
    """The conclusion of ``report`` under its facts (module docstring)."""
    facts = facts_of(report)
    if report.kind == RunKind.LINT:
        return _conclude_lint(report, facts)
    why = facts.reasons()
    worst = report.worst()
    unread = _not_examined([u for u in report.units.values() if u.party == Party.UNIT])
    if facts.error or facts.broker_lost is not None:
        verdict, code = NOT_CERTIFIED, EXIT_NOT_CERTIFIED
    elif facts.interrupted:
        verdict, code = INTERRUPTED, EXIT_INTERRUPTED
    elif worst is Verdict.FAIL:
        verdict, code = RunVerdict.FAIL, EXIT_FAILED
    elif unread:  # never a pass, a warn or a could-not-test with exit 0 (bounds.py)
        verdict, code = NOT_CERTIFIED, EXIT_NOT_CERTIFIED
    elif why:
        verdict, code = PARTIAL, EXIT_CERTIFIED  # no selected rule failed; not a certificate
    else:
        verdict, code = RunVerdict.of(worst), EXIT_CERTIFIED
    not_run = set(report.not_run)
    units = {name: _certification_unit(name, u, why, not_run, facts.unexplored)
             for name, u in report.units.items()}
    told = (*why, unread) if unread and verdict == NOT_CERTIFIED else tuple(why)
    if code == EXIT_CERTIFIED and not why and not _all_certified(units, facts.unit):
        code = EXIT_UNTESTED  # complete, nothing failed, yet a claimed level not certified
    return Conclusion(report.kind, verdict, bool(why), told, code, units, counts(report),
                      facts.strict, _judged_after_test(report, facts))


def _all_certified(units: dict[str, UnitStatus], unit: str) -> bool:
    """Every level the unit under test claims is certified (the unit's row; without the
    run's facts, every row of a unit): what exit status 0 of a complete run says."""
    rows = [units[unit]] if unit in units else [u for u in units.values() if u.party == "unit"]
    return bool(rows) and all(u.levels and all(lv.certified for lv in u.levels) for u in rows)


def _judged_after_test(report: RunReport, facts: RunFacts) -> tuple[str, ...]:
    """Rules shown passing when their test ran that the whole run fails (12.1: a later
    scenario's command left unanswered is evidence too)."""
    unit = report.units.get(facts.unit)
    if unit is None:
        return ()
    return tuple(sorted(r for r in facts.enacted_pass
                        if r in unit.rules and unit.rules[r].verdict is Verdict.FAIL))


def counts(report: RunReport) -> dict[str, int]:
    """Verdict counts, with the rules that never ran counted as ``not run`` (they are
    recorded could-not-test, reason 'not run: ...')."""
    found = dict(report.verdict_counts())
    not_run = len(report.not_run)
    if not_run:
        found[Verdict.COULD_NOT_TEST.value] -= not_run
        found[NOT_RUN] = not_run
    return found


def died_at(unit: UnitReport, verdict: Verdict = Verdict.FAIL) -> float | None:
    """When the unit died (its last heartbeat before HB-012's silence), None if it did not;
    with ``verdict`` WARN, when its heartbeat stopped for good with no command before it
    (HB-012's decided 'no-command': switched off, or gone)."""
    result = unit.rules.get("HB-012")
    if result is None or result.verdict is not verdict:
        return None
    times = [v.time for v in result.violations if v.time is not None]
    if times:
        return min(times)
    first = unit.violation_times.get("HB-012")
    return first[0] if first else None


def _certification_unit(name: str, unit: UnitReport, run_why: list[str],
                        not_run: set[str], unexplored: str = "") -> UnitStatus:
    worst = RunVerdict.of(unit.worst())
    if unit.party != Party.UNIT:
        return UnitStatus(name, unit.party, worst, worst)
    died = died_at(unit)
    general = [r for r in unit.rules.values() if _level_of(r.rule) is None]
    levels = []
    for level in dict.fromkeys(map(level_name, unit.levels)):  # ERR-008
        own = [r for r in unit.rules.values() if _level_of(r.rule) == level]
        # A rule of every level (topics, heartbeat, reboot) counts against each of them.
        failed = sum(r.verdict is Verdict.FAIL for r in own + general)
        untested = sum(r.verdict is Verdict.COULD_NOT_TEST and r.rule not in not_run
                       for r in own + general)
        unrun = sum(r.rule in not_run and r.verdict is not Verdict.FAIL for r in own)
        why = _counted(failed=failed, untested=untested, unrun=unrun)
        if died is not None:
            why.append(f"the unit died at {iso(died)}")
        if not_examined(unit):
            why.append(f"{not_examined(unit)} message(s) could not be examined whole "
                       f"({NOT_EXAMINED_RULE})")
        why += run_why
        levels.append(LevelStatus(level, not why, "; ".join(why)))
    certified = [lv.level for lv in levels if lv.certified]
    if levels and len(certified) == len(levels):
        summary = f"{CERTIFIED}: {', '.join(certified)}"
    elif not levels:
        summary = f"{NOT_CERTIFIED}: it declares no level"
    else:
        failed = sum(r.verdict is Verdict.FAIL for r in unit.rules.values())
        untested = sum(r.verdict is Verdict.COULD_NOT_TEST and r.rule not in not_run
                       for r in unit.rules.values())
        unrun = sum(r.rule in not_run and r.verdict is not Verdict.FAIL
                    for r in unit.rules.values())
        why = _counted(failed=failed, untested=untested, unrun=unrun)
        if died is not None:
            why.append(f"the unit died at {iso(died)}")
        if not_examined(unit):
            why.append(f"{not_examined(unit)} message(s) could not be examined whole "
                       f"({NOT_EXAMINED_RULE})")
        summary = f"{NOT_CERTIFIED}: " + "; ".join(why + run_why or ["see the levels"])
        if certified:
            summary += f" (certified: {', '.join(certified)})"
    if unexplored:  # never silent: its orders of commands were not explored
        summary += f"; exploration not run: {unexplored}"
    return UnitStatus(name, unit.party, worst, summary, tuple(levels), died)


def _counted(*, failed: int, untested: int, unrun: int) -> list[str]:
    counts = ", ".join(text for n, text in ((failed, f"{failed} failed"),
                                             (untested, f"{untested} could not be tested"),
                                             (unrun, f"{unrun} not run")) if n)
    return [counts] if counts else []


def _level_of(rule: str) -> str | None:
    found = CATALOGUE.get(rule)
    return found.spec_level if found is not None else None


# --- lint: what was observed -----------------------------------------------------------------
def _conclude_lint(report: RunReport, facts: RunFacts) -> Conclusion:
    """Lint's verdict: ``fail`` when a row the gate looks at fails a rule (or units past the
    bound were not judged: never a pass), ``warn``, else ``clean``; exit 1 on ``fail``."""
    rows = [u for u in report.units.values() if facts.gate == Gate.ALL or u.party == Party.UNIT]
    worst = Verdict.worst([u.worst() for u in rows])
    failed = worst is Verdict.FAIL or bool(facts.not_judged)
    unread = [why for why in (facts.not_examined, _not_examined(rows)) if why]
    verdict = (RunVerdict.FAIL if failed else PARTIAL if unread else
               RunVerdict.WARN if worst is Verdict.WARN else CLEAN)
    why = ((facts.not_judged,) if facts.not_judged else ()) + tuple(unread)
    units = {name: _lint_unit(name, u, untimed=facts.untimed) for name, u in report.units.items()}
    code = EXIT_FAILED if failed else EXIT_LINT_PARTIAL if unread else EXIT_CERTIFIED
    return Conclusion(report.kind, verdict, bool(unread), why, code,
                      units, counts(report), facts.strict)


NOT_EXAMINED_RULE = "MSG-004"
"""A message past the examinable size or nesting (MSG-004) was not examined whole: what it
held is no evidence of anything, so its unit is never clean (bounds.py)."""


def not_examined(unit: UnitReport) -> int:
    """How many of the unit's messages could not be examined whole (MSG-004)."""
    return int(unit.violation_counts.get(NOT_EXAMINED_RULE, 0))


def _not_examined(rows: list[UnitReport]) -> str:
    found = [n for n in map(not_examined, rows) if n]
    return (f"{sum(found)} message(s) of {len(found)} unit(s) or commander(s) could not be "
            f"examined whole (past the size or nesting bound, {NOT_EXAMINED_RULE})"
            if found else "")


def commands_seen(unit: UnitReport) -> int:
    """How many commands to the unit the observer saw (exec and TST)."""
    return sum(n for kind, n in unit.facts.message_counts.items()
               if kind in ("exec/command", "tst/command") or kind.startswith(
                   ("exec/command/", "tst/command/")))


UNTIMED_SPAN = "no times in the capture"
"""What lint says instead of a duration when the traffic had no recorded times (a
``mosquitto_sub -v`` capture): its arrival times are the reading's, not the traffic's."""


def _lint_unit(name: str, unit: UnitReport, *, untimed: bool = False) -> UnitStatus:
    worst = unit.worst()
    failed = sum(r.verdict is Verdict.FAIL for r in unit.rules.values())
    warned = sum(r.verdict is Verdict.WARN for r in unit.rules.values())
    span = ((unit.last_seen or 0.0) - (unit.first_seen or 0.0)) if unit.first_seen else 0.0
    unread = not_examined(unit)
    verdict = (RunVerdict.FAIL if worst is Verdict.FAIL else RunVerdict.COULD_NOT_TEST if unread
               else RunVerdict.WARN if worst is Verdict.WARN else CLEAN)
    unread_said = (f"; {unread} message(s) could not be examined whole ({NOT_EXAMINED_RULE})"
                   if unread else "")
    if unit.party != Party.UNIT:
        said = (f"{failed} rule(s) failed" if failed else
                f"{warned} rule(s) warned" if warned else CLEAN)
        return UnitStatus(name, unit.party, RunVerdict.of(worst) if verdict == CLEAN else verdict,
                          f"{said}: what it sent, observed{unread_said}")
    n = commands_seen(unit)
    commanded = "never commanded" if not n else f"{n} command{'s' * (n != 1)} seen"
    died = died_at(unit)
    found = ", ".join(t for c, t in ((failed, f"{failed} rule(s) failed"),
                                     (warned, f"{warned} rule(s) warned")) if c)
    if untimed:  # never 'clean for 0 s': the reading's times are not the traffic's
        summary = f"{found or CLEAN} ({UNTIMED_SPAN}), {commanded}"
    else:
        summary = (f"{found} in {duration(span)} observed" if found
                   else f"{CLEAN} for {duration(span)}") + f", {commanded}"
    if died is not None:
        summary += f"; it died at {iso(died)}"
    elif (stopped := died_at(unit, Verdict.WARN)) is not None:
        summary += f"; its heartbeat stopped at {iso(stopped)} (no command before it)"
    summary += unread_said
    levels = tuple(LevelStatus(lv, False, LINT_NEVER_CERTIFIES)
                   for lv in dict.fromkeys(map(level_name, unit.levels)))
    return UnitStatus(name, unit.party, verdict, summary, levels, died)


# --- triage: the most severe findings first ---------------------------------------
TRIAGE = ("death", "deafness", "commands", "messages", "warnings")
"""The severity classes, most severe first: a unit that died (HB-012), a unit that stopped
answering (EXEC-ROBUST-001), commands answered wrongly or not at all (conversation and active
rules), then what a message looks like (the passive rules), then warnings."""


def triage_rank(rule: str, verdict: Verdict) -> int:
    """The index in ``TRIAGE`` of a failed or warned rule."""
    if verdict is not Verdict.FAIL:
        return TRIAGE.index("warnings")
    if rule == "HB-012":
        return TRIAGE.index("death")
    if rule == "EXEC-ROBUST-001":
        return TRIAGE.index("deafness")
    found = CATALOGUE.get(rule)
    if found is not None and found.mode in (Mode.CONVERSATION, Mode.ACTIVE):
        return TRIAGE.index("commands")
    return TRIAGE.index("messages")


def ranked_findings(report: RunReport) -> list[tuple[int, str, RuleResult]]:
    """(triage rank, unit, result) of every failed or warned rule, most severe first: a cap
    on what is shown cuts the least severe."""
    found = [(triage_rank(r.rule, r.verdict), name, r) for name, u in report.units.items()
             for r in u.rules.values() if r.verdict in (Verdict.FAIL, Verdict.WARN)]
    return sorted(found, key=lambda f: (f[0], f[1], f[2].rule))


def duration(seconds: float) -> str:
    """``42 s``, ``1 min 5 s``, ``2 h 3 min`` for people."""
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min" + (f" {s % 60} s" if s % 60 else "")
    return f"{s // 3600} h" + (f" {s % 3600 // 60} min" if s % 3600 // 60 else "")


"""Active scenarios: the stimuli the certification suite sends to the unit under test, and the
expectations it checks.

Each scenario drives the unit through one part of spec 12 (``tst``: spec 14) and records a verdict for each of
its rules through ``Context.record``, the same way the passive checks do. ``SCENARIOS`` lists
them in the order the suite runs them: reboot last, because it wipes the unit's history; the
probes that may kill a faulty unit (refuse's invalid parameters, which killed the public L2
agents in some runs, and robust's malformed commands) after the scenarios whose evidence a
death would destroy (signal, query, resend, tst). A unit that died is restarted before the
next scenario where the run can reboot it (``suite/scenario_run.py`` ``revive``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from conformance.scenarios import ping, query, reboot, resend, robust, signal, start, tst
from conformance.scenarios.commander import Commander
from conformance.scenarios.context import Context, Timing
from conformance.scenarios.safety import Position, Safety
from conformance.scenarios.sender import DryRun, NotSent, Refused
from conformance.scenarios.traffic import Entry, Traffic
from conformance.scenarios.tst_commander import TstCommander
from conformance.topics import DIRECT_EXECUTION, TST_EXECUTION


@dataclass(frozen=True)
class Scenario:
    """A named driver, the rule ids it judges, and the level the unit must declare for it."""

    name: str
    rules: tuple[str, ...]
    run: Callable[[Context], None]
    level: str | None = DIRECT_EXECUTION
    doc: str = ""
    needs: tuple[str, ...] = ()
    """Scenarios whose outcome this one works on (run first, once)."""


SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    Scenario("ping", ping.RULES, ping.run, doc="ping is answered with pong (12.2.1)"),
    Scenario("start", start.RULES, start.run,
             doc="start-task of every task the profile allows (12.2.3, 12.4, 5.3)"),
    Scenario("signal", signal.RULES, signal.run, doc="every signal the unit lists (12.2.2)"),
    Scenario("query", query.RULES, query.run, doc="query-status over the history (12.1)"),
    Scenario("resend", resend.RULES, resend.run,
             doc="a resent command is answered again, executed once (12.1)"),
    Scenario("tst", tst.RULES, tst.run, level=TST_EXECUTION,
             doc="TST trees, signals at node, tree and unit level, refusals, a resend (14)"),
    Scenario("refuse", start.REFUSAL_RULES, start.run_refusals,
             doc="invalid parameters and unknown tasks are refused (12.1)"),
    Scenario("robust", robust.RULES, robust.run,
             doc="malformed and unknown commands do not stop the unit (12.1)"),
    Scenario("reboot", reboot.RULES, reboot.run, level=None,
             doc="a reboot gives a new agent-uuid and forgets the history (5, 12.1)",
             needs=("start",)),  # REBOOT-002 asks about tasks that ended before it
)}

RULE_SCENARIO: dict[str, str] = {rule: s.name for s in SCENARIOS.values() for rule in s.rules}

# Passive rules that judge answers to commands: the scenarios whose traffic is their evidence
# (so that selecting one of them alone, `-k EXEC-FB-002` or `--rule EXEC-FB-002`, still sends
# the stimulus).
EVIDENCE: dict[str, tuple[str, ...]] = {
    "EXEC-002": ("ping", "start"), "EXEC-003": ("start",), "EXEC-004": ("ping", "start"),
    "EXEC-005": ("ping", "start"), "EXEC-006": ("ping", "start", "robust"), "EXEC-007": ("refuse",),
    "EXEC-FB-001": ("start",), "EXEC-FB-002": ("start",), "EXEC-FB-003": ("start",),
    "EXEC-FB-004": ("start",), "ERR-006": ("query",), "ERR-013": ("signal",),
    "ERR-014": ("start",), "EXEC-009": ("ping", "start"), "EXEC-010": ("ping",),
    "HB-012": ("start",), "TST-002": ("tst",), "TST-003": ("tst",), "ERR-015": ("tst",),
    "EXEC-SEQ-001": ("signal",), "EXEC-SEQ-002": ("signal",), "EXEC-RESEND-003": ("resend",),
    "DEI-004": ("refuse",),
}


def scenarios_for(rule: str) -> tuple[str, ...]:
    """The scenarios that produce the evidence of ``rule``, in the order they run."""
    names = set(EVIDENCE.get(rule, ()))
    if rule in RULE_SCENARIO:
        names.add(RULE_SCENARIO[rule])
    for name in list(names):
        names.update(SCENARIOS[name].needs)
    return tuple(n for n in SCENARIOS if n in names)


__all__ = ["SCENARIOS", "RULE_SCENARIO", "EVIDENCE", "scenarios_for", "Scenario", "Context",
           "Timing", "Commander", "DryRun", "NotSent", "Refused", "Safety", "Position", "Traffic", "Entry",
           "TstCommander"]

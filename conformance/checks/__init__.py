"""Passive checks: history-dependent rules judged over a stream of messages, per unit.

``Monitor`` is the one entry point, shared by the linter and the certification suite. The
checks are registered by rule id (``conformance.checks.registry``), one module per spec
area: ``rates`` (HB-003, SI-002, DEI-002, TEI-002), ``identity`` (HB-006, HB-008, HB-010,
HB-011, HB-012, MSG-007; the liveness they measure in ``liveness``), ``sensors`` (SI-003, SI-004, SI-005, SENS-005), ``execution``
(EXEC-004, EXEC-FB-003), ``levels`` (HB-013), the conversations of spec 12 (every command, its
answers, the task it started; EXEC-006, EXEC-008, EXEC-FB-004 and the rest of 12):
``exec_command``, ``exec_response``, ``exec_feedback``, ``exec_deadline`` on the state of
``conversation``, whose tasks are the unit's model of ``conformance.protocol`` (one store),
which ``exec_sequence`` feeds first and judges by (EXEC-SEQ-*); and the same one level up,
spec 14 (TST-004, TST-006..TST-013):
``tst_command``, ``tst_response``, ``tst_feedback``, ``tst_deadline`` on the state of
``tst_conversation`` (commands on an operator's tst/command are attributed by ``tst_routing``).
What exec and TST conversations share is ``command_history``'s.
"""

from __future__ import annotations

# The order registers the checks, so it is the order they run on one message: the model of
# direct execution is fed first (the conversations read its tasks), a conversation is followed
# before HB-013 looks at what the unit acted on, both before the other checks.
# isort: off
from conformance.checks import (  # noqa: F401  (registers)
    exec_sequence,
    exec_command,
    exec_response,
    exec_feedback,
    levels,
    exec_deadline,
    execution,
    identity,
    rates,
    sensors,
    tst_command,
    tst_response,
    tst_feedback,
    tst_deadline,
)
# isort: on
from conformance.checks.base import CheckContext, UnitState
from conformance.checks.monitor import Monitor
from conformance.checks.registry import Check, Registry, build, check, covered_rules

# Every check module is imported above (and the Monitor built the registry from them).
CHECKS = build().by_rule
"""Rule id -> the checks implementing it."""

__all__ = ["CHECKS", "Check", "CheckContext", "Monitor", "Registry", "UnitState", "check",
           "covered_rules"]

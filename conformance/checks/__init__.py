"""Passive checks: history-dependent rules judged over a stream of messages, per unit.

``Monitor`` is the one entry point, shared by the linter and the certification suite. The
checks are registered by rule id (``conformance.checks.base.CHECKS``), one module per spec
area: ``rates`` (HB-003, SI-002, DEI-002, TEI-002), ``identity`` (HB-006, HB-008, HB-010,
HB-011, HB-012, MSG-007), ``sensors`` (SI-003, SI-004, SI-005, SENS-005), ``execution``
(EXEC-004, EXEC-FB-003) and ``conversation`` (every command, its answers, the task it started:
the conversation rules of spec 12, EXEC-006, EXEC-008, EXEC-FB-004, HB-013).
"""

from __future__ import annotations

from conformance.checks import (  # noqa: F401  (registers)
    conversation,
    execution,
    identity,
    rates,
    sensors,
)
from conformance.checks.base import CHECKS, Check, CheckContext, UnitState, check, covered_rules
from conformance.checks.monitor import Monitor

__all__ = ["CHECKS", "Check", "CheckContext", "Monitor", "UnitState", "check", "covered_rules"]

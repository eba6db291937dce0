"""Levels say what a unit does (5.1): one that acts on a level its heartbeat does not declare
is passed over by every commander that reads them (HB-013)."""

from __future__ import annotations

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import violation
from conformance.checks.conversation import CONVERSATIONS, conversations
from conformance.checks.registry import check
from conformance.message import Message
from conformance.topics import DIRECT_EXECUTION, INFO_KIND_OF_LEVEL, TST_EXECUTION, TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

# The level of 5.1 each message a unit publishes acts on: its info message, its answers.
_LEVEL_OF_KIND = {
    **{kind: level for level, kind in INFO_KIND_OF_LEVEL.items()},
    TopicKind.EXEC_RESPONSE: DIRECT_EXECUTION, TopicKind.EXEC_FEEDBACK: DIRECT_EXECUTION,
    TopicKind.TST_RESPONSE: TST_EXECUTION, TopicKind.TST_FEEDBACK: TST_EXECUTION}


@check("HB-013", on=tuple(_LEVEL_OF_KIND), reads=(CONVERSATIONS,))
def acted_on_level_is_declared(ctx: CheckContext, unit: UnitState, msg: Message,
                               v: Validation) -> list[Violation] | None:
    """5.1: levels say what a unit does; one that acts on a level it does not declare is
    passed over by every commander that reads them (HB-013, once per level)."""
    levels = unit.levels
    if levels is None:
        return None
    level = _LEVEL_OF_KIND[v.topic.kind]
    if level in levels:
        unit.examine("HB-013")
        return None
    c = conversations(unit)
    if level in c.levels_reported:
        return None
    c.levels_reported.add(level)
    unit.examine("HB-013")
    return [violation("HB-013", msg, expected=f"'{level}' in the heartbeat's levels "
                      f"({', '.join(levels) or 'none declared'})",
                      observed=f"{v.topic.kind.value} published", path="$",
                      detail=f"declare '{level}' in levels, or do not act on it")]


"""Levels say what a unit does (5.1): one that acts on a level its heartbeat does not declare
is passed over by every commander that reads them (HB-013)."""

from __future__ import annotations

from conformance.checks.base import CheckContext, UnitState, check
from conformance.checks.command_history import violation
from conformance.checks.conversation import conversations
from conformance.message import Message
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation


@check("HB-013", on=(TopicKind.DIRECT_EXECUTION_INFO, TopicKind.EXEC_RESPONSE,
                     TopicKind.EXEC_FEEDBACK, TopicKind.SENSOR_INFO, TopicKind.TST_EXECUTION_INFO,
                     TopicKind.TST_RESPONSE, TopicKind.TST_FEEDBACK))
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


_LEVEL_OF_KIND = {
    TopicKind.DIRECT_EXECUTION_INFO: "direct execution", TopicKind.EXEC_RESPONSE:
    "direct execution", TopicKind.EXEC_FEEDBACK: "direct execution",
    TopicKind.SENSOR_INFO: "sensor", TopicKind.TST_EXECUTION_INFO: "tst execution",
    TopicKind.TST_RESPONSE: "tst execution", TopicKind.TST_FEEDBACK: "tst execution"}

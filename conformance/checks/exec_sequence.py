"""What the model of direct execution judges across steps (12.2.2; ``conformance.protocol``).

Every exec message of a unit is fed to its ``Model``; the findings it returns are the sequence
rules' (EXEC-SEQ-001: a task stops once $abort is accepted; EXEC-SEQ-002: a
signal changes only the task it names; EXEC-RESEND-001 where a resent signal is applied
again: ``conformance.sequence_rules``). The same code runs in ``lint`` and in ``pytest
--unit`` (and the exploration asks the same model what to expect), so lint of a recording and
the suite cannot disagree about a sequence. What the conversation checks already judge (answers,
final statuses, resends, query-status) stays theirs: the model adds only what needs the order
of commands across tasks.

The model is the unit's one store of tasks: it is made with the conversations
(``conversation.conversations``) and this check feeds it first, before the conversation checks
read what it holds (``checks/__init__.py`` registers it first). Its life is the conversations'
(``exec_deadline`` tells it a new one).
"""

from __future__ import annotations

import dataclasses

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import violation
from conformance.checks.conversation import CONVERSATIONS, conversations
from conformance.checks.registry import check
from conformance.message import Message
from conformance.protocol import BUILTIN_SIGNALS, Command, Model, State
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation

DETAIL = {
    "EXEC-SEQ-001": "12.2.2: once $abort is acknowledged the task ends; do not resume or "
                    "keep running it (a paused task too)",
    "EXEC-SEQ-002": "12.2.2: apply a signal to the task-uuid it names, not to every task "
                    "(or to the vehicle)",
    "EXEC-RESEND-001": "12.1: a resent signal-task (its com-uuid) is answered again, not "
                       "applied again",
}


def model_of(ctx: CheckContext, unit: UnitState) -> Model:
    """The unit's model of direct execution, made with its conversations on first use
    (public: the explorer's view of what the Monitor holds)."""
    return conversations(unit, ctx).model


def state_held(unit: UnitState, task_uuid: str) -> State:
    """The model's state of ``task_uuid``: ``State.UNKNOWN`` where it holds nothing, or where
    no model was made (a reader makes none). The suite's view of what the Monitor holds (its
    commander and explorer), read under the lock that feeds the Monitor."""
    c = unit.stash.get(CONVERSATIONS)
    return c.model.state(task_uuid) if c is not None else State.UNKNOWN


@check("EXEC-SEQ-001", "EXEC-SEQ-002", "EXEC-RESEND-001",
       on=(TopicKind.EXEC_COMMAND, TopicKind.EXEC_RESPONSE, TopicKind.EXEC_FEEDBACK),
       reads=(CONVERSATIONS,))
def sequence_follows_model(ctx: CheckContext, unit: UnitState, msg: Message,
                           v: Validation) -> list[Violation] | None:
    """Feed the model (first: the conversation checks read what it holds); report what it
    finds."""
    model = model_of(ctx, unit)
    kind, m, t = v.topic.kind, v.message, msg.time
    if kind is TopicKind.EXEC_COMMAND:
        cmd = Command.read(m) if isinstance(m, dict) else None
        if cmd is not None:
            model.command(cmd, t)
        return None
    if kind is TopicKind.EXEC_RESPONSE:
        model.response(m, t)
        _examine_signal(unit, model, m)
        return None
    found = model.feedback(m, t)
    if not found:
        return None
    return [dataclasses.replace(violation(f.rule, msg, expected=f.expected, observed=f.observed,
                                          path="$.status", detail=DETAIL.get(f.rule, "")),
                                condition=f.condition) for f in found]


def _examine_signal(unit: UnitState, model: Model, m: object) -> None:
    """A builtin signal accepted (any answer but 'failed') for a task the model knows is judged from here on:
    EXEC-SEQ-001 for $abort, EXEC-SEQ-002 for every one."""
    to = m.get("response-to") if isinstance(m, dict) else None
    cmd = model.commands.get(to) if isinstance(to, str) else None
    if cmd is None or cmd.name != "signal-task" or cmd.signal not in BUILTIN_SIGNALS:
        return
    task = model.task(cmd.task_uuid)
    if task is None or not task.acked or task.acked[-1][2] != to:
        return
    unit.examine("EXEC-SEQ-002")
    if cmd.signal == "$abort":
        unit.examine("EXEC-SEQ-001")

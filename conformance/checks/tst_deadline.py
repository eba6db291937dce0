"""Deadlines of TST conversations, judged on the unit's heartbeats and at the end (14.4, 14.5).

Answers due (a resend left unanswered: TST-007; a command never answered: TST-004, TST-011),
the status a signal's 'ok' implies (TST-012), the final status of a node that left
nodes-executing, whose children all ended or whose parent ended (TST-009). A new agent-uuid is
a new life: its trees are forgotten (TST-011's decision), and what the old one left open is not
judged; commands a dead unit (HB-012) left unanswered are its death's.
"""

from __future__ import annotations

from collections.abc import Iterator

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import (
    OVER_A_GAP,
    judged_on_a_copy,
    late,
    resends_unanswered,
)
from conformance.checks.liveness import IDENTITY, dying_at_end, dying_before_life
from conformance.checks.registry import check
from conformance.checks.tst_conversation import (
    ANSWER_RULE,
    TST_CONVERSATIONS,
    TstCommand,
    TstConversations,
    own_deadline,
    runs,
)
from conformance.checks.tst_response import judge_unanswered
from conformance.message import Message
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation


@check("TST-004", "TST-007", "TST-009", "TST-011", "TST-012", on=(TopicKind.HEARTBEAT,),
       reads=(TST_CONVERSATIONS, IDENTITY))
def tst_deadlines_pass(ctx: CheckContext, unit: UnitState, msg: Message,
                       v: Validation) -> list[Violation] | None:
    """Deadlines are checked on each heartbeat of the unit (and at the end). A new agent-uuid
    is a new life: its trees are forgotten (TST-011's decision), and what the old one left open
    is not judged. (Runs on every heartbeat: cheap when nothing is open.)"""
    c = unit.stash.get(TST_CONVERSATIONS)
    if c is None:
        return None
    m = v.message
    agent = m.get("agent-uuid") if type(m) is dict else None
    if type(agent) is str and agent != c.life and not msg.retain:
        found = _new_life(ctx, unit, c, msg.time) if c.life is not None \
            and agent not in c.lives else None
        c.begin_life(agent)
        return found
    if not (c.pending or c.expects or c.awaiting):
        return None
    return _expire(ctx, unit, c, msg.time) or None


def _new_life(ctx: CheckContext, unit: UnitState, c: TstConversations, t: float
              ) -> list[Violation] | None:
    dying = dying_before_life(unit, c, t)
    dead = dying[0] if dying is not None else None
    found = _expire(ctx, unit, c, t, reboot=True)
    streak, c.unanswered = c.unanswered, []
    found.extend(_judge_left_unanswered(ctx, unit, c, streak, dead))
    c.expects.clear()
    c.awaiting.clear()
    c.watch.clear()
    c.info_nodes = None
    return found or None


def _judge_left_unanswered(ctx: CheckContext, unit: UnitState, c: TstConversations,
                           left: list[TstCommand], dead: float | None) -> Iterator[Violation]:
    """The commands still unanswered when a life (or the observation) ends: each fails its
    rule, but those sent since the unit died (``dead``) are its death's (HB-012)."""
    for cmd in left:
        if dead is not None and cmd.last_sent >= dead:
            unit.note(ANSWER_RULE[cmd.name], "TST commands sent while the unit was dying or "
                                             "dead (HB-012)")
            continue
        yield from judge_unanswered(ctx, unit, c, cmd)


def _expire(ctx: CheckContext, unit: UnitState, c: TstConversations, now: float,
            reboot: bool = False) -> list[Violation]:
    found = resends_unanswered(ctx, unit, c, now, reboot, "TST-007", lambda cmd: cmd.topic,
                               "12.1: answer a resend again, as the first time")
    if reboot:
        return found
    for e in list(c.expects):
        if e.deadline >= now:
            continue
        c.expects.remove(e)
        if e.node.final is None and not runs(e.node):
            continue  # its children did as signalled; its own silence is TST-009's
        if ctx.gaps and ctx.in_gap(e.command.last_sent, e.deadline):
            unit.note("TST-012", OVER_A_GAP)  # the feedback may be what the broker lost
            continue
        unit.examine("TST-012")
        found.append(late("TST-012", e.command.topic, e.command, f"'{e.wanted}' for node "
                          f"{e.node.node_uuid} ('{e.node.name}') within "
                          f"{ctx.profile.feedback_timeout:.1f} s of the 'ok' to "
                          f"{e.command.describe()}", f"latest status {e.node.status!r}",
                          e.command.last_sent,
                          "14.3: do what the signal says, and say so in feedback"))
    for node in list(c.awaiting.values()):
        due = own_deadline(ctx, node)
        if due is None:
            c.awaiting.pop(node.node_uuid, None)
            continue
        if due >= now:
            continue
        c.awaiting.pop(node.node_uuid, None)
        if ctx.gaps and ctx.in_gap(node.status_time or due, due):
            unit.note("TST-009", OVER_A_GAP)  # its final status may be what the broker lost
            continue
        unit.examine("TST-009")
        if "TST-009" in node.judged:
            continue
        node.judged.add("TST-009")
        why = ("it left nodes-executing" if node.left_at is not None else
               "its children all ended" if node.ended_children_at is not None else
               "its parent ended")
        found.append(late("TST-009", node.tree.command.topic, node.tree.command, f"a final "
                          f"status for node {node.node_uuid} ('{node.name}')", f"{why}, and it "
                          f"said none (latest status {node.status!r})", due,
                          "14.5: every node reports its end (succeeded, failed, aborted or "
                          "revoked)"))
    return found


@check("TST-004", "TST-009", "TST-011", finish=True, reads=(TST_CONVERSATIONS, IDENTITY))
@judged_on_a_copy(TST_CONVERSATIONS, dropped=("TST-012", "open TST expectations"))
def tst_conversations_at_end(ctx: CheckContext, unit: UnitState, c: TstConversations,
                             now: float) -> list[Violation]:
    """At the end: answers still due are judged, but not those a unit that died left (HB-012's
    finding); trees still running are not judged; what the bounds dropped is said."""
    found = _expire(ctx, unit, c, now)
    dying = dying_at_end(ctx, unit, c, now)
    found.extend(_judge_left_unanswered(ctx, unit, c, c.unanswered,
                                        dying[0] if dying is not None else None))
    running = sum(1 for t in c.trees.values() if t.state == "started" and t.life == c.life
                  and t.ended_at is None)
    if running:
        unit.note("TST-009", f"{running} tree(s) still running when the observation ended: "
                             f"not judged")
    return found

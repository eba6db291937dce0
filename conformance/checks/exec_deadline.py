"""Deadlines of exec conversations, judged on the unit's heartbeats and at the end (12.1-12.4).

Answers due (a resend left unanswered: EXEC-RESEND-002), feedback an accepted signal implies
(12.2.2), the final feedback of a task that left tasks-executing (EXEC-START-003). A new
agent-uuid is a new life: what the old one left open is not judged (the reboot lost it).
Commands still unanswered when a life or the observation ends are judged here, each by its
own rule; a unit that answers none of two or more commands of different kinds (kinds it
answered before) sent after its last answer, while it still heartbeats past their deadline,
also stopped answering
(EXEC-ROBUST-001); the command a dying unit received last, and those after, are HB-012's.
"""

from __future__ import annotations

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import (
    OVER_A_GAP,
    judged_on_a_copy,
    late,
    resends_unanswered,
    response_timeout,
)
from conformance.checks.conversation import (
    ANSWER_RULE,
    CONVERSATIONS,
    FEEDBACK_WITHOUT_TASK_UUID,
    MALFORMED,
    Conversations,
    expects_answers,
    latest_status,
    state_of,
)
from conformance.checks.exec_response import judge_unanswered
from conformance.checks.liveness import IDENTITY, dying_at_end, dying_before_life
from conformance.checks.registry import check
from conformance.message import Message
from conformance.taskrecord import State
from conformance.topics import TopicKind
from conformance.validator import Validation
from conformance.violation import Violation, clock


@check("EXEC-RESEND-002", "EXEC-START-003", "EXEC-SIG-002", on=(TopicKind.HEARTBEAT,),
       reads=(CONVERSATIONS, FEEDBACK_WITHOUT_TASK_UUID, IDENTITY))
def deadlines_pass(ctx: CheckContext, unit: UnitState, msg: Message,
                   v: Validation) -> list[Violation] | None:
    """Deadlines are checked on each heartbeat of the unit (and at the end): answers due,
    feedback a signal implies, final feedback of a task that left tasks-executing. A new
    agent-uuid is a new life: what the old one left open is not judged (the reboot lost it).
    (Runs on every heartbeat: cheap when nothing is open.)"""
    c = unit.stash.get(CONVERSATIONS)
    if c is None:
        return None
    m = v.message
    agent = m.get("agent-uuid") if type(m) is dict else None
    if agent != c.life and type(agent) is str and not msg.retain:
        found = _new_life(ctx, unit, c, agent, msg.time) if c.life is not None else None
        c.begin_life(agent)
        return found
    last, period = unit.last_heartbeat, unit.period(TopicKind.HEARTBEAT)
    if (last is not None and period is not None and not unit.heartbeat_retained
            and msg.time - last > 2 * period):
        c.silent_until = msg.time
    if not (c.pending or c.expects or c.running):
        return None
    return _expire(ctx, unit, c, msg.time) or None


def _new_life(ctx: CheckContext, unit: UnitState, c: Conversations, agent: str, t: float
              ) -> list[Violation] | None:
    if agent in c.lives:
        return None  # an earlier uuid again: two agents under one name (HB-011), no reboot
    dead = dying_before_life(unit, c, t)
    found = _expire(ctx, unit, c, float("inf"), reboot=True, dead=dead)
    c.running.clear()  # what the old life ran is not judged (the reboot lost it)
    c.expects.clear()
    c.model.forget(agent, keep=True)  # 12.1: nor are its tasks known to the model
    return found


def _expire(ctx: CheckContext, unit: UnitState, c: Conversations, now: float,
            reboot: bool = False, dead: tuple[float, float] | None = None) -> list[Violation]:
    """Judge what is overdue at ``now`` (at a reboot: everything; ``dead``: when the unit
    began dying and its last heartbeat before it, see ``dead_since``)."""
    topic = unit.address.topic("exec/command")
    found = resends_unanswered(ctx, unit, c, now, reboot, "EXEC-RESEND-002", lambda _: topic,
                               "12.1: answer a resend again, with the first answer")
    timeout = response_timeout(ctx)
    if reboot:
        found.extend(_judge_streak(ctx, unit, c, ended_by="a reboot", dead=dead))
    for e in list(c.expects):
        if e.deadline < now or reboot:
            c.expects.remove(e)
            if reboot:
                continue
            if ctx.gaps and ctx.in_gap(e.command.last_sent, e.deadline):
                unit.note(e.rule, OVER_A_GAP)  # the feedback may be what the broker lost
                continue
            if unit.stash.get(FEEDBACK_WITHOUT_TASK_UUID):
                # The awaited status may have come in feedback naming no task (EXEC-FB-001's
                # finding): not judged, as a task's end is not (12.4;
                # docs/FIELD-NOTES.md 'Precision').
                unit.note(e.rule, "the unit sends feedback without a task-uuid: the status "
                                  "a signal awaits could not be tracked")
                continue
            unit.examine(e.rule)
            task = c.followed(e.task_uuid)
            said = latest_status(task) if task is not None else None
            waited = ctx.profile.task_feedback_timeouts.get(
                task.name or "" if task is not None else "", ctx.profile.feedback_timeout)
            found.append(late(e.rule, unit.address.topic("exec/command"), e.command,
                              f"{' or '.join(sorted(e.wanted))} within "
                              f"{waited:.1f} s of accepting "
                              f"{e.command.describe()}", f"latest status {said!r}",
                              e.command.last_sent, "12.2.2: do what the signal says, and "
                              "say so in feedback"))
    for task in c.open():
        # Left while paused is no end, unless it was listed paused (5.3; exec_feedback's
        # tasks_executing_follow_tasks).
        if task.left_at is not None and task.left_at + timeout < now and (
                task.listed_paused or state_of(task) is not State.PAUSED):
            c.ended(task, ("left tasks-executing", None, task.left_at))
            if unit.stash.get(FEEDBACK_WITHOUT_TASK_UUID):
                continue  # its final feedback may be one without task-uuid
            if ctx.gaps and ctx.in_gap(task.listed_at or task.left_at, task.left_at + timeout):
                # It ended while the broker lost or held traffic: its final feedback may have
                # been sent then (the broker killed 18 s into a run).
                unit.note("EXEC-START-003", OVER_A_GAP)
                continue
            unit.examine("EXEC-START-003")
            found.append(late("EXEC-START-003", unit.address.topic("exec/command"),
                              task.command, f"a final feedback for task {task.task_uuid} "
                              f"(finished, failed or aborted)", f"it left tasks-executing at "
                              f"{clock(task.left_at)} with none (latest status "
                              f"{latest_status(task)!r})", task.left_at,
                              "12.4: send feedback with the final status when a task ends"))
    return found


def _judge_streak(ctx: CheckContext, unit: UnitState, c: Conversations, *, ended_by: str,
                  dead: tuple[float, float] | None = None) -> list[Violation]:
    """The commands still unanswered when the life (or the observation) ends: each fails its
    own rule, and those sent after the unit's last answer, of two kinds or more, past their
    deadline while it still heartbeated, show it stopped answering (EXEC-ROBUST-001). Those
    from when it began dying (``dead``: since, last heartbeat) are its death's (HB-012)."""
    streak, c.unanswered = c.unanswered, []
    alive_until = None
    if dead is not None:
        since, alive_until = dead
        died = [cmd for cmd in streak if cmd.last_sent >= since]
        if died:
            unit.note(ANSWER_RULE.get(died[0].name, "EXEC-ROBUST-002"),
                      f"{len(died)} command(s) sent while the unit was dying or dead (HB-012)")
        streak = [cmd for cmd in streak if cmd.last_sent < since]
    found: list[Violation] = []
    timeout = response_timeout(ctx)
    # Answers in flight (docs/FIELD-NOTES.md 'Precision'): a command sent before the unit's last
    # answer says nothing about whether it still answers, only about itself. Nor does a kind
    # of command it never answered (docs/FIELD-NOTES.md 'Real agents certified live': kinds never
    # answered): that
    # fails its own rule from the first second; only the kinds it answered before can stop.
    after = [cmd for cmd in streak
             if (c.last_answer is None or cmd.last_sent > c.last_answer)
             and cmd.name in c.answered_kinds
             and (alive_until is None or cmd.last_sent + timeout <= alive_until)
             and not (ctx.gaps and ctx.in_gap(cmd.last_sent, cmd.last_sent + timeout))]
    kinds = {cmd.name for cmd in after}
    if len(after) >= 2 and len(kinds) >= 2 and expects_answers(unit, c):
        first = after[0]
        before = [cmd for cmd in c.commands.values() if cmd.last_sent < first.last_sent]
        cause = max(before, key=lambda cmd: cmd.last_sent) if before else None
        named = first if first.name == MALFORMED or cause is None else cause
        unit.examine("EXEC-ROBUST-001")
        found.append(late("EXEC-ROBUST-001", unit.address.topic("exec/command"), first,
                          f"answers to commands after {named.describe()}", f"none of the "
                          f"next {len(after)} commands ({', '.join(sorted(kinds))}) answered "
                          f"until {ended_by}", first.last_sent, f"the unit stopped answering "
                          f"after {named.describe()}; it must survive any command (12.1)"))
    # Never instead of each command's own finding: each unanswered command fails its rule.
    found.extend(v for cmd in streak for v in judge_unanswered(ctx, unit, c, cmd))
    return found


@check("EXEC-ROBUST-001", "EXEC-START-003", finish=True,
       reads=(CONVERSATIONS, FEEDBACK_WITHOUT_TASK_UUID, IDENTITY))
@judged_on_a_copy(CONVERSATIONS, dropped=("EXEC-ROBUST-001", "open expectations"))
def conversations_at_end(ctx: CheckContext, unit: UnitState, c: Conversations,
                         now: float) -> list[Violation]:
    """At the end: answers still due are judged (a unit that died is HB-012's finding);
    tasks still running are not judged; what the bounds dropped is said."""
    found = _expire(ctx, unit, c, now)
    found += _judge_streak(ctx, unit, c, ended_by="the end of the observation",
                           dead=dying_at_end(ctx, unit, c, now))
    running = [t for t in c.open() if t.left_at is None and t.life == c.life]
    if running:
        unit.note("EXEC-START-003", f"{len(running)} task(s) still running when the "
                                    f"observation ended: not judged")
    return found

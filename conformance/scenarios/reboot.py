"""Reboot (5, 12.1): after a reboot the unit has a new agent-uuid (REBOOT-001); with a new
agent-uuid the tasks from before are unknown, with the same one they are still known
(REBOOT-002). The reboot is done by ``--reboot-cmd`` (or an in-process hook); without one
both rules are could-not-test."""

from __future__ import annotations

import dataclasses
import statistics
from typing import Any

from conformance.checks.stall import stamp_of
from conformance.scenarios.context import Context, describe
from conformance.scenarios.query import status_answer
from conformance.scenarios.sender import new_uuid
from conformance.scenarios.traffic import Entry
from conformance.topics import DIRECT_EXECUTION, level_name
from conformance.violation import Observed

RULES = ("REBOOT-001", "REBOOT-002")


def silence(previous: Entry, entry: Entry) -> float:
    """Seconds between two heartbeats: by the unit's stamps where both have one (5.1), so that
    heartbeats a stalled broker held and then delivered at once are not taken for the silence
    of a reboot; else by their arrivals."""
    stamps = [stamp_of(e.body, e.time) for e in (previous, entry)]
    if stamps[0] is not None and stamps[1] is not None:
        return stamps[1] - stamps[0]
    return entry.time - previous.time


def intervals(beats: list[Entry]) -> list[float]:
    """The intervals between consecutive heartbeats of one agent-uuid (``silence``), oldest
    first: a reboot's silence (a new agent-uuid) is not one of them."""
    return [silence(a, b) for a, b in zip(beats, beats[1:], strict=False)
            if a.get("agent-uuid") == b.get("agent-uuid")]


def own_period(ctx: Context) -> float:
    """The heartbeat period the reboot is read in, seconds: the declared one (5.1), or the
    median interval between heartbeats of one agent-uuid so far where that is longer: a unit
    far slower than it declares (HB-003's finding) is not taken for one that never came back
    because its new life's second heartbeat is not within two declared periods."""
    declared = ctx.rate_of("heartbeat") or 1.0
    seen = intervals(ctx.traffic.since(0, "heartbeat"))
    if not seen:
        return 1.0 / declared
    return max(1.0 / declared, statistics.median(seen))


def run(ctx: Context) -> None:
    if DIRECT_EXECUTION not in map(level_name, ctx.levels()):
        # REBOOT-002 is about the history of commands (12.1): a unit that declares no direct
        # execution does not claim it, and its row says so ('not claimed'), not could-not-test.
        record = ctx.record
        ctx = dataclasses.replace(ctx, record=lambda rule, **kw: None if rule == "REBOOT-002"
                                  else record(rule, **kw))
    if ctx.reboot is None:
        for rule in RULES:
            ctx.record(rule, seen=Observed.UNTESTABLE,
                       reason="no way to reboot the unit: pass --reboot-cmd 'COMMAND' (a shell "
                       "command that restarts it)")
        return
    # Some agents come back under another name (a random suffix per start): watch the names
    # of the unit's type and role (suite/reboot.py's Reboot can; a bare callable cannot).
    watch = getattr(ctx.reboot, "watch_names", None)
    names = watch() if watch is not None else None
    try:
        _reboot(ctx, names)
    finally:
        if names is not None:
            names.close()


def _reboot(ctx: Context, names: Any) -> None:
    """The reboot and what it shows; ``names``: a ``suite.reboot.Names`` watch, or None."""
    assert ctx.reboot is not None
    old_agent = ctx.agent_uuid
    rate = 1.0 / own_period(ctx)
    ended = ctx.notes.get("ended", [])
    before = ctx.traffic.mark()
    ctx.commander.abort_all(ctx.timing.response)  # tasks die with the reboot anyway
    known = _names_heard(ctx, names, rate) if names is not None else set()
    heard = {e.get("agent-uuid") for e in ctx.traffic.since(0, "heartbeat")}
    requested = ctx.traffic.clock.now()
    error = ctx.reboot()
    if error is not None:
        for rule in RULES:
            ctx.record(rule, seen=Observed.UNTESTABLE,
                       reason=f"the reboot ({ctx.reboot_how}) failed: {error}")
        return
    hb = _back(ctx, before, requested, heard, old_agent, rate)
    renamed = names.new_name(known, requested, 0.0) if hb is None and names else None
    if renamed is not None:
        # 3.1: UNIT is the unit's name; back under another, it is another unit to every
        # commander. Not could-not-test (it did not die); no words of the spec say a name
        # outlives a reboot, so it is REBOOT-001's decided condition 'renamed' (warns).
        ctx.record("REBOOT-001", violation=dataclasses.replace(ctx.violation(
            "REBOOT-001", expected=f"back as '{ctx.unit.name}' with a new agent-uuid (its "
            f"name is its address, 3.1)", observed=f"after the reboot ({ctx.reboot_how}) the "
            f"unit came back as '{renamed}' (a unit of the same type and role first heard "
            f"after the reboot)", subtopic="heartbeat",
            detail="keep the unit's name across a reboot: only its agent-uuid changes (5.1)"),
            condition="renamed"), missing=False)
        ctx.record("REBOOT-002", seen=Observed.UNTESTABLE,
                   reason=f"the unit came back under another name ('{renamed}', REBOOT-001)")
        ctx.notes["renamed"] = renamed  # what follows reads why its address fell silent
        return
    if hb is None:
        ctx.record("REBOOT-001", violation=ctx.violation(
            "REBOOT-001", expected=f"a heartbeat with a new agent-uuid within "
            f"{ctx.timing.reboot + 2.0 / rate:.1f} s of the reboot ({ctx.reboot_how})",
            observed=f"heartbeats went on with agent-uuid {old_agent} and no silence"
            if ctx.traffic.since(before, "heartbeat") else "no heartbeat at all",
            subtopic="heartbeat", entry=ctx.traffic.latest("heartbeat")))
        ctx.record("REBOOT-002", seen=Observed.UNTESTABLE,
                   reason="the unit did not visibly reboot (REBOOT-001)")
        return
    new_agent = hb.get("agent-uuid")
    if new_agent != old_agent:
        ctx.record("REBOOT-001", seen=Observed.EXAMINED)
    else:
        ctx.record("REBOOT-001", violation=ctx.violation(
            "REBOOT-001", expected=f"a new agent-uuid after the reboot (was {old_agent})",
            observed=f"the same agent-uuid {new_agent} after a silence", subtopic="heartbeat",
            entry=hb))
    if not ended:
        ctx.record("REBOOT-002", seen=Observed.UNTESTABLE,
                   reason="no task ended before the reboot to ask about")
        return
    _history(ctx, ended[0], old_agent, new_agent)


def _names_heard(ctx: Context, names: Any, rate: float) -> set[str]:
    """The names of units of the unit's type and role heard before the reboot: after two
    heartbeats of the unit they have been heard (unless far slower), and are not taken for
    it when it comes back."""
    count = [0]

    def second(_entry: Entry) -> bool:
        count[0] += 1
        return count[0] >= 2

    ctx.traffic.wait_for(second, ctx.timing.periods(3, rate), after=ctx.traffic.mark(),
                         subtopic="heartbeat", what="two heartbeats before the reboot")
    return set(names.heard())


def _back(ctx: Context, before: int, requested: float, heard: set[Any], old_agent: Any,
          rate: float) -> Entry | None:
    """The first heartbeat of the unit back from the reboot, None if it did not come back.

    Back when a heartbeat of an agent-uuid never heard before the reboot is followed by
    another within two declared periods: the new life is under way, its commands subscribed
    (a new uuid alone may be one that changes on its own, HB-006, just as the reboot began).
    Or a heartbeat follows a silence of more than two declared periods (HB-006's reboot
    silence) with the same one (REBOOT-001 fails on it)."""
    last = [ctx.traffic.latest("heartbeat")]
    first: list[Entry | None] = [None]

    def back(entry: Entry) -> bool:
        previous, last[0] = last[0], entry
        if previous is None:
            return False
        soon = silence(previous, entry) <= 2.0 / rate
        if previous.time >= requested and previous.get("agent-uuid") not in heard and soon:
            first[0] = previous  # the new life's first heartbeat: REBOOT-001 reads its uuid
            return True
        return entry.get("agent-uuid") == old_agent and not soon

    # The reboot's budget, and the second heartbeat of the new life on top of it.
    hb = ctx.traffic.wait_for(back, ctx.timing.reboot + 2.0 / rate, after=before,
                              subtopic="heartbeat")
    return first[0] or hb


def _history(ctx: Context, ended: tuple[str, str, str], old_agent: Any, new_agent: Any) -> None:
    """REBOOT-002: a task that ended before the reboot is unknown after it when the
    agent-uuid changed (the history was lost), still known when it did not (5.1)."""
    # Ready for commands again: answer a ping (deadline: the reboot's). A unit that never
    # answered ping (EXEC-PING-001's, judged already) would only let that deadline run out:
    # it is asked the query-status of a task it never saw instead (needed below anyway).
    ghost: Entry | None = None
    if any(e.get("response") == "pong" for e in ctx.traffic.since(0, "exec/response")):
        ctx.commander.ping(ctx.timing.reboot)
        asked = False
    else:
        _, ghost = ctx.commander.query(new_uuid(), ctx.timing.reboot)
        asked = True
    task_uuid, name, status = ended
    sent, answer = ctx.commander.query(task_uuid, ctx.timing.response)
    if answer is None:
        # Its history cannot be read off a unit that does not answer query-status at all:
        # that is EXEC-QUERY-001's finding, not a history kept or lost.
        ctx.record("REBOOT-002", seen=Observed.UNTESTABLE,
                   reason=f"query-status was not answered within {ctx.timing.response:.1f} s "
                          f"(EXEC-QUERY-001)")
        return
    got = status_answer(answer)
    # Compared with the unit's own answer for a task it never saw, so that a wrong word for
    # 'unknown' stays EXEC-QUERY-002's finding and is not counted here again.
    if not asked:
        _, ghost = ctx.commander.query(new_uuid(), ctx.timing.response)
    unknown = status_answer(ghost) if ghost is not None else "unknown"
    if new_agent != old_agent:
        ok = got == unknown
        expected = (f"task '{name}' from before the reboot unknown (answered {unknown!r}, as "
                    f"for a task never seen): a new agent-uuid means the history was lost")
    else:
        ok = got not in (unknown, None)
        expected = (f"task '{name}' still known ('{status}'): the agent-uuid did not change, "
                    f"so the history must be kept")
    if ok:
        ctx.record("REBOOT-002", seen=Observed.EXAMINED)
    else:
        ctx.record("REBOOT-002", violation=ctx.violation(
            "REBOOT-002", expected=expected, observed=repr(got) if answer is not None else
            f"no response within {ctx.timing.response:.1f} s", entry=answer,
            detail=f"agent-uuid before {old_agent}, after {new_agent}; {describe(answer)}"))

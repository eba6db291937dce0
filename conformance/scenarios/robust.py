"""Robustness (12.1): malformed JSON, unknown commands and missing fields do not stop the unit
(it still answers ping: EXEC-ROBUST-001); a malformed command whose com-uuid can be read is
answered 'failed' with a reason (EXEC-ROBUST-002, a 'should')."""

from __future__ import annotations

import orjson

# Unreadable probes (no com-uuid can be read, so no answer is expected; the unit must survive
# them) are defined with the suite's sender, where lint recognises them as the suite's.
from conformance.checks.suite_commands import UNREADABLE
from conformance.scenarios.commander import NO_SUCH_TASK
from conformance.scenarios.context import Context, describe
from conformance.scenarios.sender import SENDER, NotSent, Sent, new_uuid
from conformance.violation import Observed

RULES = ("EXEC-ROBUST-001", "EXEC-ROBUST-002")
ALIVE_WAITS = 3
"""Response deadlines the last ping may take: a late pong still shows the unit lives."""


def malformed(com_uuid: str) -> list[tuple[str, bytes]]:
    """Malformed commands whose com-uuid can be read: each should be answered 'failed'
    (the answer's fail-reason is EXEC-007's business). None names a real task: a lenient
    parser on a real unit could run it (docs/ARCHITECTURE.md 'Safety'; the publish policy would
    refuse a motion task anyway)."""
    def body(**fields: object) -> bytes:
        return orjson.dumps({"com-uuid": com_uuid, "sender": SENDER, **fields})

    prefix = f'{{"com-uuid": "{com_uuid}", "sender": "{SENDER}", '.encode()
    return [
        ("an unknown command", body(command="waraps-conformance-no-such-command")),
        ("a command without 'command'", body()),
        ("start-task without task", body(command="start-task")),
        ("start-task whose task is a string", body(command="start-task", task=NO_SUCH_TASK)),
        ("JSON cut off after the com-uuid", prefix + b'"command": "start-ta'),
        ("NaN in a command (not JSON)", prefix + b'"command": "ping", "x": NaN}'),
    ]


def run(ctx: Context) -> None:
    # 'Stopped answering' is judged only by a kind of command the unit answered before: a
    # ping, first, when none was answered yet (a rerun of this rule alone).
    try:
        answered_ping = _pong_seen(ctx) or (
            ctx.commander.ping(ctx.timing.response)[1] is not None or _pong_seen(ctx))
    except NotSent:  # --dry-run: the probes are still shown, nothing is judged
        answered_ping = False
    for _what, payload in UNREADABLE:
        ctx.commander.send_raw(payload)
    pending: list[tuple[str, Sent]] = []
    for index in range(len(malformed(""))):
        com_uuid = new_uuid()  # a fresh one for each: they are different commands
        what, payload = malformed(com_uuid)[index]
        pending.append((what, ctx.commander.send_raw(payload, com_uuid=com_uuid)))
    unanswered = 0
    for what, sent in pending:  # one deadline for all: they were sent together
        answer = ctx.commander.response(sent, ctx.timing.response if not unanswered else 0.2)
        if answer is not None and answer.get("response") == "failed":
            ctx.record("EXEC-ROBUST-002", seen=Observed.EXAMINED)
            continue
        unanswered += answer is None
        ctx.record("EXEC-ROBUST-002", violation=ctx.violation(
            "EXEC-ROBUST-002", expected=f"'failed' for {what}",
            observed=describe(answer) if answer is not None else "no response",
            entry=answer, detail=f"command {sent.payload.decode('utf-8', 'replace')}",
            command=sent.com_uuid))
    # Still alive? Any pong after this ping counts (EXEC-PING-002 judges its response-to),
    # however late: lateness is EXEC-PING-001's and EXEC-010's, not a stopped unit. A unit
    # that never answered a ping cannot show it by one ('stopped answering' is
    # judged only from kinds of command it answered before; EXEC-PING-001 is its finding).
    if not answered_ping:
        ctx.record("EXEC-ROBUST-001", seen=Observed.UNTESTABLE, reason=(
            "the unit answered no ping before the malformed commands: whether it still answers "
            "after them cannot be told by one (EXEC-PING-001)"))
        return
    sent = ctx.commander.send({"command": "ping"})
    alive = ALIVE_WAITS * ctx.timing.response
    pong = ctx.traffic.wait_for(lambda e: e.get("response") == "pong", alive,
                                after=sent.mark, subtopic="exec/response")
    if pong is not None:
        ctx.record("EXEC-ROBUST-001", seen=Observed.EXAMINED)
        return
    ctx.record("EXEC-ROBUST-001", violation=ctx.violation(
        "EXEC-ROBUST-001", expected="a pong after malformed and unknown commands",
        observed=f"no answer to ping within {alive:.1f} s",
        detail=f"sent {len(UNREADABLE)} unreadable and {len(pending)} malformed commands"))


def _pong_seen(ctx: Context) -> bool:
    return any(e.get("response") == "pong" for e in ctx.traffic.since(0, "exec/response"))

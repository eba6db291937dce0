"""ping (12.2.1): the unit answers with a pong whose response-to is the ping's com-uuid."""

from __future__ import annotations

from conformance.scenarios.context import Context
from conformance.scenarios.traffic import Entry
from conformance.violation import Observed

RULES = ("EXEC-PING-001", "EXEC-PING-002")


def run(ctx: Context) -> None:
    sent = ctx.commander.send({"command": "ping"})

    def pong(e: Entry) -> bool:
        # Any pong counts as an answer (PING-001): a wrong response-to is told apart from none.
        return e.get("response-to") == sent.com_uuid or e.get("response") == "pong"

    answer = ctx.traffic.wait_for(pong, ctx.timing.response, after=sent.mark,
                                  subtopic="exec/response")
    if answer is None and not ctx.commander.dry_run:
        # 12.1: "If a response is not arriving re-send the command with the same com-uuid".
        # The run's first command may reach a unit that heartbeats before it subscribes.
        again = ctx.commander.resend(sent)
        answer = ctx.traffic.wait_for(pong, ctx.timing.response, after=again.mark,
                                      subtopic="exec/response")
    if answer is None:
        ctx.record("EXEC-PING-001", violation=ctx.violation(
            "EXEC-PING-001", expected=f"a response 'pong' within {ctx.timing.response:.1f} s",
            observed="no response, to the ping or to its resend",
            detail=f"ping com-uuid {sent.com_uuid}", command=sent.com_uuid))
        ctx.record("EXEC-PING-002", seen=Observed.UNTESTABLE,
                   reason="the ping was not answered (EXEC-PING-001)")
        return
    if answer.get("response") == "pong":
        ctx.record("EXEC-PING-001", seen=Observed.EXAMINED)
    else:
        ctx.record("EXEC-PING-001", violation=ctx.violation(
            "EXEC-PING-001", expected="response 'pong'", observed=repr(answer.get("response")),
            entry=answer))
    if answer.get("response-to") == sent.com_uuid:
        ctx.record("EXEC-PING-002", seen=Observed.EXAMINED)
    else:
        ctx.record("EXEC-PING-002", violation=ctx.violation(
            "EXEC-PING-002", expected=f"response-to {sent.com_uuid} (the ping's com-uuid)",
            observed=f"response-to {answer.get('response-to')!r}", entry=answer,
            detail="copy the command's com-uuid into response-to, unchanged (12.3)"))

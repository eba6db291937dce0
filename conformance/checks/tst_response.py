"""Responses on tst/response, matched to their TST command by response-to and judged (14.4).

A start-tst is answered 'started' with the tree's root-uuid (TST-004), a signal 'ok', or
'failed' with a reason for an unknown node or an ended tree (TST-011); an 'ok' implies the
feedback the signal asks for (TST-012, checked by ``tst_feedback`` and ``tst_deadline``); a
resend is answered again (TST-007) and starts nothing twice (TST-006). Commands the unit left
unanswered before the one it answers are its own faults.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import left_unanswered, str_of, violation
from conformance.checks.registry import check
from conformance.checks.tst_conversation import (
    ANSWER_RULE,
    TST_CONVERSATIONS,
    Expect,
    TstCommand,
    TstConversations,
    TstNode,
    runs,
    tst_conversations,
)
from conformance.message import Message
from conformance.protocol import BUILTIN_SIGNALS as SIGNALS
from conformance.topics import TST_EXECUTION, TopicKind
from conformance.tst import FINAL, unit_name
from conformance.validator import Validation
from conformance.violation import Violation

EXPECTS_KEPT = 256
STARTED = ("started", "running")  # 14.4.4; 'running' is ERR-015's reading (the validator's)
SIGNAL_FEEDBACK = {"$abort": "aborted", "$enough": "succeeded", "$pause": "paused",
                   "$continue": "running"}
"""TST-012's decision: the status a node signalled (and answered 'ok') reports next."""


@check("TST-004", "TST-006", "TST-007", "TST-011", on=(TopicKind.TST_RESPONSE,),
       reads=(TST_CONVERSATIONS,))
def tst_response_answers_command(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> Iterator[Violation]:
    """14.4: a response answers a TST command (response-to = its com-uuid), with a value that
    fits the command; a resend is answered again, the same way."""
    m = v.message
    response_to = str_of(m, "response-to")
    if response_to is None:
        return
    c = tst_conversations(unit)
    cmd = c.commands.get(response_to)
    if cmd is None or cmd.judged:
        return  # a command before the observation, or another unit's on a shared topic
    c.answered_any = True
    c.last_answer = msg.time
    value, root_uuid = str_of(m, "response"), str_of(m, "root-uuid")
    c.heard(cmd, value, root_uuid)
    if cmd.answers > 1:
        unit.examine("TST-007")
        if cmd.tree is not None and value in STARTED and cmd.values[0][0] in STARTED:
            unit.examine("TST-006")
            first = cmd.values[0][1]
            if root_uuid != first:
                yield violation("TST-006", msg, expected=f"the resent {cmd.describe()} "
                                f"answered as before (root-uuid {first})", observed=f"started "
                                f"again as root-uuid {root_uuid}", path="$.root-uuid",
                                detail="12.1: remember com-uuids; answer a resend from memory")
        return
    if c.unanswered:
        for earlier in c.unanswered_before(cmd.last_sent):
            yield from judge_unanswered(ctx, unit, c, earlier)
    if cmd.name == "start-tst":
        yield from _judge_start(ctx, unit, c, cmd, msg, m, value, root_uuid)
    else:
        yield from _judge_signal(ctx, unit, c, cmd, msg, m, value)


def _judge_start(ctx: CheckContext, unit: UnitState, c: TstConversations, cmd: TstCommand,
                 msg: Message, m: Any, value: str | None, root_uuid: str | None
                 ) -> Iterator[Violation]:
    """14.4.4: 'started' with root-uuid = the root's node-uuid (generated when none was set),
    or 'failed' ('direct failure to start', TST-005's to judge: only the suite knows which
    trees the unit can run)."""
    tree = cmd.tree
    if value == "failed":
        unit.examine("TST-004")
        if tree is not None:
            tree.state = "refused"
        return
    if value not in STARTED:
        unit.examine("TST-004")
        yield violation("TST-004", msg, expected=f"'started' (or 'failed' with a reason) "
                        f"answering {cmd.describe()}", observed=f"response {value!r}",
                        path="$.response", detail="14.4.4: a start-tst is answered 'started' "
                        "with the tree's root-uuid")
        return
    if tree is None:
        return
    tree.state = "started"
    root = tree.root
    assert root is not None
    unit.examine("TST-004")
    given = root.node_uuid if not root.node_uuid.startswith("(unnamed") else None
    if root_uuid is None or (given is not None and root_uuid != given):
        yield violation("TST-004", msg, expected=f"root-uuid {given or '(a generated one)'}: "
                        f"the root's node-uuid in {cmd.describe()}",
                        observed=f"root-uuid {root_uuid!r}", path="$.root-uuid",
                        detail="14.3.4, 14.4.4: the response names the tree by its root's "
                        "node-uuid, the one the commander set")
    if root_uuid is not None and root_uuid != given and root_uuid not in c.nodes:
        # The unit's own name for the root: its feedback is judged as the root's.
        alias = TstNode(root_uuid, root.name, tree, None, True)
        tree.roots.append(alias)
        c.nodes[root_uuid] = alias


def _judge_signal(ctx: CheckContext, unit: UnitState, c: TstConversations, cmd: TstCommand,
                  msg: Message, m: Any, value: str | None) -> Iterator[Violation]:
    """14.4.1-14.4.3: 'ok', or 'failed' with a reason for an unknown node or an ended tree;
    an 'ok' implies the feedback the signal asks for (TST-012)."""
    unit.examine("TST-011")
    reason = str_of(m, "fail-reason")
    if value not in ("ok", "failed"):
        yield violation("TST-011", msg, expected=f"'ok' or 'failed' answering "
                        f"{cmd.describe()}", observed=f"response {value!r}", path="$.response",
                        detail="14.4.1-14.4.3: a signal is answered 'ok'")
        return
    # 'failed' without a fail-reason is the response schema's (TST-002), not judged again.
    targets, known = _targets(unit, c, cmd)
    if value == "ok":
        wrong = _why_not_ok(unit, c, cmd, known)
        if wrong:
            yield violation("TST-011", msg, expected=f"'failed' with a reason answering "
                            f"{cmd.describe()}: {wrong}", observed="'ok'", path="$.response",
                            detail="14.3: refuse a signal for a node the unit does not run")
            return
        wanted = SIGNAL_FEEDBACK.get(cmd.signal or "")
        if wanted is None:
            return
        if not targets and known is not None and known.final is not None \
                and known.final[0] == wanted and known.final[2] >= cmd.time:
            unit.examine("TST-012")  # it ended so before the answer came (no topic order, 12)
        for node in targets:
            if node.status == wanted and wanted not in FINAL:
                unit.examine("TST-012")  # already so: nothing to report
                continue
            if len(c.expects) < EXPECTS_KEPT:
                c.expects.append(Expect(node, wanted, msg.time + ctx.profile.feedback_timeout,
                                        cmd))
            else:
                c.dropped += 1
    elif targets and cmd.signal in SIGNALS and cmd.name != "signal-unit":
        # 'failed' for a node that runs, in a tree that runs: it should have been done,
        # unless the node is a task that does not list the signal (5.3: 'for each task a
        # list of signals it understands'), as at the exec level.
        node = targets[0]
        listed = unit.tasks_available.get(node.name)
        if not node.children and listed is not None and cmd.signal not in listed:
            return
        yield violation("TST-011", msg, expected=f"'ok' answering {cmd.describe()}: node "
                        f"{node.node_uuid} ('{node.name}') runs (latest status "
                        f"'{node.status}')", observed=f"'failed': {reason}",
                        path="$.response", detail="14.3: a running node takes the built-in "
                        "signals")


def _targets(unit: UnitState, c: TstConversations, cmd: TstCommand
             ) -> tuple[list[TstNode], TstNode | None]:
    """The live nodes a signal addresses (the node, the tree's root, every live root of the
    unit), and the node it names when the traffic knows it."""
    if cmd.name == "signal-unit":
        if cmd.target is None or unit_name(cmd.target) != unit.address.name:
            return [], None
        roots = [t.root for t in list(c.trees.values())
                 if t.state == "started" and t.life == c.life and not t.ambiguous
                 and t.root is not None and t.ended_at is None]
        return [r for r in roots if runs(r)], None
    node = c.nodes.get(cmd.target) if cmd.target else None
    if node is None:
        return [], None
    tree = node.tree
    if tree.state != "started" or tree.life != c.life or tree.ambiguous \
            or tree.ended_at is not None or not runs(node) or not runs(tree.roots[0]):
        return [], node
    if cmd.name == "signal-tst-tree" and not node.root:
        return [], node  # 14.3.2 names the tree by its root: a refusal is right
    return [node], node


def _why_not_ok(unit: UnitState, c: TstConversations, cmd: TstCommand,
                node: TstNode | None) -> str:
    """Why an 'ok' to this signal is wrong ('' when it is not, or the traffic cannot tell)."""
    if cmd.name == "signal-unit":
        return ""
    if node is not None:
        tree = node.tree
        if tree.state == "refused":
            return f"node {node.node_uuid} is of a tree the unit refused"
        if tree.life != c.life:
            return f"node {node.node_uuid} is of a tree from before the unit's reboot"
        ended = tree.ended_at
        if ended is not None and ended < cmd.time:
            return f"the tree of node {node.node_uuid} ended before the signal was sent"
        return ""
    # A node-uuid the observation never saw: unknown to the unit, when everything the unit
    # runs is known (its latest nodes-executing lists only roots of trees the traffic started,
    # and a node that runs has its root listed).
    if c.info_nodes is None or cmd.target in c.info_nodes:
        unit.note("TST-011", "'ok' to a signal for a node the observation never saw: not "
                             "judged without nodes-executing listing only known trees")
        return ""
    known_roots = {r.node_uuid for t in c.trees.values() for r in t.roots if t.life == c.life}
    if not c.info_roots <= known_roots:
        return ""
    return f"no tree the unit runs has node {cmd.target}"


def judge_unanswered(ctx: CheckContext, unit: UnitState, c: TstConversations, cmd: TstCommand
                     ) -> Iterator[Violation]:
    """A TST command the unit never answered fails its rule (14.4), if the unit answers TST
    commands: it declares 'tst execution' or has answered any."""
    rule = ANSWER_RULE[cmd.name]
    if not (c.answered_any or unit.claims(TST_EXECUTION)):
        unit.note(rule, "TST commands seen, but the unit declares no 'tst execution' and "
                        "answered none")
        return
    yield from left_unanswered(ctx, unit, rule, cmd, cmd.topic, "14.4: answer every TST "
                               "command, 'failed' with a reason when it cannot be done")

"""A tree's nodes as their feedback and nodes-executing show them (14.5, TST-013).

Feedback follows every node of a started tree to one final status (TST-009), root-flag on the
root alone (TST-008), a seq's children in order and composites ending as their children say
(TST-010); a signal answered 'ok' is followed by the status it asks for (TST-012). Feedback
after a final status that a resend caused is TST-006's. ``tst_execution_info``'s
nodes-executing lists exactly the nodes not yet in a final status (TST-013); a node that
leaves it without one has ended silently (TST-009, judged by ``tst_deadline``).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import str_of, violation
from conformance.checks.registry import check
from conformance.checks.tst_conversation import (
    TST_CONVERSATIONS,
    TstConversations,
    TstNode,
    tst_conversations,
)
from conformance.message import Message
from conformance.results import NOT_APPLICABLE
from conformance.topics import TopicKind
from conformance.tst import FINAL
from conformance.validator import Validation
from conformance.violation import Violation, clock

READ_AS = {"finished": "succeeded"}
"""A near miss of 14.5's vocabulary (TST-003, the validator's) is read as the status it means."""
NOT_STARTED = frozenset({"not-active"})
"""14.5's status of a node that has not started: a unit may announce every node of a tree so
when the tree starts (14.5's list begins with it). A seq's child so announced has not run
(TST-010 judges its first status that is not this one)."""


def _grace(unit: UnitState) -> float:
    """How old a change must be before nodes-executing is judged on it: one declared period
    of tst_execution_info (an info composed just before the change may arrive after it), at
    least a second."""
    period = unit.period(TopicKind.TST_EXECUTION_INFO)
    return max(1.0, period or 1.0)


def _status(m: Any) -> str | None:
    status = str_of(m, "status")
    return READ_AS.get(status, status) if status is not None else None


@check("TST-006", "TST-008", "TST-009", "TST-010", "TST-012", "TST-013",
       on=(TopicKind.TST_FEEDBACK,), reads=(TST_CONVERSATIONS,))
def tst_feedback_follows_tree(ctx: CheckContext, unit: UnitState, msg: Message,
                              v: Validation) -> Iterator[Violation]:
    """14.5: feedback follows every node of a started tree to one final status, root-flag on
    the root alone; composites end as their children say."""
    m = v.message
    node_uuid, status = str_of(m, "node-uuid"), _status(m)
    if node_uuid is None or status is None:
        return
    c = tst_conversations(unit)
    node = c.nodes.get(node_uuid)
    if node is None or node.tree.state == "refused" or node.tree.life != c.life:
        return  # not a tree the traffic started (or one refused: TST-005's)
    tree = node.tree
    t = msg.time
    yield from _judge_root_flag(unit, node, node_uuid, msg, m)
    if node.final is not None:
        yield from _judge_after_final(unit, node, node_uuid, msg, m, status)
        return
    if status == "active":
        node.actives += 1
        if node.actives > 1 and tree.resent is not None and "TST-006" not in node.judged:
            node.judged.add("TST-006")
            unit.examine("TST-006")
            yield violation("TST-006", msg, expected=f"node {node_uuid} ('{node.name}') "
                            f"started once", observed="'active' again after its start-tst "
                            "was resent", path="$.status", detail="12.1: a resent start-tst "
                            "is answered from memory, not started again")
    if node.unlisted_at is not None and t - node.unlisted_at >= _grace(unit) \
            and "TST-013" not in node.judged:
        node.judged.add("TST-013")
        unit.examine("TST-013")
        yield violation("TST-013", msg, expected=f"node {node_uuid} ('{node.name}') in "
                        f"nodes-executing while it runs", observed=f"left out at "
                        f"{clock(node.unlisted_at)}, and it still ran ('{status}' "
                        f"{t - node.unlisted_at:.2f} s later)", path="$.status",
                        detail="list every node that is not yet in a final status")
    node.unlisted_at = node.left_at = None
    if status != "revoked" and status not in NOT_STARTED \
            and (node.status is None or node.status in NOT_STARTED):
        yield from _judge_order(unit, node, msg, status)
    node.status, node.status_time = status, t
    yield from _judge_signalled(unit, c, node, msg, status)
    if status in FINAL:
        yield from _ended(ctx, unit, c, node, (status, str_of(m, "com-uuid"), t), msg)


def _judge_root_flag(unit: UnitState, node: TstNode, node_uuid: str, msg: Message, m: Any
                     ) -> Iterator[Violation]:
    """14.5: root-flag is true in the feedback of the tree's top node alone (TST-008)."""
    flag = m.get("root-flag") if isinstance(m, dict) else None
    if not isinstance(flag, bool):
        if isinstance(m, dict) and "root-flag" not in m:
            unit.note("TST-008", f"{NOT_APPLICABLE}its TST feedback carries no root-flag")
        return
    unit.examine("TST-008")
    if flag is not node.root:
        yield violation("TST-008", msg, expected=f"root-flag {str(node.root).lower()} for "
                        f"{'the root' if node.root else 'a node below the root'} "
                        f"{node_uuid} ('{node.name}')", observed=f"root-flag "
                        f"{str(flag).lower()}", path="$.root-flag",
                        detail="14.5: root-flag marks the feedback of the tree's top node")


def _judge_after_final(unit: UnitState, node: TstNode, node_uuid: str, msg: Message, m: Any,
                       status: str) -> Iterator[Violation]:
    """14.5: a node's final status is its last (TST-009); after a resent start-tst, feedback
    again is a tree started twice (TST-006). Once per node and rule."""
    assert node.final is not None
    end_status, end_com, end_time = node.final
    if str_of(m, "com-uuid") == end_com:
        return  # the final message delivered again
    tree = node.tree
    # A node active or running again after a resent start-tst was started twice (TST-006's
    # words); any other status after the final one is TST-009's (decided: 14.5 names no
    # final status).
    again = (tree.resent is not None and tree.resent > end_time
             and status in ("active", "running"))
    rule = "TST-006" if again else "TST-009"
    unit.examine(rule)
    if rule not in node.judged:
        node.judged.add(rule)
        yield violation(rule, msg, expected=f"nothing for node {node_uuid} after its "
                        f"final status '{end_status}'", observed=f"status '{status}' "
                        f"{msg.time - end_time:.2f} s later" + (" (after its start-tst was "
                                                                "resent: started again)"
                                                                if again else ""),
                        path="$.status", detail="14.5: a node's final status is its last")


def _judge_signalled(unit: UnitState, c: TstConversations, node: TstNode, msg: Message,
                     status: str) -> Iterator[Violation]:
    """14.3: a signal answered 'ok' is followed by the status it asks for (TST-012): that
    status settles it, a final status other than it breaks it."""
    for e in [e for e in c.expects if e.node is node]:
        if status == e.wanted:
            unit.examine("TST-012")
            c.expects.remove(e)
        elif status in FINAL:
            c.expects.remove(e)
            unit.examine("TST-012")
            yield violation("TST-012", msg, expected=f"'{e.wanted}' after "
                            f"{e.command.describe()} was answered 'ok'",
                            observed=f"status '{status}'", path="$.status",
                            detail="14.3: do what the signal says, and say so in feedback")


def _judge_order(unit: UnitState, node: TstNode, msg: Message, status: str
                 ) -> Iterator[Violation]:
    """TST-010: a seq runs its children in order, and none after a child that did not
    succeed."""
    parent = node.parent
    if parent is None or parent.name != "seq" or "TST-010" in parent.judged:
        return
    i = parent.children.index(node)
    earlier = parent.children[:i]
    if any(s.status is None for s in earlier):
        return  # an earlier child the traffic never saw (no feedback): cannot tell
    unit.examine("TST-010")
    running = [s for s in earlier if s.final is None]
    failed = [s for s in earlier if s.final is not None and s.final[0] in ("failed", "aborted")]
    if running or failed:
        parent.judged.add("TST-010")
        s = (running or failed)[0]
        said = ("has not started" if s.status in NOT_STARTED else "still runs") if running \
            else f"ended '{s.final[0]}'"  # type: ignore[index]
        yield violation("TST-010", msg, expected=f"seq {parent.node_uuid} starts child "
                        f"{node.node_uuid} only after child {s.node_uuid} succeeded",
                        observed=f"'{status}' while child {s.node_uuid} "
                                 f"('{s.name}') {said}", path="$.status",
                        detail="a seq runs its children in order, and stops at a child that "
                               "does not succeed (the rest are revoked)")


def _ended(ctx: CheckContext, unit: UnitState, c: TstConversations, node: TstNode,
           final: tuple[str, str | None, float], msg: Message) -> Iterator[Violation]:
    node.final = final
    c.awaiting.pop(node.node_uuid, None)
    c.watch_node(node)
    unit.examine("TST-009")
    if node.composite:
        yield from _judge_outcome(unit, node, msg)
        for child in node.children:  # its children end with it
            if child.live:
                c.awaiting[child.node_uuid] = child
    parent = node.parent
    if parent is not None:
        if parent.final is not None:
            yield from _judge_outcome(unit, parent, msg)
        elif all(ch.final is not None for ch in parent.children):
            parent.ended_children_at = final[2]
            c.awaiting[parent.node_uuid] = parent


def _outcome(children: list[TstNode]) -> str:
    """TST-010's decision: failed if a child that ran failed, else aborted if one was, else
    succeeded (revoked children never ran)."""
    ran = [ch.final[0] for ch in children if ch.final is not None and ch.final[0] != "revoked"]
    return "failed" if "failed" in ran else "aborted" if "aborted" in ran else "succeeded"


def _judge_outcome(unit: UnitState, node: TstNode, msg: Message) -> Iterator[Violation]:
    """TST-010: a composite's final status follows its children's (judged once every child
    reported a final status; children the traffic never heard of leave it unjudged)."""
    if node.final is None or "TST-010-outcome" in node.judged:
        return
    if any(ch.final is None for ch in node.children):
        return
    node.judged.add("TST-010-outcome")
    unit.examine("TST-010")
    want = _outcome(node.children)
    if node.final[0] != want and "TST-010" not in node.judged:
        node.judged.add("TST-010")
        ends = ", ".join(f"{ch.node_uuid} {ch.final[0]}" for ch in node.children
                         if ch.final is not None)
        yield Violation.of("TST-010", expected=f"{node.name} {node.node_uuid} ends '{want}' "
                           f"(its children: {ends})", observed=f"'{node.final[0]}'",
                           topic=msg.topic, path="$.status", time=node.final[2],
                           payload=msg.payload, detail="a composite succeeds only if every "
                           "child that ran succeeded; else it fails if one failed, else it is "
                           "aborted")


# --- tst_execution_info -------------------------------------------------------------------------

@check("TST-013", "TST-009", on=(TopicKind.TST_EXECUTION_INFO,), reads=(TST_CONVERSATIONS,))
def nodes_executing_follow_trees(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> list[Violation] | None:
    """TST-013 (modelled on 5.3's tasks-executing): nodes-executing lists exactly the nodes not
    yet in a final status; a node that leaves it without one has ended silently (TST-009).
    (Runs on every tst_execution_info: cheap when no tree is open.)"""
    m = v.message
    listed_raw = m.get("nodes-executing") if type(m) is dict else None
    c = unit.stash.get(TST_CONVERSATIONS)
    if type(listed_raw) is not list:
        if c is not None and c.trees:
            unit.note("TST-013", f"{NOT_APPLICABLE}tst_execution_info has no "
                                 f"nodes-executing (TST-013's list is optional)")
        return None
    listed = {e.get("node-uuid") for e in listed_raw if isinstance(e, dict)}
    roots = {e.get("root-uuid") for e in listed_raw if isinstance(e, dict)}
    if c is None:
        c = tst_conversations(unit)
    c.info_nodes, c.info_roots = listed | roots, roots  # type: ignore[assignment]
    t = msg.time
    grace = _grace(unit)
    found: list[Violation] = []
    for node in list(c.watch.values()):  # ended: listed still?
        assert node.final is not None
        if t - node.final[2] < grace:
            continue
        del c.watch[node.node_uuid]
        if node.node_uuid in listed and "TST-013" not in node.judged:
            node.judged.add("TST-013")
            unit.examine("TST-013")
            found.append(violation("TST-013", msg, expected=f"node {node.node_uuid} "
                                   f"('{node.name}') no longer in nodes-executing",
                                   observed=f"listed {t - node.final[2]:.2f} s after its final "
                                            f"status '{node.final[0]}'",
                                   path="$.nodes-executing",
                                   detail="list only nodes not yet in a final status"))
        elif node.node_uuid not in listed:
            unit.examine("TST-013")
    for tree in list(c.trees.values()):
        if tree.state != "started" or tree.life != c.life or tree.ended_at is not None:
            continue
        for node in (n for r in tree.roots for n in r.walk()):
            if not node.live or node.status_time is None or node.status in NOT_STARTED:
                continue  # a node announced 'not-active' is not executing yet
            if node.node_uuid in listed:
                node.listed = True
                node.unlisted_at = node.left_at = None
                unit.examine("TST-013")
            elif t - node.status_time >= grace and node.unlisted_at is None:
                node.unlisted_at = t
                if node.listed:
                    node.left_at = t
                    c.awaiting[node.node_uuid] = node
    return found or None

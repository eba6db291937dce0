"""TST conversations (spec 14; the exec conversations' pattern one level up): what one unit
was told on ``tst/command`` and how it answered, as the traffic showed it: commands, the trees
they started and their nodes.

A start-tst on ``tst/command`` opens a tree (``tst_command``): its response (``response-to`` =
its com-uuid) says 'started' with ``root-uuid`` = the root's node-uuid (TST-004; 'running' is
ERR-015's reading and opens the tree too), then feedback follows every node to a final status
(TST-009) with ``root-flag`` on the root only (TST-008), composites ending as their children say
(TST-010) (``tst_feedback``). Signals address a node, a tree or the unit: answered 'ok', or
'failed' with a reason for an unknown node or an ended tree (TST-011), and an 'ok' implies the
feedback the signal asks for (TST-012) (``tst_response``). A resend (same com-uuid, same
content) is answered again (TST-007) and starts nothing twice (TST-006). ``tst_execution_info``'s
nodes-executing lists the nodes that run (TST-013). Deadlines pass on the unit's heartbeats and
at the end (``tst_deadline``). The same code judges a recording in ``lint`` and the suite's
commands in ``pytest --unit``; what exec and TST conversations share is ``command_history``'s.

Only trees the traffic started are judged: feedback for a node no start-tst (or root-uuid) of
the observation named is not. Commands sent to an operator's ``tst/command`` (14.1: 'usually
sent to op0') reach these checks as the unit's they concern: ``checks/tst_routing.py``.

Blame goes to the root cause: feedback after a final status that a resend caused is TST-006's,
not TST-009's; a composite that never says its end is TST-009's, not TST-012's or TST-010's;
a node that leaves nodes-executing without a final status is TST-009's, not TST-013's;
commands a dead unit (HB-012) left unanswered are its death's.

Everything is bounded: trees, nodes and commands are LRUs, open expectations are capped, and
what was dropped is counted and said in the report.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator
from typing import Any

from conformance.checks.base import BoundedDict, CheckContext, UnitState
from conformance.checks.command_history import (
    CommandHistory,
    SentCommand,
    per_unit,
    response_timeout,
    str_of,
)
from conformance.checks.stash import StashKey

COMMANDS_KEPT = 1024
TREES_KEPT = 512
NODES_KEPT = 8192
WATCH_KEPT = 512
"""Nodes that ended recently, watched in nodes-executing (TST-013's staleness)."""
TST_COMMANDS = ("start-tst", "signal-tst-node", "signal-tst-tree", "signal-unit")  # 14.2, 14.3
ANSWER_RULE = {"start-tst": "TST-004", "signal-tst-node": "TST-011",
               "signal-tst-tree": "TST-011", "signal-unit": "TST-011"}


class TstCommand(SentCommand):
    """One TST command sent to a unit, and what came back."""

    __slots__ = ("signal", "target", "tree", "topic")

    def __init__(self, com_uuid: str, name: str, t: float, m: dict[str, Any], digest: bytes,
                 excerpt: bytes, life: str | None, topic: str) -> None:
        super().__init__(com_uuid, name, t, digest, excerpt, life)
        self.signal = str_of(m, "signal")
        self.target = str_of(m, "unit" if name == "signal-unit" else "node-uuid")
        self.tree: TstTree | None = None
        self.topic = topic
        """Where it was sent: the unit's tst/command, or an operator's (14.1)."""

    def describe(self) -> str:
        what = self.name + (f" {self.signal}" if self.signal else "")
        if self.target:
            what += f" to {self.target}"
        return f"{what} (com-uuid {self.com_uuid})"


class TstNode:
    """One node of a tree the traffic started, as its feedback showed it (14.5)."""

    __slots__ = ("node_uuid", "name", "tree", "parent", "children", "root", "status",
                 "status_time", "final", "actives", "listed", "unlisted_at", "left_at",
                 "judged", "ended_children_at")

    def __init__(self, node_uuid: str, name: str, tree: TstTree, parent: TstNode | None,
                 root: bool) -> None:
        self.node_uuid = node_uuid
        self.name = name
        self.tree = tree
        self.parent = parent
        self.children: list[TstNode] = []
        self.root = root
        self.status: str | None = None
        self.status_time: float | None = None
        self.final: tuple[str, str | None, float] | None = None
        """(status, com-uuid, time) of its final feedback."""
        self.actives = 0
        self.listed = False
        """Seen in nodes-executing (TST-013) at least once."""
        self.unlisted_at: float | None = None
        """When an info left it out although it had been live for a while."""
        self.left_at: float | None = None
        """When it left nodes-executing without a final status."""
        self.judged: set[str] = set()
        """Rules already failed for this node (each says it once)."""
        self.ended_children_at: float | None = None
        """When its last child reached a final status (its own is then due)."""

    @property
    def composite(self) -> bool:
        return bool(self.children)

    @property
    def live(self) -> bool:
        return self.status is not None and self.final is None

    def walk(self) -> Iterator[TstNode]:
        yield self
        for child in self.children:
            yield from child.walk()


class TstTree:
    """A tree a start-tst sent; ``state`` is sent, started or refused."""

    __slots__ = ("command", "root", "roots", "state", "life", "resent", "ambiguous")

    def __init__(self, command: TstCommand, life: str | None) -> None:
        self.command = command
        self.root: TstNode | None = None
        self.roots: list[TstNode] = []
        """The root, and a root of the unit's own naming (root-uuid other than the root's
        node-uuid: the unit made its own node-uuids)."""
        self.state = "sent"
        self.life = life
        self.resent: float | None = None
        self.ambiguous = False

    @property
    def ended_at(self) -> float | None:
        ends = [r.final[2] for r in self.roots if r.final is not None]
        return min(ends) if ends else None


class Expect:
    """Feedback a signal answered 'ok' implies (TST-012), due by ``deadline``."""

    __slots__ = ("node", "wanted", "deadline", "command")

    def __init__(self, node: TstNode, wanted: str, deadline: float, command: TstCommand) -> None:
        self.node, self.wanted, self.deadline, self.command = node, wanted, deadline, command


class TstConversations(CommandHistory):
    """What one unit was told on tst/command and how it answered (bounded)."""

    def __init__(self) -> None:
        super().__init__(COMMANDS_KEPT)
        self.trees: BoundedDict = BoundedDict(TREES_KEPT)
        """com-uuid of its start-tst -> tree."""
        self.nodes: BoundedDict = BoundedDict(NODES_KEPT)
        self.expects: list[Expect] = []
        self.watch: OrderedDict[str, TstNode] = OrderedDict()
        """Nodes that ended, until an info shows whether they are still listed."""
        self.awaiting: dict[str, TstNode] = {}
        """Nodes with a deadline of their own: composites whose children all ended, nodes that
        left nodes-executing, nodes whose parent ended."""
        self.info_nodes: set[str] | None = None
        """node-uuids and root-uuids in the latest nodes-executing (None: none seen)."""
        self.info_roots: set[str] = set()

    def watch_node(self, node: TstNode) -> None:
        self.watch[node.node_uuid] = node
        if len(self.watch) > WATCH_KEPT:
            self.watch.popitem(last=False)


TST_CONVERSATIONS: StashKey[TstConversations] = StashKey("tst-conversations")
"""The unit's TST conversations (made by ``tst_conversations``)."""


def tst_conversations(unit: UnitState) -> TstConversations:
    return per_unit(unit, TST_CONVERSATIONS, TstConversations)


def open_until(unit: UnitState, ctx: CheckContext) -> float | None:
    """The latest deadline (Unix seconds) of what is still open in the unit's TST conversations:
    answers due, feedback signals imply, final statuses due; None when nothing is open. An
    active scenario waits for one heartbeat after it, so that the verdicts are in."""
    c = unit.stash.get(TST_CONVERSATIONS)
    if c is None:
        return None
    due = [cmd.last_sent + response_timeout(ctx) for cmd in c.pending.values() if not cmd.judged]
    due += [e.deadline for e in c.expects]
    due += [d for n in c.awaiting.values() if (d := own_deadline(ctx, n)) is not None]
    return max(due) if due else None


def own_deadline(ctx: CheckContext, node: TstNode) -> float | None:
    """When a node waiting for its final status has waited too long."""
    if node.final is not None:
        return None
    if node.left_at is not None:
        return node.left_at + response_timeout(ctx)
    if node.ended_children_at is not None:
        return node.ended_children_at + ctx.profile.feedback_timeout
    parent = node.parent
    if parent is not None and parent.final is not None:
        return parent.final[2] + ctx.profile.feedback_timeout
    return None


def runs(node: TstNode) -> bool:
    """Whether the traffic shows the node still running: a live leaf, or a live composite
    with a child that runs or is still to run. A composite whose children all ended, but
    which said no end of its own, has ended silently (TST-009's finding)."""
    if node.final is not None or node.status is None:
        return False
    return not node.children or any(ch.status is None or runs(ch) for ch in node.children)

"""The TST trees the reference unit runs (spec 14): their nodes, and how a node's status follows
its children's and the signals it gets (14.5; the catalogue's TST-009, TST-010, TST-012).

Leaf nodes are section-9 tasks run by the unit's ``TaskRunner`` (``conformance.sim.runner``):
a leaf's task reports to its node instead of ``exec/feedback``, and its task-uuid is its
node-uuid, so it shows in ``tasks-executing`` like any task the unit runs. Composite nodes are
``seq`` (children in order; fails when a child fails) and ``conc`` (children in parallel;
succeeds when all succeed). What goes on the wire (responses, feedback) is
``conformance.sim.tst``'s: it is told each status change.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from conformance.sim.memory import forget_oldest_ended
from conformance.sim.tasks import Task, plan
from conformance.tst import COMPOSITES, FINAL, Node

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

MAX_TREES = 500
"""Trees remembered per life (the oldest ended ones are forgotten first)."""
_TASK_TO_NODE = {"running": "running", "paused": "paused", "finished": "succeeded",
                 "aborted": "aborted", "failed": "failed"}
"""A leaf's task status (12.4) -> its node's status (14.5); task-specific ones are not sent."""

Report = Callable[["TstNode", str, str], None]
"""Told each status change of a node: (node, status, reason)."""


@dataclass(eq=False)
class TstNode:
    """A node of a running tree: ``status`` is None until it is activated, then one of 14.5."""

    uuid: str
    name: str
    params: Any
    tree: TstTree
    parent: TstNode | None
    children: list[TstNode] = field(default_factory=list)
    status: str | None = None
    task: Task | None = None
    next_child: int = 0
    enough: bool = False
    """$enough reached it: a seq starts no further child and ends succeeded."""

    @property
    def composite(self) -> bool:
        return self.name in COMPOSITES

    @property
    def ended(self) -> bool:
        return self.status in FINAL

    @property
    def live(self) -> bool:
        return self.status is not None and not self.ended

    def walk(self) -> list[TstNode]:
        out = [self]
        for child in self.children:
            out.extend(child.walk())
        return out


@dataclass(eq=False)
class TstTree:
    """A started tree: its root, the start-tst's com-uuid and where it answers (a topic base)."""

    com_uuid: str
    reply: str
    root: TstNode = field(init=False)

    @property
    def ended(self) -> bool:
        return self.root.ended


class Trees:
    """The trees one ``UnitCore`` runs in this life; ``report`` publishes a node's status."""

    def __init__(self, unit: UnitCore, report: Report) -> None:
        self.unit = unit
        self.runner = unit.runner
        self.faults = unit.faults
        self.report = report
        self.trees: OrderedDict[str, TstTree] = OrderedDict()
        """root node-uuid -> tree, in start order."""
        self.nodes: dict[str, TstNode] = {}

    def forget(self) -> None:
        """A reboot forgets the trees (12.1's history; TST-011): what ran has stopped."""
        self.trees.clear()
        self.nodes.clear()

    def add(self, root: Node, com: str, reply: str) -> TstTree:
        """A tree to run, not yet activated: its nodes get their node-uuids (or fresh ones)."""
        tree = TstTree(com, reply)
        tree.root = self._build(root, tree, None)
        self.trees[tree.root.uuid] = tree
        while (old := forget_oldest_ended(self.trees, MAX_TREES)) is not None:
            for n in old.root.walk():
                self.nodes.pop(n.uuid, None)
        return tree

    def _build(self, node: Node, tree: TstTree, parent: TstNode | None) -> TstNode:
        out = TstNode(node.node_uuid or self.unit.fresh_uuid(), node.name,
                      node.params if isinstance(node.params, dict) else {}, tree, parent)
        self.nodes[out.uuid] = out
        out.children = [self._build(c, tree, out) for c in node.children]
        return out

    def drop_tree_of(self, com: str) -> None:
        """Fault tst-resend-starts-twice: the resend starts the same tree again from scratch."""
        for key, tree in list(self.trees.items()):
            if tree.com_uuid == com:
                for n in tree.root.walk():
                    self.nodes.pop(n.uuid, None)
                    if n.task is not None:
                        n.task.node = None
                        self.runner.tasks.pop(n.task.uuid, None)
                del self.trees[key]

    def live_roots(self) -> list[TstNode]:
        """The roots of the trees that have not ended, in start order (signal-unit, 14.3.3)."""
        return [t.root for t in self.trees.values() if not t.ended]

    def executing(self, stale: bool = False) -> list[dict[str, str]]:
        """nodes-executing of tst_execution_info (TST-013); ``stale``: ended nodes too."""
        return [{"node-name": n.name, "node-uuid": n.uuid, "root-uuid": n.tree.root.uuid}
                for t in self.trees.values() for n in t.root.walk()
                if n.live or (stale and n.status is not None)]

    # --- running --------------------------------------------------------------------------------
    def _set(self, node: TstNode, status: str, reason: str = "") -> None:
        node.status = status
        self.report(node, status, reason)

    def activate(self, node: TstNode, now: float) -> None:
        self._set(node, "active")
        if node.name == "seq":
            self._set(node, "running")
            self._next_of_seq(node, now)
        elif node.name == "conc":
            self._set(node, "running")
            for child in node.children:
                if node.live:  # a child that failed at once ends the conc
                    self.activate(child, now)
        else:
            self._begin_task(node, now)

    def _begin_task(self, node: TstNode, now: float) -> None:
        """Run a leaf as a start-task would (12, 14: the same task execution)."""
        unit, runner = self.unit, self.runner
        task = Task(node.uuid, node.name, node.params, unit.specs.get(node.name),
                    node.tree.com_uuid, leg_started=now)
        task.node = lambda status, reason: self._task_status(node, status, reason)
        node.task = task
        plan(task, unit.vehicle, unit.task_seconds)
        runner.preempt(task, f"pre-empted by TST node {node.uuid}")
        if node.ended:  # aborted with the task it pre-empted (a conc of two camera tasks)
            return
        runner.tasks.pop(task.uuid, None)
        runner.remember(task)
        self._task_status(node, "running", "")
        runner.start(task, now)

    def _task_status(self, node: TstNode, status: str, reason: str) -> None:
        """A leaf's task changed status (the unit's task runner calls this)."""
        shown = _TASK_TO_NODE.get(status)
        if shown is None or node.ended or node.status == shown:
            return
        self._set(node, shown, reason if shown in ("failed", "aborted") else "")
        if node.ended:
            self._child_ended(node)

    def _end(self, node: TstNode, status: str, reason: str = "") -> None:
        if node.ended:
            return
        self._set(node, status, reason)
        self._child_ended(node)

    def _child_ended(self, child: TstNode) -> None:
        """TST-010: a composite's final status follows its children's."""
        parent = child.parent
        if parent is None or parent.ended:
            return
        if parent.name == "seq":  # (a revoked node never ran: only a child that ran ends)
            ok = child.status == "succeeded" or "tst-seq-ignores-failure" in self.faults
            if not ok or parent.enough:
                for later in parent.children[parent.next_child:]:
                    self._revoke(later)
                parent.next_child = len(parent.children)
            self._next_of_seq(parent, self.runner.now)
            return
        # conc: when one child does not succeed, the others are aborted
        if child.status != "succeeded":
            for sibling in parent.children:
                if sibling.live:
                    self.abort(sibling, f"sibling {child.uuid} {child.status}")
                elif sibling.status is None:
                    self._revoke(sibling)
        if all(c.ended for c in parent.children):
            self._end(parent, *self._outcome(parent))

    def _next_of_seq(self, seq: TstNode, now: float) -> None:
        """Start the seq's next child that is still to run; none left: the seq ends."""
        while seq.next_child < len(seq.children):
            child = seq.children[seq.next_child]
            seq.next_child += 1
            if child.status is None:  # not revoked by a signal meanwhile
                self.activate(child, now)
                return
        if seq.live:
            self._end(seq, *self._outcome(seq))

    def _outcome(self, node: TstNode) -> tuple[str, str]:
        ran = [c for c in node.children if c.status != "revoked"]
        if node.name == "seq" and "tst-seq-ignores-failure" in self.faults:
            return "succeeded", ""
        failed = next((c for c in ran if c.status == "failed"), None)
        if failed is not None:
            return "failed", f"child {failed.uuid} ({failed.name}) failed"
        aborted = next((c for c in ran if c.status == "aborted"), None)
        if aborted is not None:
            return "aborted", f"child {aborted.uuid} ({aborted.name}) was aborted"
        return "succeeded", ""

    def _revoke(self, node: TstNode) -> None:
        """A node that will never run now (its seq ended before its turn)."""
        for n in node.walk():
            if n.status is None:
                self._set(n, "revoked", "the tree ended before this node ran")

    # --- signals ------------------------------------------------------------------------------
    def apply(self, node: TstNode, signal: str, now: float) -> None:
        """TST-012: what a signal does to a node and the nodes below it."""
        runner = self.runner
        if signal == "$abort":
            if "tst-abort-ignored" not in self.faults:
                self.abort(node, "aborted by $abort")
        elif signal == "$enough":
            for n in node.walk():
                n.enough = True
            for n in node.walk():
                if n.task is not None and n.live:
                    runner.end(n.task, "finished", "ended by $enough")
                elif n.status is None:  # not started yet: it will not be
                    self._revoke(n)
        elif signal == "$pause":
            for n in node.walk():
                if n.status in ("active", "running"):
                    if n.task is not None:
                        runner.pause(n.task, now)
                    else:
                        self._set(n, "paused")
        elif signal == "$continue":
            for n in node.walk():
                if n.status == "paused":
                    if n.task is not None:
                        self._continue_task(n.task, now)
                    else:
                        self._set(n, "running")

    def _continue_task(self, task: Task, now: float) -> None:
        if task.status == "paused":
            self.runner.resume(task, now)
            self.runner.advance(task, now)

    def abort(self, node: TstNode, reason: str) -> None:
        if node.ended:
            return
        if node.status is None:  # not started yet: it will not be
            self._revoke(node)
            return
        if node.task is not None:
            self.runner.end(node.task, "aborted", reason)
            return
        if not node.composite:  # a leaf between 'active' and its task
            self._end(node, "aborted", reason)
            return
        for child in node.children:
            if child.live:
                self.abort(child, reason)
        if node.live:  # a child that was already ended leaves the composite to end here
            self._end(node, *self._outcome(node))

"""The TST level of the reference unit (spec 14): it runs start-tst trees, reports each node on
``tst/feedback``, answers signals on ``tst/response`` and lists its running nodes in
``tst_execution_info``.

Leaf nodes are section-9 tasks run by the unit's own task engine (``conformance.sim.tasks``, as
for start-task: 14 'the Task execution is the same as for level 2'); a leaf's task reports to its
node instead of ``exec/feedback``; its task-uuid is its node-uuid, so it shows in
``tasks-executing`` like any task the unit runs. Composite nodes are ``seq`` (children in order; fails when a
child fails) and ``conc`` (children in parallel; succeeds when all succeed). The decisions this
follows are the catalogue's TST-004..TST-013 and ERR-009, ERR-015..ERR-018.

Commands arrive on the unit's own ``tst/command``, and with an operator address also on the
operator's (14.1: 'usually sent to op0'), a topic many units share: there the unit acts only on
commands that concern it and stays silent otherwise, and it answers and reports on the
operator's ``tst/response`` and ``tst/feedback``.

Like ``UnitCore`` it is free of threads and sockets; ``now`` is ``time.monotonic()`` seconds.
"""

from __future__ import annotations

import copy
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import orjson

from conformance.sim.tasks import Task, plan
from conformance.tst import COMMON_KEYS, COMPOSITES, FINAL, Node, read_tree, unit_name

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

TST_COMMANDS = ("start-tst", "signal-tst-node", "signal-tst-tree", "signal-unit")  # 14.2, 14.3
SIGNALS = ("$abort", "$pause", "$continue", "$enough")  # 14: abort/pause/continue/enough
MAX_TREES = 500
"""Trees remembered per life (the oldest ended ones are forgotten first)."""
MAX_HISTORY = 5000
"""TST commands remembered per life, for resends."""
_TASK_TO_NODE = {"running": "running", "paused": "paused", "finished": "succeeded",
                 "aborted": "aborted", "failed": "failed"}
"""A leaf's task status (12.4) -> its node's status (14.5); task-specific ones are not sent."""


def misdirected(command: str) -> str:
    """The hint a unit adds when a TST command arrives on exec/command (ERR-016)."""
    if command in TST_COMMANDS:
        return f"; {command} is a TST command: send it to tst/command (14.1)"
    return ""


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


class TstEngine:
    """The TST executor of one ``UnitCore``; ``operator`` is the base of the operator whose
    ``tst/command`` it also listens to (None: only its own)."""

    def __init__(self, unit: UnitCore, operator: str | None = None) -> None:
        self.unit = unit
        self.faults = unit.faults
        self.operator = operator
        self.trees: OrderedDict[str, TstTree] = OrderedDict()
        """root node-uuid -> tree, in start order."""
        self.nodes: dict[str, TstNode] = {}
        self.history: OrderedDict[str, tuple[str, dict[str, Any] | None]] = OrderedDict()
        """com-uuid -> (reply base, the response sent or None when none is due), for resends."""
        self.boot = 0  # the unit's first life (made before the unit has counted its boots)

    @property
    def topics(self) -> list[str]:
        """The tst/command topics it listens to: its own, then the operator's."""
        own = [f"{self.unit.base}/tst/command"]
        return own + ([f"{self.operator}/tst/command"] if self.operator else [])

    def _forget_if_rebooted(self) -> None:
        # A reboot forgets the trees (12.1's history; TST-011): what ran has stopped.
        if self.boot != self.unit.boot:
            self.boot = self.unit.boot
            self.trees.clear()
            self.nodes.clear()
            self.history.clear()

    # --- publishing ---------------------------------------------------------------------------
    def _publish(self, base: str, sub: str, body: dict[str, Any]) -> None:
        payload = orjson.dumps(body, option=orjson.OPT_SORT_KEYS)
        if base == self.unit.base:
            self.unit.emit(sub, payload)
        else:  # the operator's topics (14.1)
            self.unit.published += 1
            self.unit._emit(f"{base}/{sub}", payload, False)

    def _answer(self, com: str, reply: str, response: str, fail_reason: str = "",
                **extra: str) -> None:
        """A response (14.4), remembered for a resend."""
        body: dict[str, Any] = {"fail-reason": fail_reason, "response": response,
                                "response-to": com, **extra}
        self.history[com] = (reply, body)
        if len(self.history) > MAX_HISTORY:
            self.history.popitem(last=False)
        self._send(reply, dict(body))

    def _send(self, reply: str, body: dict[str, Any]) -> None:
        reuse = "tst-response-reuses-com-uuid" in self.faults
        body["com-uuid"] = body["response-to"] if reuse else self.unit._fresh_uuid()
        self._publish(reply, "tst/response", body)

    def _feedback(self, node: TstNode, status: str, reason: str = "") -> None:
        """A node's status changes (14.5)."""
        node.status = status
        if status in FINAL and node.composite and "tst-no-final-feedback" in self.faults:
            return
        shown = "finished" if status == "succeeded" and "tst-feedback-finished" in self.faults \
            else status
        root = node is node.tree.root or "tst-root-flag-everywhere" in self.faults
        self._publish(node.tree.reply, "tst/feedback", {
            "com-uuid": self.unit._fresh_uuid(), "fail-reason": reason,
            "node-uuid": node.uuid, "root-flag": root, "status": shown})

    # --- commands -----------------------------------------------------------------------------
    def command(self, payload: bytes, now: float, topic: str) -> None:
        """Handle one message from a tst/command topic. Never raises on hostile input."""
        self._forget_if_rebooted()
        reply = topic.rsplit("/", 2)[0]
        shared = reply != self.unit.base
        try:
            msg = orjson.loads(payload)
        except orjson.JSONDecodeError:
            msg = None
        com = msg.get("com-uuid") if isinstance(msg, dict) else None
        if not isinstance(com, str) or not com or len(com) > 128:
            return  # nothing to answer to (and on a shared topic, maybe not ours)
        assert isinstance(msg, dict)
        if com in self.history and "tst-resend-starts-twice" not in self.faults:
            # 12.1: a resent command reuses its com-uuid; answer it again, do not run it twice.
            where, cached = self.history[com]
            if cached is not None and "tst-resend-unanswered" not in self.faults:
                self._send(where, dict(cached))
            self.history.move_to_end(com)
            return
        command = msg.get("command")
        if command == "start-tst":
            self._start_tst(com, msg, now, reply, shared)
        elif command in ("signal-tst-node", "signal-tst-tree", "signal-unit"):
            self._signal(com, msg, now, reply, shared, command)
        elif not shared:
            self._answer(com, reply, "failed", f"unknown TST command {str(command)[:64]!r}: "
                         f"this unit understands {', '.join(TST_COMMANDS)} (14.2, 14.3)")

    # --- start-tst ----------------------------------------------------------------------------
    def _start_tst(self, com: str, msg: dict[str, Any], now: float, reply: str,
                   shared: bool) -> None:
        tst = msg.get("tst")
        if "tst-common-params-only" in self.faults:
            tst = _without(tst, COMMON_KEYS[0])  # reads 'common-params' only
        root, problems = read_tree(tst)
        me = self.unit.address.name
        if shared and (root is None or root.execunit is None
                       or unit_name(root.execunit) != me):
            return  # the operator's topic: another unit's tree
        if "tst-resend-starts-twice" in self.faults:
            self._drop_tree_of(com)
        if root is None or problems:
            where = "; ".join(f"{p.path}: expected {p.expected} ({p.observed})"
                              for p in problems[:3])
            self._answer(com, reply, "failed", f"malformed tree: {where or 'tst is missing'}")
            return
        reason = self._refusal(root)
        if reason is not None:
            self._answer(com, reply, "failed", reason)
            return
        tree = TstTree(com, reply)
        tree.root = self._build(root, tree, None)
        self.trees[tree.root.uuid] = tree
        self._forget_old_trees()
        response = "running" if "tst-start-answered-running" in self.faults else "started"
        root_uuid = com if "tst-root-uuid-wrong" in self.faults else tree.root.uuid
        self._answer(com, reply, response, "", **{"root-uuid": root_uuid})
        self._activate(tree.root, now)

    def _refusal(self, root: Node) -> str | None:
        """Why this unit cannot run the tree (TST-005), or None."""
        me = self.unit.address.name
        inherited: dict[int, str | None] = {id(root): root.execunit}
        for node in root.walk():
            execunit = node.execunit or inherited.get(id(node))
            for child in node.children:
                inherited[id(child)] = child.execunit or execunit
            if (execunit is not None and unit_name(execunit) != me
                    and "tst-accept-foreign-execunit" not in self.faults):
                return (f"{node.path}: execunit {execunit[:64]} is not this unit (/{me}); "
                        f"this unit runs only its own nodes (no delegation)")
            if node.node_uuid is not None and node.node_uuid in self.nodes:
                return f"{node.path}: node-uuid {node.node_uuid} is already used by a tree"
            if node.composite:
                continue
            spec = self.unit.specs.get(node.name)
            if spec is None:
                hint = " (11.1.1's look-at-angle: section 9 has look-at-bearing, ERR-005)" \
                    if node.name == "look-at-angle" else ""
                return (f"{node.path}: unknown node name {node.name[:64]!r}{hint}; this unit "
                        f"runs seq, conc and {', '.join(self.unit.specs)}")
            problems = spec.problems(node.params)
            if problems:  # each at its JSON path in the command
                return f"invalid parameters for {node.name}: " + "; ".join(
                    f"{node.path}.{p}" if p.startswith("params") else p for p in problems)
        return None

    def _build(self, node: Node, tree: TstTree, parent: TstNode | None) -> TstNode:
        out = TstNode(node.node_uuid or self.unit._fresh_uuid(), node.name,
                      node.params if isinstance(node.params, dict) else {}, tree, parent)
        self.nodes[out.uuid] = out
        out.children = [self._build(c, tree, out) for c in node.children]
        return out

    def _forget_old_trees(self) -> None:
        while len(self.trees) > MAX_TREES:
            old = next((k for k, t in self.trees.items() if t.ended), None)
            if old is None:
                return
            for n in self.trees.pop(old).root.walk():
                self.nodes.pop(n.uuid, None)

    def _drop_tree_of(self, com: str) -> None:
        """Fault tst-resend-starts-twice: the resend starts the same tree again from scratch."""
        for key, tree in list(self.trees.items()):
            if tree.com_uuid == com:
                for n in tree.root.walk():
                    self.nodes.pop(n.uuid, None)
                    if n.task is not None:
                        n.task.node = None
                        self.unit.tasks.pop(n.task.uuid, None)
                del self.trees[key]

    # --- running --------------------------------------------------------------------------------
    def _activate(self, node: TstNode, now: float) -> None:
        self._feedback(node, "active")
        if node.name == "seq":
            self._feedback(node, "running")
            self._next_of_seq(node, now)
        elif node.name == "conc":
            self._feedback(node, "running")
            for child in node.children:
                if node.live:  # a child that failed at once ends the conc
                    self._activate(child, now)
        else:
            self._begin_task(node, now)

    def _begin_task(self, node: TstNode, now: float) -> None:
        """Run a leaf as a start-task would (12, 14: the same task execution)."""
        unit = self.unit
        task = Task(node.uuid, node.name, node.params, unit.specs.get(node.name),
                    node.tree.com_uuid, leg_started=now)
        task.node = lambda status, reason: self._task_status(node, status, reason)
        node.task = task
        plan(task, unit.vehicle, unit.task_seconds)
        for other in list(unit.tasks.values()):  # the vehicle/camera/detector is this task's
            if not other.ended and other.group == task.group:
                unit._end(other, "aborted", f"pre-empted by TST node {node.uuid}")
        if node.ended:  # aborted with the task it pre-empted (a conc of two camera tasks)
            return
        unit.tasks.pop(task.uuid, None)
        unit._remember(task)
        self._task_status(node, "running", "")
        if task.legs:
            unit._start_leg(task)
        unit._advance_task(task, now)

    def _task_status(self, node: TstNode, status: str, reason: str) -> None:
        """A leaf's task changed status (the unit's task engine calls this)."""
        shown = _TASK_TO_NODE.get(status)
        if shown is None or node.ended or node.status == shown:
            return
        self._feedback(node, shown, reason if shown in ("failed", "aborted") else "")
        if node.ended:
            self._child_ended(node)

    def _end(self, node: TstNode, status: str, reason: str = "") -> None:
        if node.ended:
            return
        self._feedback(node, status, reason)
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
            self._next_of_seq(parent, self._now())
            return
        # conc: when one child does not succeed, the others are aborted
        if child.status != "succeeded":
            for sibling in parent.children:
                if sibling.live:
                    self._abort(sibling, f"sibling {child.uuid} {child.status}")
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
                self._activate(child, now)
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
                self._feedback(n, "revoked", "the tree ended before this node ran")

    def _now(self) -> float:
        last = self.unit._last_step
        return last if last is not None else 0.0

    # --- signals ------------------------------------------------------------------------------
    def _signal(self, com: str, msg: dict[str, Any], now: float, reply: str, shared: bool,
                command: str) -> None:
        signal = msg.get("signal")

        def refuse(reason: str) -> None:
            if not shared:  # the operator's topic: someone else's command, maybe
                self._answer(com, reply, "failed", reason)

        if command == "signal-unit":
            unit = msg.get("unit")
            if not isinstance(unit, str) or unit_name(unit) != self.unit.address.name:
                refuse(f"signal-unit names unit {str(unit)[:64]!r}; this is "
                       f"/{self.unit.address.name} (14.3.3)")
                return
            targets = [t.root for t in self.trees.values() if not t.ended]
        else:
            node_uuid = msg.get("node-uuid")
            node = self.nodes.get(node_uuid) if isinstance(node_uuid, str) else None
            if node is None:
                if shared:
                    return
                if "tst-signal-unknown-node-ok" in self.faults:
                    self._answer(com, reply, "ok")
                else:
                    refuse(f"no TST node with node-uuid {str(node_uuid)[:64]} is known")
                return
            if command == "signal-tst-tree" and node.parent is not None:
                refuse(f"{node.uuid} is not the root of a tree: signal-tst-tree takes the "
                       f"root node-uuid {node.tree.root.uuid} (14.3.2)")
                return
            if node.tree.ended:
                refuse(f"the tree of node {node.uuid} has ended ({node.tree.root.status})")
                return
            if node.ended:
                refuse(f"node {node.uuid} has ended ({node.status})")
                return
            targets = [node]
        if signal not in SIGNALS:
            refuse(f"unknown signal {str(signal)[:64]!r}: TST nodes understand "
                   f"{', '.join(SIGNALS)}")
            return
        self._answer(com, reply, "ok")
        self.unit._step(now)
        for target in targets:
            self._apply(target, signal, now)

    def _apply(self, node: TstNode, signal: str, now: float) -> None:
        """TST-012: what a signal does to a node and the nodes below it."""
        if signal == "$abort":
            if "tst-abort-ignored" not in self.faults:
                self._abort(node, "aborted by $abort")
        elif signal == "$enough":
            for n in node.walk():
                n.enough = True
            for n in node.walk():
                if n.task is not None and n.live:
                    self.unit._end(n.task, "finished", "ended by $enough")
                elif n.status is None:  # not started yet: it will not be
                    self._revoke(n)
        elif signal == "$pause":
            for n in node.walk():
                if n.status in ("active", "running"):
                    if n.task is not None:
                        self._pause_task(n.task, now)
                    else:
                        self._feedback(n, "paused")
        elif signal == "$continue":
            for n in node.walk():
                if n.status == "paused":
                    if n.task is not None:
                        self._continue_task(n.task, now)
                    else:
                        self._feedback(n, "running")

    def _abort(self, node: TstNode, reason: str) -> None:
        if node.ended:
            return
        if node.status is None:  # not started yet: it will not be
            self._revoke(node)
            return
        if node.task is not None:
            self.unit._end(node.task, "aborted", reason)
            return
        if not node.composite:  # a leaf between 'active' and its task
            self._end(node, "aborted", reason)
            return
        for child in node.children:
            if child.live:
                self._abort(child, reason)
        if node.live:  # a child that was already ended leaves the composite to end here
            self._end(node, *self._outcome(node))

    def _pause_task(self, task: Task, now: float) -> None:
        # As signal-task's $pause (12.2.2): the task keeps its place and reports 'paused'.
        if task.status != "running":
            return
        task.status = "paused"
        leg = task.legs[task.leg] if task.leg < len(task.legs) else None
        if leg is not None and leg.point is None:
            task.paused_left = leg.seconds - (now - task.leg_started)
        if task.group == "motion":
            self.unit.vehicle.stop()
        assert task.node is not None
        task.node("paused", "")

    def _continue_task(self, task: Task, now: float) -> None:
        if task.status != "paused":
            return
        task.status = "running"
        task.resume_clock(now)
        if task.group == "motion" and task.leg < len(task.legs):
            self.unit._start_leg(task)
        assert task.node is not None
        task.node("running", "")
        self.unit._advance_task(task, now)

    # --- tst_execution_info -----------------------------------------------------------------------
    def fill_info(self, msg: dict[str, Any]) -> None:
        """What the engine adds to tst_execution_info: its type (ERR-018) and the nodes that run
        (TST-013)."""
        self._forget_if_rebooted()
        if "tst-info-type-upper" in self.faults:
            msg["type"] = "TSTExecutionInfo"
        stale = "tst-info-stale-nodes" in self.faults
        msg["nodes-executing"] = [
            {"node-name": n.name, "node-uuid": n.uuid, "root-uuid": n.tree.root.uuid}
            for t in self.trees.values() for n in t.root.walk()
            if n.live or (stale and n.status is not None)]


def _without(tst: Any, key: str) -> Any:
    """The tree with ``key`` removed from every node (fault tst-common-params-only)."""
    tree = copy.deepcopy(tst)
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            node.pop(key, None)
            children = node.get("children")
            if isinstance(children, list):
                stack.extend(children)
    return tree

"""The TST level of the reference unit (spec 14): what arrives on ``tst/command`` (start-tst,
signals) and goes out on ``tst/response`` and ``tst/feedback``, and the running nodes it lists in
``tst_execution_info``. The trees themselves run in ``conformance.sim.tst_tree``. The decisions
this follows are the catalogue's TST-004..TST-013 and ERR-009, ERR-015..ERR-018.

Commands arrive on the unit's own ``tst/command``, and with an operator address also on the
operator's (14.1: 'usually sent to op0'), a topic many units share: there the unit acts only on
commands that concern it and stays silent otherwise, and it answers and reports on the
operator's ``tst/response`` and ``tst/feedback``.

Like ``UnitCore`` it is free of threads and sockets; ``now`` is ``time.monotonic()`` seconds.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, Any

import orjson

from conformance.sim.memory import Resends
from conformance.sim.tst_tree import Trees, TstNode
from conformance.tst import COMMON_KEYS, FINAL, Node, read_tree, unit_name

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

TST_COMMANDS = ("start-tst", "signal-tst-node", "signal-tst-tree", "signal-unit")  # 14.2, 14.3
SIGNALS = ("$abort", "$pause", "$continue", "$enough")  # 14: abort/pause/continue/enough
EXAMPLE_FIELDS = {  # variant strict: the fields of the spec's examples, per command
    "start-tst": frozenset({"com-uuid", "command", "receiver", "sender", "tst"}),  # 11
    "signal-tst-node": frozenset({"com-uuid", "command", "node-uuid", "sender", "signal"}),
    "signal-tst-tree": frozenset({"com-uuid", "command", "node-uuid", "sender", "signal"}),
    "signal-unit": frozenset({"com-uuid", "command", "sender", "signal", "unit"}),  # 14.3
}
NODE_FIELDS = frozenset({"children", "common_params", "name", "params"})
"""Variant strict: every node of 11's examples has these, and common_params has both
execunit and node-uuid."""


def misdirected(command: str) -> str:
    """The hint a unit adds when a TST command arrives on exec/command (ERR-016)."""
    if command in TST_COMMANDS:
        return f"; {command} is a TST command: send it to tst/command (14.1)"
    return ""


class TstEngine:
    """The TST executor of one ``UnitCore``; ``operator`` is the base of the operator whose
    ``tst/command`` it also listens to (None: only its own)."""

    def __init__(self, unit: UnitCore, operator: str | None = None) -> None:
        self.unit = unit
        self.faults = unit.faults
        self.variants = unit.variants
        self.operator = operator
        self.trees = Trees(unit, self._feedback)
        self.history: Resends[tuple[str, dict[str, Any]]] = Resends()
        """com-uuid -> (reply base, the response sent), for resends."""
        self.deferred: list[tuple[str, dict[str, Any]]] | None = None
        """Variant feedback-first: the responses of the command being handled, sent after
        the node feedback it causes."""

    @property
    def topics(self) -> list[str]:
        """The tst/command topics it listens to: its own, then the operator's."""
        own = [f"{self.unit.base}/tst/command"]
        return own + ([f"{self.operator}/tst/command"] if self.operator else [])

    def forget(self) -> None:
        """A reboot forgets the trees and the commands (12.1's history; TST-011)."""
        self.trees.forget()
        self.history.clear()

    # --- publishing ---------------------------------------------------------------------------
    def _answer(self, com: str, reply: str, response: str, fail_reason: str = "",
                **extra: str) -> None:
        """A response (14.4), remembered for a resend."""
        body: dict[str, Any] = {"fail-reason": fail_reason, "response": response,
                                "response-to": com, **extra}
        if "terse" in self.variants and response != "failed":
            del body["fail-reason"]  # 14.4.1's examples have none
        self.history.remember(com, (reply, body))
        self._send(reply, dict(body))

    def _send(self, reply: str, body: dict[str, Any]) -> None:
        if self.deferred is not None:
            self.deferred.append((reply, body))
            return
        reuse = "tst-response-reuses-com-uuid" in self.faults
        body["com-uuid"] = body["response-to"] if reuse else self.unit.fresh_uuid()
        self.unit.send("tst/response", body, base=reply)

    def _feedback(self, node: TstNode, status: str, reason: str = "") -> None:
        """Report a node's new status (14.5); the operator's topics when it came from there."""
        if status in FINAL and node.composite and "tst-no-final-feedback" in self.faults:
            return
        shown = "finished" if status == "succeeded" and "tst-feedback-finished" in self.faults \
            else status
        root = node is node.tree.root or "tst-root-flag-everywhere" in self.faults
        body = {"com-uuid": self.unit.fresh_uuid(), "fail-reason": reason,
                "node-uuid": node.uuid, "root-flag": root, "status": shown}
        if "terse" in self.variants:  # the schema's required fields only (14.5)
            del body["root-flag"]
            if not reason:
                del body["fail-reason"]
        self.unit.send("tst/feedback", body, base=node.tree.reply)

    # --- commands -----------------------------------------------------------------------------
    def command(self, payload: bytes, now: float, topic: str) -> None:
        """Handle one message from a tst/command topic. Never raises on hostile input."""
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
            where, cached = self.history.resent(com)
            if "tst-resend-unanswered" not in self.faults:
                self._send(where, dict(cached))
            return
        command = msg.get("command")
        if "strict" in self.variants and command in EXAMPLE_FIELDS:
            reason = _unlike_examples(command, msg)
            if reason is not None:
                if not shared:  # on an operator's topic it may be another unit's
                    self._answer(com, reply, "failed", reason)
                return
        if command in TST_COMMANDS:
            if "feedback-first" in self.variants:
                self.deferred = []
            try:
                if command == "start-tst":
                    self._start_tst(com, msg, now, reply, shared)
                else:
                    self._signal(com, msg, now, reply, shared, command)
            finally:
                deferred, self.deferred = self.deferred or [], None
                for args in deferred:
                    self._send(*args)
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
            self.trees.drop_tree_of(com)
        if root is None or problems:
            where = "; ".join(f"{p.path}: expected {p.expected} ({p.observed})"
                              for p in problems[:3])
            self._answer(com, reply, "failed", f"malformed tree: {where or 'tst is missing'}")
            return
        reason = self._refusal(root)
        if reason is not None:
            self._answer(com, reply, "failed", reason)
            return
        tree = self.trees.add(root, com, reply)
        response = "running" if "tst-start-answered-running" in self.faults else "started"
        root_uuid = com if "tst-root-uuid-wrong" in self.faults else tree.root.uuid
        self._answer(com, reply, response, "", **{"root-uuid": root_uuid})
        if "announce-nodes" in self.variants:  # 14.5's not-active for every node first
            for node in tree.root.walk():
                self._feedback(node, "not-active")
        self.trees.activate(tree.root, now)

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
            if node.node_uuid is not None and node.node_uuid in self.trees.nodes:
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

    # --- signals ------------------------------------------------------------------------------
    def _signal(self, com: str, msg: dict[str, Any], now: float, reply: str, shared: bool,
                command: str) -> None:
        signal = msg.get("signal")

        def refuse(reason: str) -> None:
            self._answer(com, reply, "failed", reason)

        if command == "signal-unit":
            unit = msg.get("unit")
            if not isinstance(unit, str) or unit_name(unit) != self.unit.address.name:
                if not shared:  # on an operator's topic (14.1): another unit's command
                    refuse(f"signal-unit names unit {str(unit)[:64]!r}; this is "
                           f"/{self.unit.address.name} (14.3.3)")
                return
            targets = self.trees.live_roots()
        else:
            node = self._signalled_node(com, msg, reply, shared, command)
            if node is None:
                return
            targets = [node]
        if signal not in SIGNALS:
            refuse(f"unknown signal {str(signal)[:64]!r}: TST nodes understand "
                   f"{', '.join(SIGNALS)}")
            return
        spec = self.unit.specs.get(targets[0].name) if len(targets) == 1 else None
        if spec is not None and not targets[0].composite and signal not in spec.signals:
            # 5.3: a leaf runs a task, which understands the signals its task lists.
            refuse(f"task {spec.name} does not understand {signal}; it understands "
                   f"{', '.join(spec.signals)}")
            return
        self._answer(com, reply, "ok")
        self.unit.runner.step(now)
        for target in targets:
            self.trees.apply(target, signal, now)

    def _signalled_node(self, com: str, msg: dict[str, Any], reply: str, shared: bool,
                        command: str) -> TstNode | None:
        """The live node a signal-tst-node or -tree names, or None when there is none (the
        command then answered, or left to the unit it concerns: 14.1)."""
        node_uuid = msg.get("node-uuid")
        node = self.trees.nodes.get(node_uuid) if isinstance(node_uuid, str) else None
        why = None
        if node is None:
            if shared:  # on an operator's topic (14.1): another unit's node, maybe
                return None
            if "tst-signal-unknown-node-ok" in self.faults:
                self._answer(com, reply, "ok")
                return None
            why = f"no TST node with node-uuid {str(node_uuid)[:64]} is known"
        elif command == "signal-tst-tree" and node.parent is not None:
            why = (f"{node.uuid} is not the root of a tree: signal-tst-tree takes the "
                   f"root node-uuid {node.tree.root.uuid} (14.3.2)")
        elif node.tree.ended:
            why = f"the tree of node {node.uuid} has ended ({node.tree.root.status})"
        elif node.ended:
            why = f"node {node.uuid} has ended ({node.status})"
        if why is not None:
            self._answer(com, reply, "failed", why)
            return None
        return node

    # --- tst_execution_info -----------------------------------------------------------------------
    def fill_info(self, msg: dict[str, Any]) -> None:
        """What the engine adds to tst_execution_info: its type (ERR-018) and the nodes that run
        (TST-013)."""
        if "tst-info-type-upper" in self.faults:
            msg["type"] = "TSTExecutionInfo"
        msg["nodes-executing"] = self.trees.executing(stale="tst-info-stale-nodes" in self.faults)


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


def _unlike_examples(command: str, msg: dict[str, Any]) -> str | None:
    """Variant strict: why ``msg`` is not shaped like the spec's examples of ``command`` (11,
    14.3), or None. receiver (11's examples) may be left out: 14.1 sends to the unit's own
    topic too."""
    allowed = EXAMPLE_FIELDS[command]
    extra = sorted(set(msg) - allowed)
    if extra:
        return f"field {str(extra[0])[:64]!r} is in no example of {command}"
    missing = sorted(allowed - {"receiver"} - set(msg))
    if missing:
        return f"{command} without {', '.join(missing)} (the spec's examples have it)"
    if command == "signal-unit" and not str(msg["unit"]).startswith("/"):
        return "unit is '/NAME' in 14.3.3's example"
    if command != "start-tst":
        return None
    stack: list[tuple[str, Any]] = [("tst", msg["tst"])]
    while stack:
        path, node = stack.pop()
        if not isinstance(node, dict) or set(node) != NODE_FIELDS:
            shown = sorted(node) if isinstance(node, dict) else type(node).__name__
            return (f"{path}: every node of 11's examples has exactly "
                    f"{', '.join(sorted(NODE_FIELDS))} ({str(shown)[:120]})")
        common = node["common_params"]
        if not isinstance(common, dict) or set(common) != {"execunit", "node-uuid"}:
            return (f"{path}.common_params: every node of 11's examples has execunit and "
                    f"node-uuid")
        if not str(common["execunit"]).startswith("/"):
            return f"{path}.common_params.execunit: '/NAME' in every example of section 11"
        children = node["children"]
        if isinstance(children, list):
            stack.extend((f"{path}.children[{i}]", c) for i, c in enumerate(children))
    return None

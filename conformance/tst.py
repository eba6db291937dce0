"""TST trees (spec 11, 14): read the tree of a start-tst command, and list what is wrong with it.

The one place a TST tree is read, shared by the validator (a commander's start-tst, TST-014),
``waraps-conformance validate --tst`` (a mission planner's plan) and the reference unit
(``conformance.sim.tst``), so all three agree on what a well-formed tree is.

A node is ``{"name", "params", "children", "common_params": {"execunit", "node-uuid"}}``.
v0.7 names no composite node: ``seq`` (children in order) and ``conc`` (children in parallel)
are the TST system's; every other node is a task of section 9 and has no children.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

COMPOSITES = ("seq", "conc")
STATUSES = ("not-active", "active", "waiting", "running", "failed", "revoked", "paused",
            "aborted", "succeeded")  # 14.5
FINAL = ("succeeded", "failed", "aborted", "revoked")
"""TST-009's decision: the statuses after which a node says nothing more."""
COMMON_KEYS = ("common_params", "common-params")  # ERR-009: the examples', then practice's
MAX_NODES = 1000
MAX_DEPTH = 32
"""A tree larger or deeper than this is refused unread (no mission comes near either)."""


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a tree: where (a JSON path), what was expected and observed."""

    path: str
    expected: str
    observed: str
    rule: str = "TST-014"
    in_schema: bool = False
    """The start-tst schema states it too (the validator reports it from there, as TST-001)."""


@dataclass
class Node:
    """One node of a tree as sent: ``path`` is its JSON path in the command (``$.tst``,
    ``$.tst.children[1]``); ``node_uuid`` and ``execunit`` are None where not set."""

    path: str
    name: str
    params: Any
    node_uuid: str | None
    execunit: str | None
    children: list[Node] = field(default_factory=list)

    @property
    def composite(self) -> bool:
        return self.name in COMPOSITES

    def walk(self) -> Iterator[Node]:
        """This node and every node below it, depth first, in order."""
        yield self
        for child in self.children:
            yield from child.walk()


def unit_name(text: str) -> str:
    """The unit a TST command names: '/dji21' (14.3.3, 11's '/op0') or 'dji21' (ERR-017),
    or a full unit address; its last level."""
    return text.strip().rstrip("/").rsplit("/", 1)[-1]


def common_params(node: dict[str, Any]) -> tuple[dict[str, Any], str | None]:
    """The node's common parameters under either spelling (ERR-009), and what is wrong with
    them (not an object, or both spellings present and different)."""
    found = [(k, node[k]) for k in COMMON_KEYS if k in node]
    if not found:
        return {}, None
    if len(found) == 2 and found[0][1] != found[1][1]:
        return {}, "common_params and common-params both given, and they differ"
    key, value = found[0]
    if not isinstance(value, dict):
        return {}, f"{key} is an object {{execunit, node-uuid}}"
    return value, None


def _str(value: Any) -> str | None:
    return value if isinstance(value, str) and value else None


def read_tree(tst: Any, path: str = "$.tst") -> tuple[Node | None, list[Problem]]:
    """The tree of a start-tst's ``tst`` value, and every problem of its structure (TST-014).

    The node objects are returned even when there are problems, as far as they could be read
    (None when the root is not an object). Parameters are not judged here: that is the task
    schemas' (TASK-001) and, for a unit, its own task specifications'.
    """
    reader = _TreeReader()
    return reader.read(tst, path, 0), reader.problems


class _TreeReader:
    """The reading of one tree: its problems, where each node-uuid was first seen, the nodes
    counted (bounded: ``MAX_NODES``, ``MAX_DEPTH``)."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []
        self.seen: dict[str, str] = {}
        self.count = 0

    def read(self, value: Any, where: str, depth: int) -> Node | None:
        """The node at ``where`` and the nodes below it, as far as they could be read."""
        problems = self.problems
        self.count += 1
        if self.count > MAX_NODES or depth > MAX_DEPTH:
            if self.count == MAX_NODES + 1 or depth == MAX_DEPTH + 1:
                problems.append(Problem(where, f"at most {MAX_NODES} nodes, {MAX_DEPTH} deep",
                                        "more"))
            return None
        if not isinstance(value, dict):
            problems.append(Problem(where, "a node object {name, params, children, "
                                    "common_params}", type(value).__name__, in_schema=True))
            return None
        name = value.get("name")
        if not isinstance(name, str) or not name:
            problems.append(Problem(f"{where}.name", "the node's name (a task of section 9, "
                                    "seq or conc)", "missing" if name is None else repr(name),
                                    in_schema=not isinstance(name, str)))
            name = ""
        node_uuid, execunit = self._common(value, where)
        node = Node(where, name, value.get("params", {}), node_uuid, execunit)
        for i, child in enumerate(self._children(value, where, node)):
            got = self.read(child, f"{where}.children[{i}]", depth + 1)
            if got is not None:
                node.children.append(got)
        return node

    def _common(self, value: dict[str, Any], where: str) -> tuple[str | None, str | None]:
        """The node's node-uuid (one of its own in the tree) and execunit, from its one set of
        common parameters (ERR-009: either spelling)."""
        common, wrong = common_params(value)
        key = next((k for k in COMMON_KEYS if k in value), COMMON_KEYS[0])
        if wrong:
            self.problems.append(Problem(f"{where}.{key}", "one set of common parameters",
                                         wrong))
        node_uuid = _str(common.get("node-uuid"))
        if node_uuid is not None:
            if node_uuid in self.seen:
                self.problems.append(Problem(f"{where}.{key}.node-uuid",
                                             f"a node-uuid of its own (also the node-uuid at "
                                             f"{self.seen[node_uuid]})", node_uuid))
            else:
                self.seen[node_uuid] = where
        return node_uuid, _str(common.get("execunit"))

    def _children(self, value: dict[str, Any], where: str, node: Node) -> list[Any]:
        """The node's children as sent: a composite (seq, conc) has some, a task none (14)."""
        children = value.get("children", [])
        if not isinstance(children, list):
            self.problems.append(Problem(f"{where}.children", "a list of nodes",
                                         type(children).__name__, in_schema=True))
            children = []
        if node.composite and not children:
            self.problems.append(Problem(f"{where}.children", f"{node.name} runs its "
                                         "children: at least one", "none"))
        elif node.name and not node.composite and children:
            self.problems.append(Problem(f"{where}.children", f"none: {node.name} is a task, "
                                         "only seq and conc have children",
                                         f"{len(children)} children"))
        return children

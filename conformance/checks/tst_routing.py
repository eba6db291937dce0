"""Whose TST conversation a message on an operator's tst topics is (14.1).

14.1: TST commands are 'usually sent to op0' (``op0/tst/command``), a topic many units share,
and answered on ``op0/tst/response`` and ``op0/tst/feedback``. The Monitor judges such a
conversation as the unit's it concerns, decided from the traffic alone:

- a start-tst concerns the unit its root's ``execunit`` names, a signal-unit the unit its
  ``unit`` names (ERR-017: '/NAME' or 'NAME'), a signal-tst-node or -tree the unit whose tree
  holds the node;
- a response concerns the unit of the command it answers (``response-to``), and its
  ``root-uuid`` then names a node of that unit;
- feedback concerns the unit whose tree holds the node.

The unit must be one the observer follows (a unit it has seen, or the unit under test), and
the operator must not itself declare 'tst execution': an operator that runs or delegates trees
answers for them, and they stay its own. What cannot be attributed stays the operator's.
Nodes a unit named itself (a tree sent without node-uuids) cannot be attributed beyond the root.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from conformance.checks.base import BoundedDict
from conformance.topics import TopicKind, UnitAddress
from conformance.tst import common_params, unit_name

COMMANDS_KEPT = 4096
NODES_KEPT = 16384


class TstRouting:
    """What the observation learnt about who runs what: com-uuids and node-uuids -> unit."""

    def __init__(self) -> None:
        self.by_com: BoundedDict = BoundedDict(COMMANDS_KEPT)
        self.by_node: BoundedDict = BoundedDict(NODES_KEPT)

    def party(self, kind: TopicKind, m: Any, resolve: Callable[[str], UnitAddress | None]
              ) -> UnitAddress | None:
        """The unit a message on a shared tst topic concerns, or None (the topic's own).
        ``resolve`` turns a unit name into the address of a unit the observer follows."""
        if not isinstance(m, dict):
            return None
        if kind is TopicKind.TST_COMMAND:
            return self._command(m, resolve)
        if kind is TopicKind.TST_RESPONSE:
            address = self.by_com.get(m.get("response-to"))
            root = m.get("root-uuid")
            if address is not None and isinstance(root, str):
                self.by_node[root] = address
            return address
        if kind is TopicKind.TST_FEEDBACK:
            return self.by_node.get(m.get("node-uuid"))
        return None

    def _command(self, m: dict[str, Any], resolve: Callable[[str], UnitAddress | None]
                 ) -> UnitAddress | None:
        command, com = m.get("command"), m.get("com-uuid")
        address: UnitAddress | None = None
        if command == "start-tst":
            tst = m.get("tst")
            common = common_params(tst)[0] if isinstance(tst, dict) else {}
            execunit = common.get("execunit")
            if isinstance(execunit, str):
                address = resolve(unit_name(execunit))
            if address is not None:
                for node_uuid in _node_uuids(tst):
                    self.by_node[node_uuid] = address
        elif command == "signal-unit":
            unit = m.get("unit")
            address = resolve(unit_name(unit)) if isinstance(unit, str) else None
        elif command in ("signal-tst-node", "signal-tst-tree"):
            address = self.by_node.get(m.get("node-uuid"))
        if address is not None and isinstance(com, str):
            self.by_com[com] = address
        return address


def _node_uuids(tst: Any, limit: int = 1000) -> list[str]:
    out: list[str] = []
    stack = [tst]
    while stack and len(out) < limit:
        node = stack.pop()
        if not isinstance(node, dict):
            continue
        uuid = common_params(node)[0].get("node-uuid")
        if isinstance(uuid, str):
            out.append(uuid)
        children = node.get("children")
        if isinstance(children, list):
            stack.extend(children[:limit])
    return out

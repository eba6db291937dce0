"""A TST command on tst/command opens a conversation, or continues one when resent; a start-tst
opens its tree (14.2, 14.3).

EXEC-008 (the commander's): 2 'Use UUID to identify a communication message', so the same
com-uuid with other content makes a resend ambiguous. The state is ``tst_conversation``'s; the
answers are judged by ``tst_response``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator

import orjson

from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import str_of
from conformance.checks.registry import check
from conformance.checks.tst_conversation import (
    TST_COMMANDS,
    TST_CONVERSATIONS,
    TstCommand,
    TstConversations,
    TstNode,
    TstTree,
    tst_conversations,
)
from conformance.message import Message
from conformance.topics import TopicKind
from conformance.tst import Node, read_tree
from conformance.validator import Validation
from conformance.violation import Violation, head


@check("EXEC-008", on=(TopicKind.TST_COMMAND,), reads=(TST_CONVERSATIONS,))
def tst_command_opens_conversation(ctx: CheckContext, unit: UnitState, msg: Message,
                                   v: Validation) -> Iterator[Violation]:
    """A TST command with a com-uuid opens (or, resent, continues) a conversation; a start-tst
    opens its tree. The same com-uuid with other content is EXEC-008's (the commander's):
    2 'Use UUID to identify a communication message'."""
    m = v.message
    com_uuid, name = str_of(m, "com-uuid"), str_of(m, "command")
    if com_uuid is None or name not in TST_COMMANDS or not isinstance(m, dict):
        return
    c = tst_conversations(unit)
    t = msg.time
    if c.first_command is None:
        c.first_command = t
    content = orjson.dumps(m, option=orjson.OPT_SORT_KEYS)
    digest = hashlib.blake2b(content, digest_size=16).digest()
    before = c.commands.get(com_uuid)
    if before is not None and before.digest == digest:
        # 12.1 (and 14): a resend. It is answered again and starts nothing twice.
        c.resent(before, t)
        if before.tree is not None:
            before.tree.resent = t
        return
    if before is not None:
        before.judged = True
        c.pending.pop(com_uuid, None)
        unit.examine("EXEC-008")
        yield Violation.of(
            "EXEC-008", expected=f"com-uuid {com_uuid} reused only to resend the same command",
            observed=f"another {name} than the {before.name} sent {t - before.time:.2f} s "
                     f"earlier", topic=msg.topic, path="$.com-uuid", time=t, payload=msg.payload,
            detail="generate a fresh com-uuid for every new command")
        return
    unit.examine("EXEC-008")
    cmd = TstCommand(com_uuid, name, t, m, digest, head(memoryview(content), 160), c.life,
                     msg.topic)
    c.commands[com_uuid] = cmd
    c.await_answer(cmd)
    if name == "start-tst":
        root, problems = read_tree(m.get("tst"))
        if root is not None and not problems:  # a malformed tree is TST-014's and TST-005's
            cmd.tree = _open_tree(c, cmd, root)


def _open_tree(c: TstConversations, cmd: TstCommand, root: Node) -> TstTree:
    """The tree of a start-tst, its nodes known by the node-uuids the commander set (a node
    without one gets the unit's own, which the traffic cannot tell: it is not judged)."""
    tree = TstTree(cmd, c.life)

    def build(node: Node, parent: TstNode | None) -> TstNode:
        uuid = node.node_uuid or f"(unnamed {id(node)})"
        out = TstNode(uuid, node.name, tree, parent, parent is None)
        if node.node_uuid is not None:
            known = c.nodes.get(uuid)
            if known is not None and known.tree is not tree and known.tree.life == c.life \
                    and known.tree.state != "refused":
                tree.ambiguous = True  # a node-uuid of a tree already running: TST-005's
            else:
                c.nodes[uuid] = out
        out.children = [build(child, out) for child in node.children]
        return out

    tree.root = build(root, None)
    tree.roots.append(tree.root)
    c.trees[cmd.com_uuid] = tree
    return tree

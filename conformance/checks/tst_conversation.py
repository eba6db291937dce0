"""TST conversations (spec 14; DESIGN 'TST is the same pattern one level up'), judged from traffic.

A start-tst on ``tst/command`` opens a tree: its response (``response-to`` = its com-uuid) says
'started' with ``root-uuid`` = the root's node-uuid (TST-004; 'running' is ERR-015's reading and
opens the tree too), then feedback follows every node to a final status (TST-009) with
``root-flag`` on the root only (TST-008), composites ending as their children say (TST-010).
Signals address a node, a tree or the unit: answered 'ok', or 'failed' with a reason for an
unknown node or an ended tree (TST-011), and an 'ok' implies the feedback the signal asks for
(TST-012). A resend (same com-uuid, same content) is answered again (TST-007) and starts
nothing twice (TST-006). ``tst_execution_info``'s nodes-executing lists the nodes that run
(TST-013). The same code judges a recording in ``lint`` and the suite's commands in
``pytest --unit``; conversations of exec commands are ``checks/conversation.py``'s, whose
helpers this module shares.

Only trees the traffic started are judged: feedback for a node no start-tst (or root-uuid) of
the observation named is not. Commands sent to an operator's ``tst/command`` (14.1: 'usually
sent to op0') reach this module as the unit's they concern: ``checks/tst_routing.py``.

Blame goes to the root cause: feedback after a final status that a resend caused is TST-006's,
not TST-009's; a composite that never says its end is TST-009's, not TST-012's or TST-010's;
a node that leaves nodes-executing without a final status is TST-009's, not TST-013's;
commands a dead unit (HB-012) left unanswered are its death's.

Everything is bounded: trees, nodes and commands are LRUs, open expectations are capped, and
what was dropped is counted and said in the report.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict
from collections.abc import Iterator
from typing import Any

import orjson

from conformance.checks.base import BoundedDict, CheckContext, UnitState, check
from conformance.checks.conversation import _str, _timeout, _violation, overdue, per_unit
from conformance.message import Message
from conformance.topics import TopicKind
from conformance.tst import FINAL, Node, read_tree, unit_name
from conformance.validator import Validation
from conformance.violation import Violation

COMMANDS_KEPT = 1024
TREES_KEPT = 512
NODES_KEPT = 8192
PENDING_KEPT = 256
EXPECTS_KEPT = 256
WATCH_KEPT = 512
"""Nodes that ended recently, watched in nodes-executing (TST-013's staleness)."""
TST_COMMANDS = ("start-tst", "signal-tst-node", "signal-tst-tree", "signal-unit")  # 14.2, 14.3
SIGNALS = ("$abort", "$pause", "$continue", "$enough")  # 14: abort/pause/continue/enough
ANSWER_RULE = {"start-tst": "TST-004", "signal-tst-node": "TST-011",
               "signal-tst-tree": "TST-011", "signal-unit": "TST-011"}
STARTED = ("started", "running")  # 14.4.4; 'running' is ERR-015's reading (the validator's)
READ_AS = {"finished": "succeeded"}
"""A near miss of 14.5's vocabulary (TST-003, the validator's) is read as the status it means."""
LIVE = frozenset({"active", "running", "paused", "waiting"})
SIGNAL_FEEDBACK = {"$abort": "aborted", "$enough": "succeeded", "$pause": "paused",
                   "$continue": "running"}
"""TST-012's decision: the status a node signalled (and answered 'ok') reports next."""


class TstCommand:
    """One TST command sent to a unit, and what came back."""

    __slots__ = ("com_uuid", "name", "time", "last_sent", "sends", "answers", "values", "signal",
                 "target", "digest", "excerpt", "life", "judged", "tree", "topic")

    def __init__(self, com_uuid: str, name: str, t: float, m: dict[str, Any], digest: bytes,
                 excerpt: bytes, life: str | None, topic: str) -> None:
        self.com_uuid = com_uuid
        self.name = name
        self.time = self.last_sent = t
        self.sends = 1
        self.answers = 0
        self.values: list[tuple[str | None, str | None]] = []
        """(response, root-uuid) of each answer, at most 4."""
        self.signal = _str(m, "signal")
        self.target = _str(m, "unit" if name == "signal-unit" else "node-uuid")
        self.digest = digest
        self.excerpt = excerpt
        self.life = life
        self.judged = False
        self.tree: TstTree | None = None
        self.topic = topic

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


class TstConversations:
    """What one unit was told on tst/command and how it answered (bounded)."""

    def __init__(self) -> None:
        self.commands: BoundedDict = BoundedDict(COMMANDS_KEPT)
        self.pending: OrderedDict[str, TstCommand] = OrderedDict()
        self.unanswered: list[TstCommand] = []
        self.trees: BoundedDict = BoundedDict(TREES_KEPT)
        """com-uuid of its start-tst -> tree."""
        self.nodes: BoundedDict = BoundedDict(NODES_KEPT)
        self.expects: list[Expect] = []
        self.watch: OrderedDict[str, TstNode] = OrderedDict()
        """Nodes that ended, until an info shows whether they are still listed."""
        self.awaiting: dict[str, TstNode] = {}
        """Nodes with a deadline of their own: composites whose children all ended, nodes that
        left nodes-executing, nodes whose parent ended."""
        self.answered_any = False
        self.life: str | None = None
        self.lives: list[str] = []
        self.first_command: float | None = None
        self.dropped = 0
        self.info_nodes: set[str] | None = None
        """node-uuids and root-uuids in the latest nodes-executing (None: none seen)."""
        self.info_roots: set[str] = set()

    def watch_node(self, node: TstNode) -> None:
        self.watch[node.node_uuid] = node
        if len(self.watch) > WATCH_KEPT:
            self.watch.popitem(last=False)


def tst_conversations(unit: UnitState) -> TstConversations:
    return per_unit(unit, "tst_conversations", TstConversations)  # type: ignore[no-any-return]


def open_until(unit: UnitState, ctx: CheckContext) -> float | None:
    """The latest deadline (Unix seconds) of what is still open in the unit's TST conversations:
    answers due, feedback signals imply, final statuses due; None when nothing is open. An
    active scenario waits for one heartbeat after it, so that the verdicts are in."""
    c = unit.private.get("tst_conversations")
    if c is None:
        return None
    due = [cmd.last_sent + _timeout(ctx) for cmd in c.pending.values() if not cmd.judged]
    due += [e.deadline for e in c.expects]
    due += [d for n in c.awaiting.values() if (d := _own_deadline(ctx, n)) is not None]
    return max(due) if due else None


def _expects_answers(unit: UnitState, c: TstConversations) -> bool:
    """14: a unit answers TST commands when it declares tst execution or has answered any."""
    return c.answered_any or unit.claims("tst execution")


def _grace(unit: UnitState) -> float:
    """How old a change must be before nodes-executing is judged on it: one declared period
    of tst_execution_info (an info composed just before the change may arrive after it), at
    least a second."""
    period = unit.period(TopicKind.TST_EXECUTION_INFO)
    return max(1.0, period or 1.0)


def _status(m: Any) -> str | None:
    status = _str(m, "status")
    return READ_AS.get(status, status) if status is not None else None


# --- commands -----------------------------------------------------------------------------------

@check("EXEC-008", on=(TopicKind.TST_COMMAND,))
def tst_command_opens_conversation(ctx: CheckContext, unit: UnitState, msg: Message,
                                   v: Validation) -> Iterator[Violation]:
    """A TST command with a com-uuid opens (or, resent, continues) a conversation; a start-tst
    opens its tree. The same com-uuid with other content is EXEC-008's (the commander's):
    2 'Use UUID to identify a communication message'."""
    m = v.message
    com_uuid, name = _str(m, "com-uuid"), _str(m, "command")
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
        before.sends += 1
        before.last_sent = t
        c.commands[com_uuid] = before
        _await(c, before)
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
    cmd = TstCommand(com_uuid, name, t, m, digest, bytes(memoryview(content)[:160]), c.life,
                     msg.topic)
    c.commands[com_uuid] = cmd
    _await(c, cmd)
    if name == "start-tst":
        root, problems = read_tree(m.get("tst"))
        if root is not None and not problems:  # a malformed tree is TST-014's and TST-005's
            cmd.tree = _open_tree(c, cmd, root)


def _await(c: TstConversations, cmd: TstCommand) -> None:
    c.pending.pop(cmd.com_uuid, None)
    c.pending[cmd.com_uuid] = cmd
    if len(c.pending) > PENDING_KEPT:
        c.pending.popitem(last=False)
        c.dropped += 1


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


# --- responses ----------------------------------------------------------------------------------

@check("TST-004", "TST-006", "TST-007", "TST-011", on=(TopicKind.TST_RESPONSE,))
def tst_response_answers_command(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> Iterator[Violation]:
    """14.4: a response answers a TST command (response-to = its com-uuid), with a value that
    fits the command; a resend is answered again, the same way."""
    m = v.message
    response_to = _str(m, "response-to")
    if response_to is None:
        return
    c = tst_conversations(unit)
    cmd = c.commands.get(response_to)
    if cmd is None or cmd.judged:
        return  # a command before the observation, or another unit's on a shared topic
    c.answered_any = True
    cmd.answers += 1
    value, root_uuid = _str(m, "response"), _str(m, "root-uuid")
    if len(cmd.values) < 4:
        cmd.values.append((value, root_uuid))
    if cmd.answers >= cmd.sends:
        c.pending.pop(cmd.com_uuid, None)
    if cmd in c.unanswered:
        c.unanswered.remove(cmd)
    if cmd.answers > 1:
        unit.examine("TST-007")
        if cmd.tree is not None and value in STARTED and cmd.values[0][0] in STARTED:
            unit.examine("TST-006")
            first = cmd.values[0][1]
            if root_uuid != first:
                yield _violation("TST-006", msg, expected=f"the resent {cmd.describe()} "
                                 f"answered as before (root-uuid {first})", observed=f"started "
                                 f"again as root-uuid {root_uuid}", path="$.root-uuid",
                                 detail="12.1: remember com-uuids; answer a resend from memory")
        return
    yield from _judge_unanswered(ctx, unit, c, before=cmd.last_sent)
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
        yield _violation("TST-004", msg, expected=f"'started' (or 'failed' with a reason) "
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
        yield _violation("TST-004", msg, expected=f"root-uuid {given or '(a generated one)'}: "
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
    reason = _str(m, "fail-reason")
    if value not in ("ok", "failed"):
        yield _violation("TST-011", msg, expected=f"'ok' or 'failed' answering "
                         f"{cmd.describe()}", observed=f"response {value!r}", path="$.response",
                         detail="14.4.1-14.4.3: a signal is answered 'ok'")
        return
    # 'failed' without a fail-reason is the response schema's (TST-002), not judged again.
    targets, known = _targets(unit, c, cmd)
    if value == "ok":
        wrong = _why_not_ok(unit, c, cmd, known)
        if wrong:
            yield _violation("TST-011", msg, expected=f"'failed' with a reason answering "
                             f"{cmd.describe()}: {wrong}", observed="'ok'", path="$.response",
                             detail="14.3: refuse a signal for a node the unit does not run")
            return
        wanted = SIGNAL_FEEDBACK.get(cmd.signal or "")
        if wanted is None:
            return
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
        # 'failed' for a node that runs, in a tree that runs: it should have been done.
        node = targets[0]
        yield _violation("TST-011", msg, expected=f"'ok' answering {cmd.describe()}: node "
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
        return [r for r in roots if _runs(r)], None
    node = c.nodes.get(cmd.target) if cmd.target else None
    if node is None:
        return [], None
    tree = node.tree
    if tree.state != "started" or tree.life != c.life or tree.ambiguous \
            or tree.ended_at is not None or not _runs(node) or not _runs(tree.roots[0]):
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


def _judge_unanswered(ctx: CheckContext, unit: UnitState, c: TstConversations, *,
                      before: float) -> Iterator[Violation]:
    """Commands left unanswered that were sent before an answered one: each fails its rule."""
    keep = []
    for cmd in c.unanswered:
        if cmd.last_sent <= before:
            yield from _unanswered(ctx, unit, c, cmd)
        else:
            keep.append(cmd)
    c.unanswered = keep


def _unanswered(ctx: CheckContext, unit: UnitState, c: TstConversations, cmd: TstCommand
                ) -> Iterator[Violation]:
    rule = ANSWER_RULE[cmd.name]
    if not _expects_answers(unit, c):
        unit.note(rule, "TST commands seen, but the unit declares no 'tst execution' and "
                        "answered none")
        return
    unit.examine(rule)
    yield _late(rule, cmd, f"an answer to {cmd.describe()} within {_timeout(ctx):.1f} s",
                "no answer", cmd.last_sent, "14.4: answer every TST command, 'failed' with a "
                "reason when it cannot be done")


# --- feedback -----------------------------------------------------------------------------------

@check("TST-006", "TST-008", "TST-009", "TST-010", "TST-012", "TST-013",
       on=(TopicKind.TST_FEEDBACK,))
def tst_feedback_follows_tree(ctx: CheckContext, unit: UnitState, msg: Message,
                              v: Validation) -> Iterator[Violation]:
    """14.5: feedback follows every node of a started tree to one final status, root-flag on
    the root alone; composites end as their children say."""
    m = v.message
    node_uuid, status = _str(m, "node-uuid"), _status(m)
    if node_uuid is None or status is None:
        return
    c = tst_conversations(unit)
    node = c.nodes.get(node_uuid)
    if node is None or node.tree.state == "refused" or node.tree.life != c.life:
        return  # not a tree the traffic started (or one refused: TST-005's)
    tree = node.tree
    t = msg.time
    flag = m.get("root-flag") if isinstance(m, dict) else None
    if isinstance(flag, bool):
        unit.examine("TST-008")
        if flag is not node.root:
            yield _violation("TST-008", msg, expected=f"root-flag {str(node.root).lower()} for "
                             f"{'the root' if node.root else 'a node below the root'} "
                             f"{node_uuid} ('{node.name}')", observed=f"root-flag "
                             f"{str(flag).lower()}", path="$.root-flag",
                             detail="14.5: root-flag marks the feedback of the tree's top node")
    if node.final is not None:
        end_status, end_com, end_time = node.final
        if _str(m, "com-uuid") == end_com:
            return  # the final message delivered again
        again = tree.resent is not None and tree.resent > end_time
        rule = "TST-006" if again else "TST-009"
        unit.examine(rule)
        if rule not in node.judged:
            node.judged.add(rule)
            yield _violation(rule, msg, expected=f"nothing for node {node_uuid} after its "
                             f"final status '{end_status}'", observed=f"status '{status}' "
                             f"{t - end_time:.2f} s later" + (" (after its start-tst was "
                                                              "resent: started again)"
                                                              if again else ""),
                             path="$.status", detail="14.5: a node's final status is its last")
        return
    if status == "active":
        node.actives += 1
        if node.actives > 1 and tree.resent is not None and "TST-006" not in node.judged:
            node.judged.add("TST-006")
            unit.examine("TST-006")
            yield _violation("TST-006", msg, expected=f"node {node_uuid} ('{node.name}') "
                             f"started once", observed="'active' again after its start-tst "
                             "was resent", path="$.status", detail="12.1: a resent start-tst "
                             "is answered from memory, not started again")
    if node.unlisted_at is not None and t - node.unlisted_at >= _grace(unit) \
            and "TST-013" not in node.judged:
        node.judged.add("TST-013")
        unit.examine("TST-013")
        yield _violation("TST-013", msg, expected=f"node {node_uuid} ('{node.name}') in "
                         f"nodes-executing while it runs", observed=f"left out at "
                         f"{node.unlisted_at:.3f}, and it still ran ('{status}' "
                         f"{t - node.unlisted_at:.2f} s later)", path="$.status",
                         detail="list every node that is not yet in a final status")
    node.unlisted_at = node.left_at = None
    if node.status is None and status != "revoked":
        yield from _judge_order(unit, node, msg, status)
    node.status, node.status_time = status, t
    for e in [e for e in c.expects if e.node is node]:
        if status == e.wanted:
            unit.examine("TST-012")
            c.expects.remove(e)
        elif status in FINAL:
            c.expects.remove(e)
            unit.examine("TST-012")
            yield _violation("TST-012", msg, expected=f"'{e.wanted}' after "
                             f"{e.command.describe()} was answered 'ok'",
                             observed=f"status '{status}'", path="$.status",
                             detail="14.3: do what the signal says, and say so in feedback")
    if status in FINAL:
        yield from _ended(ctx, unit, c, node, (status, _str(m, "com-uuid"), t), msg)


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
        said = "still runs" if running else f"ended '{s.final[0]}'"  # type: ignore[index]
        yield _violation("TST-010", msg, expected=f"seq {parent.node_uuid} starts child "
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

@check("TST-013", "TST-009", on=(TopicKind.TST_EXECUTION_INFO,))
def nodes_executing_follow_trees(ctx: CheckContext, unit: UnitState, msg: Message,
                                 v: Validation) -> list[Violation] | None:
    """TST-013 (modelled on 5.3's tasks-executing): nodes-executing lists exactly the nodes not
    yet in a final status; a node that leaves it without one has ended silently (TST-009).
    (Runs on every tst_execution_info: cheap when no tree is open.)"""
    m = v.message
    listed_raw = m.get("nodes-executing") if type(m) is dict else None
    c = unit.private.get("tst_conversations")
    if type(listed_raw) is not list:
        if c is not None and c.trees:
            unit.note("TST-013", "tst_execution_info has no nodes-executing: not judged")
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
            found.append(_violation("TST-013", msg, expected=f"node {node.node_uuid} "
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
            if not node.live or node.status_time is None:
                continue
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


# --- deadlines: judged on the unit's heartbeats and at the end ----------------------------------

def _own_deadline(ctx: CheckContext, node: TstNode) -> float | None:
    """When a node waiting for its final status has waited too long."""
    if node.final is not None:
        return None
    if node.left_at is not None:
        return node.left_at + _timeout(ctx)
    if node.ended_children_at is not None:
        return node.ended_children_at + ctx.profile.feedback_timeout
    parent = node.parent
    if parent is not None and parent.final is not None:
        return parent.final[2] + ctx.profile.feedback_timeout
    return None


@check("TST-004", "TST-007", "TST-009", "TST-011", "TST-012", on=(TopicKind.HEARTBEAT,))
def tst_deadlines_pass(ctx: CheckContext, unit: UnitState, msg: Message,
                       v: Validation) -> list[Violation] | None:
    """Deadlines are checked on each heartbeat of the unit (and at the end). A new agent-uuid
    is a new life: its trees are forgotten (TST-011's decision), and what the old one left open
    is not judged. (Runs on every heartbeat: cheap when nothing is open.)"""
    c = unit.private.get("tst_conversations")
    if c is None:
        return None
    m = v.message
    agent = m.get("agent-uuid") if type(m) is dict else None
    if type(agent) is str and agent != c.life and not msg.retain:
        found = _new_life(ctx, unit, c, msg.time) if c.life is not None \
            and agent not in c.lives else None
        c.life = agent
        if agent not in c.lives:
            c.lives.append(agent)
            del c.lives[:-8]
        return found
    if not (c.pending or c.expects or c.awaiting):
        return None
    return _expire(ctx, unit, c, msg.time) or None


def _new_life(ctx: CheckContext, unit: UnitState, c: TstConversations, t: float
              ) -> list[Violation] | None:
    from conformance.checks.identity import SILENCE_PERIODS, heartbeat_period

    last, period = unit.last_heartbeat, heartbeat_period(unit)
    dead_since = (last - period if last is not None and period
                  and t - last > SILENCE_PERIODS * period else None)
    found = _expire(ctx, unit, c, t, reboot=True)
    streak, c.unanswered = c.unanswered, []
    for cmd in streak:
        if dead_since is not None and cmd.last_sent >= dead_since:
            unit.note(ANSWER_RULE[cmd.name], "TST commands sent while the unit was dying or "
                                             "dead (HB-012)")
            continue
        found.extend(_unanswered(ctx, unit, c, cmd))
    c.expects.clear()
    c.awaiting.clear()
    c.watch.clear()
    c.info_nodes = None
    return found or None


def _expire(ctx: CheckContext, unit: UnitState, c: TstConversations, now: float,
            reboot: bool = False) -> list[Violation]:
    found: list[Violation] = []
    timeout = _timeout(ctx)
    for cmd in overdue(c, now, timeout, reboot):
        unit.examine("TST-007")
        found.append(_late("TST-007", cmd, f"a second answer to the resent "
                           f"{cmd.describe()} within {timeout:.1f} s", "none",
                           cmd.last_sent, "12.1: answer a resend again, as the first time"))
    if reboot:
        return found
    for e in list(c.expects):
        if e.deadline >= now:
            continue
        c.expects.remove(e)
        if e.node.final is None and not _runs(e.node):
            continue  # its children did as signalled; its own silence is TST-009's
        unit.examine("TST-012")
        found.append(_late("TST-012", e.command, f"'{e.wanted}' for node {e.node.node_uuid} "
                           f"('{e.node.name}') within {ctx.profile.feedback_timeout:.1f} s of "
                           f"the 'ok' to {e.command.describe()}",
                           f"latest status {e.node.status!r}", e.command.last_sent,
                           "14.3: do what the signal says, and say so in feedback"))
    for node in list(c.awaiting.values()):
        due = _own_deadline(ctx, node)
        if due is None:
            c.awaiting.pop(node.node_uuid, None)
            continue
        if due >= now:
            continue
        c.awaiting.pop(node.node_uuid, None)
        unit.examine("TST-009")
        if "TST-009" in node.judged:
            continue
        node.judged.add("TST-009")
        why = ("it left nodes-executing" if node.left_at is not None else
               "its children all ended" if node.ended_children_at is not None else
               "its parent ended")
        found.append(_late("TST-009", node.tree.command, f"a final status for node "
                           f"{node.node_uuid} ('{node.name}')", f"{why}, and it said none "
                           f"(latest status {node.status!r})", due,
                           "14.5: every node reports its end (succeeded, failed, aborted or "
                           "revoked)"))
    return found


def _runs(node: TstNode) -> bool:
    """Whether the traffic shows the node still running: a live leaf, or a live composite
    with a child that runs or is still to run. A composite whose children all ended, but
    which said no end of its own, has ended silently (TST-009's finding)."""
    if node.final is not None or node.status is None:
        return False
    return not node.children or any(ch.status is None or _runs(ch) for ch in node.children)


@check("TST-004", "TST-009", "TST-011", finish=True)
def tst_conversations_at_end(ctx: CheckContext, unit: UnitState, now: float,
                             findings: Any) -> Iterator[Violation]:
    """At the end: answers still due are judged (a unit that died is HB-012's finding); trees
    still running are not judged; what the bounds dropped is said. (Pure: works on a copy.)"""
    from copy import deepcopy

    from conformance.checks.identity import death

    original = unit.private.get("tst_conversations")
    if original is None:
        return
    c = deepcopy(original)
    scratch = dataclasses.replace(unit, examined={}, notes={},
                                  private={**unit.private, "tst_conversations": c})
    found = _expire(ctx, scratch, c, now)
    dead = death(ctx, unit, now)
    for cmd in c.unanswered:
        if dead is not None and cmd.last_sent >= dead[0]:
            scratch.note(ANSWER_RULE[cmd.name], "TST commands sent while the unit was dying "
                                                "or dead (HB-012)")
            continue
        found.extend(_unanswered(ctx, scratch, c, cmd))
    running = sum(1 for t in c.trees.values() if t.state == "started" and t.life == c.life
                  and t.ended_at is None)
    if running:
        scratch.note("TST-009", f"{running} tree(s) still running when the observation "
                                f"ended: not judged")
    if c.dropped:
        scratch.note("TST-012", f"{c.dropped} open TST expectations dropped (bounded "
                                f"memory): not judged")
    for rule, n in scratch.examined.items():
        findings.examine(rule, n)
    for rule, why in scratch.notes.items():
        findings.note(rule, why)
    yield from found


def _late(rule: str, cmd: TstCommand | None, expected: str, observed: str, t: float,
          detail: str) -> Violation:
    """A violation found when a deadline passed: its evidence is the command."""
    return Violation.of(rule, expected=expected, observed=observed,
                        topic=cmd.topic if cmd is not None else "", path="$", time=t,
                        payload=cmd.excerpt if cmd is not None else None, detail=detail)

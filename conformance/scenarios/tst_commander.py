"""The commander side of spec 14: send TST commands for the unit under test and wait for answers.

Commands go to ONE topic, the one the run was told (14.1): the unit's own ``tst/command`` by
default, or an operator's such as ``op0/tst/command``, where they name the unit (execunit,
signal-unit's ``unit``); the MQTT client's publish policy allows exactly that topic
(docs/ARCHITECTURE.md 'Safety'). Answers are read on the matching ``tst/response`` and
``tst/feedback`` (``Traffic`` files an operator's under the same subtopics). Every tree it starts is
remembered until its root reports a final status, so ``abort_all`` can end it with ``signal-tst-tree
$abort`` at teardown, on failure and on Ctrl-C. Under ``--dry-run`` nothing is published: ``send``
prints what it would publish and raises ``DryRun``.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import Any

from conformance.scenarios.deviation import Deviations, Kind
from conformance.scenarios.sender import Sender, Sent
from conformance.scenarios.traffic import Entry, Traffic
from conformance.topics import UnitAddress
from conformance.tst import COMPOSITES, FINAL

READ_AS = {"finished": "succeeded"}
"""A near miss of 14.5's vocabulary (TST-003's to judge) is waited on as what it means."""


def node(name: str, params: dict[str, Any], node_uuid: str, children: Iterable[dict] = (),
         *, execunit: str) -> dict[str, Any]:
    """A TST node as every example of 11 writes it: name, params, children and common_params
    (ERR-009's canonical spelling) with both execunit and node-uuid, on every node, the root's
    children too: a strict unit may refuse a node without them (docs/FIELD-NOTES.md 'Precision':
    strict
    readers'), and 14.3.4 says node-uuids are best set on every node."""
    return {"name": name, "params": params, "children": list(children),
            "common_params": {"execunit": execunit, "node-uuid": node_uuid}}


@dataclass
class OpenTree:
    """A tree this commander started: the root node-uuids it may go by (the one sent, the
    response's root-uuid) and the traffic mark from before it was sent."""

    roots: set[str]
    mark: int
    name: str
    com_uuids: list[str] = field(default_factory=list)
    stuck: bool = False
    """Its $abort went unanswered, or was refused while it ran: teardown between scenarios
    does not abort it again (i20 6); the run's last teardown does."""


class TstCommander(Sender):
    """Sends spec-14 commands for one unit to ``topic`` and waits, with deadlines, for its
    responses and node feedback. ``publish(topic, payload)`` does the MQTT publish."""

    responses = "tst/response"

    def __init__(self, unit: UnitAddress, topic: str, traffic: Traffic,
                 publish: Callable[[str, bytes], None], *, dry_run: bool = False,
                 say: Callable[[str], None] = print,
                 wait_connected: Callable[[float], bool] = lambda timeout: True,
                 deviations: Deviations | None = None, gaps: Callable[[], int] = lambda: 0,
                 away: Callable[[], object] = lambda: None) -> None:
        super().__init__(unit, topic, traffic, publish, dry_run=dry_run, say=say,
                         wait_connected=wait_connected, gaps=gaps, away=away)
        self.open_trees: dict[str, OpenTree] = {}
        """com-uuid of the start-tst -> the tree, until it ended or its $abort was answered."""
        self.deviations = deviations if deviations is not None else Deviations()
        self._tree_of: dict[str, str] = {}
        """node-uuid -> the node-uuid of its tree's root, for every node of the trees sent."""
        self._tasks: dict[str, list[str]] = {}
        """root node-uuid -> the node-uuids of its task (non-composite) nodes."""
        self._composites: dict[str, str] = {}
        """node-uuid -> 'seq' or 'conc', for the composite nodes of the trees sent."""
        self._alias: dict[str, str] = {}
        """A root-uuid the unit answered with -> the root node-uuid sent (TST-004's)."""
        self._ignored: set[str] = set()
        """Signals the unit answered 'ok' and did not do (TST-012, noted once)."""

    @property
    def shared(self) -> bool:
        """Whether commands go to an operator's topic (14.1), not the unit's own."""
        return self.topic != self.unit.topic("tst/command")

    @property
    def receiver(self) -> str:
        """The name the command topic belongs to, as 11's start-tst examples name it in
        ``receiver`` (``op0`` for ``op0/tst/command``; the unit's own name on its own)."""
        return self.topic.removesuffix("/tst/command").rsplit("/", 1)[-1]

    @property
    def me(self) -> str:
        """The unit as TST commands name it: '/NAME' (14.3.3, 11; ERR-017)."""
        return f"/{self.unit.name}"

    # --- publishing ---------------------------------------------------------------------
    def send(self, body: dict[str, Any], *, com_uuid: str | None = None) -> Sent:
        """Publish a command; ``com-uuid`` and ``sender`` are filled in when missing."""
        return self.publish_command(*self.compose(body, com_uuid))

    def resend(self, sent: Sent) -> Sent:
        """The very same command again (12.1's resend, which holds for TST commands too)."""
        return self.publish_command(sent.payload, sent.body)

    def _remember(self, sent: Sent) -> None:
        """A start-tst: the tree it may start, to abort it at the end."""
        if sent.body.get("command") != "start-tst":
            return
        tst = sent.body.get("tst")
        common = tst.get("common_params", {}) if isinstance(tst, dict) else {}
        root = common.get("node-uuid") if isinstance(common, dict) else None
        with self._lock:
            known = self.open_trees.setdefault(sent.com_uuid, OpenTree(
                {root} if isinstance(root, str) else set(), sent.mark,
                str(tst.get("name", "")) if isinstance(tst, dict) else ""))
            known.com_uuids.append(sent.com_uuid)

    def _forget(self, sent: Sent) -> None:
        with self._lock:
            self.open_trees.pop(sent.com_uuid, None)

    # --- waiting ------------------------------------------------------------------------
    def response(self, sent: Sent, timeout: float, *, after: int | None = None
                 ) -> Entry | None:
        """The response whose response-to is the command's com-uuid (14.4)."""
        answer = self.await_response(sent, timeout, after=after)
        if answer is not None and sent.body.get("command") == "start-tst":
            self._track(sent.com_uuid, answer)
        return answer

    def request(self, body: dict[str, Any], timeout: float) -> tuple[Sent, Entry | None]:
        sent = self.send(body)
        return sent, self.response(sent, timeout)

    def _track(self, com: str, answer: Entry) -> None:
        with self._lock:
            tree = self.open_trees.get(com)
            if tree is None:
                return
            if answer.get("response") == "failed":
                del self.open_trees[com]  # never started: nothing to abort
            elif isinstance(answer.get("root-uuid"), str):
                tree.roots.add(answer.get("root-uuid"))

    def start(self, tree: dict[str, Any], timeout: float) -> tuple[Sent, Entry | None, str]:
        """start-tst (14.3.4); the root node-uuid to address the tree by: the response's
        root-uuid when it gives one, else the one sent."""
        self._learn(tree)
        sent, answer = self.request({"command": "start-tst", "receiver": self.receiver,
                                     "tst": tree}, timeout)
        root = answer.get("root-uuid") if answer is not None else None
        sent_root = str(tree.get("common_params", {}).get("node-uuid"))
        if isinstance(root, str) and root and root != sent_root:
            with self._lock:  # the unit's own name for the root (TST-004's finding)
                self._alias[root] = sent_root
        return sent, answer, root if isinstance(root, str) and root else sent_root

    def _learn(self, tree: dict[str, Any]) -> None:
        """Remember which nodes a tree sent has: its task nodes and its composites."""
        root = str(tree.get("common_params", {}).get("node-uuid"))
        stack, tasks = [tree], []
        with self._lock:
            while stack:
                n = stack.pop()
                uuid_ = str(n.get("common_params", {}).get("node-uuid"))
                self._tree_of[uuid_] = root
                if n.get("name") in COMPOSITES:
                    self._composites[uuid_] = str(n.get("name"))
                else:
                    tasks.append(uuid_)
                stack.extend(n.get("children") or [])
            self._tasks[root] = tasks

    def signal(self, command: str, target: str, signal: str, timeout: float
               ) -> tuple[Sent, Entry | None]:
        """signal-tst-node / signal-tst-tree (``target`` a node-uuid) or signal-unit
        (``target`` the unit, '/NAME') (14.3.1-14.3.3)."""
        key = "unit" if command == "signal-unit" else "node-uuid"
        return self.request({"command": command, key: target, "signal": signal}, timeout)

    def statuses(self, node_uuid: str, after: int) -> list[str]:
        """Every status reported for ``node_uuid`` after ``after``, in order (14.5)."""
        return [self._read(s) for e in self.traffic.since(after, "tst/feedback")
                if e.get("node-uuid") == node_uuid and isinstance(s := e.get("status"), str)]

    def _read(self, status: Any) -> Any:
        """A status as what it means; a near miss of 14.5's words is noted once (TST-003)."""
        means = READ_AS.get(status, status) if isinstance(status, str) else status
        if means != status:
            self.deviations.note(
                Kind.TST_STATUS_VOCABULARY, f"the unit reports node status {status!r} (not in "
                f"14.5's list) for {means!r}", f"the suite takes {status!r} as {means!r}")
        return means

    def feedback(self, node_uuid: str, statuses: Collection[str] | None, timeout: float, *,
                 after: int) -> Entry | None:
        """The first feedback for ``node_uuid`` after ``after`` with one of ``statuses`` (any
        when None)."""
        def match(e: Entry) -> bool:
            return e.get("node-uuid") == node_uuid and (
                statuses is None or self._read(e.get("status")) in statuses)
        return self.traffic.wait_for(match, timeout, after=after, subtopic="tst/feedback",
                                     what=f"TST node {node_uuid[:8]}: "
                                     + ("any status" if statuses is None else
                                        " or ".join(sorted(statuses))))

    def follow(self, given: str, root: str, statuses: Collection[str] | None, timeout: float,
               *, after: int) -> tuple[str, Entry | None]:
        """The first feedback of a tree just started (one of ``statuses``; any when None), and
        the node-uuid to address the tree by. 14.4.4: the root-uuid answered is the root's
        node-uuid sent; a unit that answers another one (TST-004's finding) but reports the
        tree under the node-uuid sent is followed under that one (noted once), so that its
        signals reach the tree and no wait runs out for feedback that comes under a name
        the suite is not watching."""
        ids = {given, root}

        def match(e: Entry) -> bool:
            return e.get("node-uuid") in ids and (
                statuses is None or self._read(e.get("status")) in statuses)
        found = self.traffic.wait_for(match, timeout, after=after, subtopic="tst/feedback",
                                      what=f"the first feedback of tree {given[:8]}")
        if found is not None and found.get("node-uuid") == given != root:
            self.deviations.note(
                Kind.TST_ROOT_UUID, f"start-tst with root node-uuid {given} was answered "
                f"root-uuid {root}, and the tree's feedback names {given}",
                "the suite addresses each tree by the node-uuid it sent")
            return given, found
        return root, found

    def effect(self, signal: str, watch: str, wanted: Collection[str], *, after: int,
               timeout: float, short: float, target: str | None = None) -> Entry | None:
        """The feedback a signal answered 'ok' implies: ``watch`` reporting one of ``wanted``
        after ``after``, within ``timeout`` seconds; ``short`` once the unit has answered this
        signal 'ok' and not done it (TST-012, noted once: deviation.py).

        The end of a seq or conc is awaited until its task nodes have all ended, then
        ``short`` more for its own final status: nothing of the tree runs any more, and
        whether that status comes is the Monitor's to judge (TST-009), by its own deadline,
        which then runs out while the scenario goes on."""
        known = signal in self._ignored
        gaps = self.gaps()
        if self.is_composite(watch) and set(wanted) <= set(FINAL):
            found = self._composite_end(watch, wanted, short if known else timeout,
                                        after=after, short=short)
        else:
            found = self.feedback(watch, wanted, short if known else timeout, after=after)
        if found is not None or known or self.over(watch):
            return found
        # The signalled node did what it was told, but ``watch`` (its tree) went on: that is
        # the tree's finding (TST-010), not a signal ignored.
        node = target if target is not None and not target.startswith("/") else watch
        if node != watch and any(s in wanted for s in self.statuses(node, after)):
            return None
        if self.broken_since(gaps):
            return None  # the broker lost or held it meanwhile: no habit of the unit
        with self._lock:
            self._ignored.add(signal)
        self.deviations.note(
            Kind.TST_SIGNAL_IGNORED, f"{signal} was answered 'ok', and node {watch} reported "
            f"no {' or '.join(sorted(wanted))} within {timeout:.1f} s",
            f"later waits for what {signal} implies last {short:.1f} s")
        return None

    def _composite_end(self, watch: str, wanted: Collection[str], timeout: float, *,
                       after: int, short: float) -> Entry | None:
        tasks = set(self.task_nodes(watch))
        ended = {n for n in tasks if self.final(n, 0)}

        def match(e: Entry) -> bool:
            node, status = e.get("node-uuid"), self._read(e.get("status"))
            if node == watch:
                return status in wanted
            if node in tasks and status in FINAL:
                ended.add(node)
            return bool(tasks) and ended >= tasks
        found = self.traffic.wait_for(match, timeout, after=after, subtopic="tst/feedback",
                                      what=f"the end of {self._name(watch)} {watch[:8]}")
        if found is None or found.get("node-uuid") == watch:
            return found
        return self.feedback(watch, wanted, short, after=after)

    def is_composite(self, node_uuid: str) -> bool:
        """Whether a node sent (or a root-uuid the unit gave one) is a seq or conc."""
        return bool(self._name(node_uuid))

    def _name(self, node_uuid: str) -> str:
        with self._lock:
            return self._composites.get(self._alias.get(node_uuid, node_uuid), "")

    def task_nodes(self, node_uuid: str) -> list[str]:
        """The task nodes of the tree ``node_uuid`` belongs to."""
        with self._lock:
            sent = self._alias.get(node_uuid, node_uuid)
            return list(self._tasks.get(self._tree_of.get(sent, sent), ()))

    def final(self, node_uuid: str, after: int) -> str | None:
        return next((s for s in self.statuses(node_uuid, after) if s in FINAL), None)

    def over(self, node_uuid: str, after: int = 0) -> bool:
        """Whether ``node_uuid`` has ended: it reported a final status, or it is a tree's root
        and every task node of the tree has (nothing of it runs; whether the seq or conc says
        so is TST-009's)."""
        if self.final(node_uuid, after):
            return True
        if not self.is_composite(node_uuid):
            return False
        tasks = self.task_nodes(node_uuid)
        return bool(tasks) and all(self.final(n, after) for n in tasks)

    def ended(self, tree: OpenTree) -> bool:
        return any(self.over(root, tree.mark) for root in tree.roots)

    # --- safety -------------------------------------------------------------------------
    def abort_all(self, timeout: float, *, stuck: bool = True) -> list[str]:
        """``signal-tst-tree $abort`` to every tree this commander started whose root has not
        ended (docs/ARCHITECTURE.md 'Safety'); wait up to ``timeout`` seconds in all for the
        answers. Returns the root node-uuids aborted. ``stuck=False`` (between scenarios) leaves
        out the trees whose $abort went unanswered or was refused while they ran (i20 6); the
        run's last teardown tries them once more."""
        if self.dry_run:
            return []
        for e in self.traffic.since(0, "tst/response"):  # answers that came after a Ctrl-C
            com = e.get("response-to")
            if isinstance(com, str) and com in self.open_trees:
                self._track(com, e)
        with self._lock:
            trees = list(self.open_trees.items())
        sent: list[tuple[str, str, Sent]] = []
        for com, tree in trees:
            if self.ended(tree):
                with self._lock:
                    self.open_trees.pop(com, None)
                continue
            if tree.stuck and not stuck:
                continue
            for root in sorted(tree.roots):
                try:
                    sent.append((com, root, self.send({"command": "signal-tst-tree",
                                                       "node-uuid": root, "signal": "$abort"})))
                except Exception as e:  # keep aborting the others; say which one failed
                    self._say(f"could not abort TST tree {root}: {e}")
        aborted = []
        for com, root, s in sent:
            answer = self.response(s, timeout / max(1, len(sent)))
            if answer is not None and answer.get("response") == "ok":
                aborted.append(root)
                with self._lock:
                    self.open_trees.pop(com, None)
            else:  # refused (ended meanwhile, or not this name of it), or unanswered
                with self._lock:
                    still = self.open_trees.get(com)
                if still is not None and answer is not None and self.ended(still):
                    with self._lock:
                        self.open_trees.pop(com, None)
                elif still is not None:
                    still.stuck = True
        return aborted

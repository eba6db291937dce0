"""The commander side of spec 14: send TST commands for the unit under test and wait for answers.

Commands go to ONE topic, the one the run was told (14.1): the unit's own ``tst/command`` by
default, or an operator's such as ``op0/tst/command``, where they name the unit (execunit,
signal-unit's ``unit``); the MQTT client's publish policy allows exactly that topic (DESIGN
'Safety'). Answers are read on the matching ``tst/response`` and ``tst/feedback`` (``Traffic``
files an operator's under the same subtopics). Every tree it starts is remembered until its
root reports a final status, so ``abort_all`` can end it with ``signal-tst-tree $abort`` at
teardown, on failure and on Ctrl-C. Under ``--dry-run`` nothing is published: ``send`` prints
what it would publish and raises ``DryRun``.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import Any

from conformance.scenarios.sender import Sender, Sent
from conformance.scenarios.traffic import Entry, Traffic
from conformance.topics import UnitAddress
from conformance.tst import FINAL

READ_AS = {"finished": "succeeded"}
"""A near miss of 14.5's vocabulary (TST-003's to judge) is waited on as what it means."""


def node(name: str, params: dict[str, Any], node_uuid: str, children: Iterable[dict] = (),
         execunit: str | None = None) -> dict[str, Any]:
    """A TST node as 11's examples write it (common_params: ERR-009's canonical spelling)."""
    common: dict[str, Any] = {"node-uuid": node_uuid}
    if execunit is not None:
        common["execunit"] = execunit
    return {"name": name, "params": params, "children": list(children), "common_params": common}


@dataclass
class OpenTree:
    """A tree this commander started: the root node-uuids it may go by (the one sent, the
    response's root-uuid) and the traffic mark from before it was sent."""

    roots: set[str]
    mark: int
    name: str
    com_uuids: list[str] = field(default_factory=list)


class TstCommander(Sender):
    """Sends spec-14 commands for one unit to ``topic`` and waits, with deadlines, for its
    responses and node feedback. ``publish(topic, payload)`` does the MQTT publish."""

    responses = "tst/response"

    def __init__(self, unit: UnitAddress, topic: str, traffic: Traffic,
                 publish: Callable[[str, bytes], None], *, dry_run: bool = False,
                 say: Callable[[str], None] = print,
                 wait_connected: Callable[[float], bool] = lambda timeout: True) -> None:
        super().__init__(unit, topic, traffic, publish, dry_run=dry_run, say=say,
                         wait_connected=wait_connected)
        self.open_trees: dict[str, OpenTree] = {}
        """com-uuid of the start-tst -> the tree, until it ended or its $abort was answered."""

    @property
    def shared(self) -> bool:
        """Whether commands go to an operator's topic (14.1), not the unit's own."""
        return self.topic != self.unit.topic("tst/command")

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
        sent, answer = self.request({"command": "start-tst", "tst": tree}, timeout)
        root = answer.get("root-uuid") if answer is not None else None
        sent_root = tree.get("common_params", {}).get("node-uuid")
        return sent, answer, root if isinstance(root, str) and root else str(sent_root)

    def signal(self, command: str, target: str, signal: str, timeout: float
               ) -> tuple[Sent, Entry | None]:
        """signal-tst-node / signal-tst-tree (``target`` a node-uuid) or signal-unit
        (``target`` the unit, '/NAME') (14.3.1-14.3.3)."""
        key = "unit" if command == "signal-unit" else "node-uuid"
        return self.request({"command": command, key: target, "signal": signal}, timeout)

    def statuses(self, node_uuid: str, after: int) -> list[str]:
        """Every status reported for ``node_uuid`` after ``after``, in order (14.5)."""
        return [READ_AS.get(s, s) for e in self.traffic.since(after, "tst/feedback")
                if e.get("node-uuid") == node_uuid and isinstance(s := e.get("status"), str)]

    def feedback(self, node_uuid: str, statuses: Collection[str] | None, timeout: float, *,
                 after: int) -> Entry | None:
        """The first feedback for ``node_uuid`` after ``after`` with one of ``statuses`` (any
        when None)."""
        def match(e: Entry) -> bool:
            status = e.get("status")
            return e.get("node-uuid") == node_uuid and (
                statuses is None or READ_AS.get(status, status) in statuses)
        return self.traffic.wait_for(match, timeout, after=after, subtopic="tst/feedback")

    def final(self, node_uuid: str, after: int) -> str | None:
        return next((s for s in self.statuses(node_uuid, after) if s in FINAL), None)

    def ended(self, tree: OpenTree) -> bool:
        return any(self.final(root, tree.mark) for root in tree.roots)

    # --- safety -------------------------------------------------------------------------
    def abort_all(self, timeout: float) -> list[str]:
        """``signal-tst-tree $abort`` to every tree this commander started whose root has not
        ended (DESIGN 'Safety'); wait up to ``timeout`` seconds in all for the answers.
        Returns the root node-uuids aborted."""
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
            elif answer is not None:  # refused: ended meanwhile, or not this name of it
                with self._lock:
                    tree = self.open_trees.get(com)
                    if tree is not None and self.ended(tree):
                        self.open_trees.pop(com, None)
        return aborted

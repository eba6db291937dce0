"""A TST workout for one simulated unit (spec 14): trees that succeed, pause, continue, end on
$enough and on $abort, trees the unit must refuse, a resend and every signal command, judged
rule by rule (TST-004..TST-013).

Like ``sim_workout``, a deliberately small judge of the tests' own (the certification suite's
TST scenarios are a colleague's): it shows that each TST fault of the simulator changes exactly
the behaviour it names. Vocabulary is TST-003's business (the validator's): a near miss of a
14.5 status ('finished') is read here as the status it means.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Iterable
from typing import Any

from sim_observer import Observer

WAIT = 2.0  # seconds for an answer on loopback (a deadline, not a duration claim)
FINAL = ("succeeded", "failed", "aborted", "revoked")  # TST-009's decision
READ_AS = {"finished": "succeeded"}


def new_uuid() -> str:
    return str(uuid.uuid4())


class TstView:
    """The TST traffic of one unit (its topic base) inside a shared observer."""

    def __init__(self, obs: Observer, base: str) -> None:
        self.obs, self.base = obs, base
        self.name = base.rsplit("/", 1)[-1]
        self.command_topic = f"{base}/tst/command"

    def json_on(self, sub: str, mark: int = 0) -> list[dict[str, Any]]:
        return [x for x in self.obs.json_on(f"{self.base}/{sub}", mark) if isinstance(x, dict)]

    def send(self, body: dict[str, Any]) -> str:
        return self.obs.send(body, topic=self.command_topic)

    def answer(self, com: str, n: int = 1, timeout: float = WAIT) -> dict[str, Any] | None:
        def found(_: Any) -> Any:
            got = [r for r in self.json_on("tst/response") if r.get("response-to") == com]
            return got[n - 1] if len(got) >= n else None
        return self.obs.wait_for(found, timeout, fail=False)

    def request(self, body: dict[str, Any], timeout: float = WAIT) -> dict[str, Any] | None:
        return self.answer(self.send(body), timeout=timeout)

    def signal(self, command: str, target: str, signal: str) -> dict[str, Any] | None:
        key = "unit" if command == "signal-unit" else "node-uuid"
        return self.request({"command": command, key: target, "signal": signal})

    def feedback(self, node_uuid: str | None = None) -> list[dict[str, Any]]:
        return [f for f in self.json_on("tst/feedback")
                if node_uuid is None or f.get("node-uuid") == node_uuid]

    def statuses(self, node_uuid: str) -> list[str]:
        return [READ_AS.get(str(f.get("status")), str(f.get("status")))
                for f in self.feedback(node_uuid)]

    def final(self, node_uuid: str) -> str | None:
        return next((s for s in self.statuses(node_uuid) if s in FINAL), None)

    def wait(self, condition: Callable[[], Any], timeout: float = WAIT) -> Any:
        return self.obs.wait_for(lambda _: condition(), timeout, fail=False)

    def sync(self) -> bool:
        """Once this answer is here, everything the unit sent for earlier commands is too: it
        handles its commands one after another and publishes on one connection."""
        return self.signal("signal-tst-node", new_uuid(), "$abort") is not None

    def next_info(self, timeout: float = WAIT) -> dict[str, Any] | None:
        mark = self.obs.mark()
        return self.obs.wait_for(lambda _: (got := self.json_on("tst_execution_info", mark))
                                 and got[0], timeout, fail=False)


def node(name: str, params: dict[str, Any], node_uuid: str, children: Iterable[dict] = (),
         execunit: str | None = None, spelling: str = "common-params") -> dict[str, Any]:
    """A TST node; ``spelling`` of its common parameters: practice's or the examples' (ERR-009)."""
    common = {"node-uuid": node_uuid}
    if execunit is not None:
        common["execunit"] = execunit
    return {"name": name, "params": params, "children": list(children), spelling: common}


def start(tree: dict[str, Any]) -> dict[str, Any]:
    return {"command": "start-tst", "tst": tree}


def outcome(statuses: list[str | None]) -> str:
    """TST-010's decision: failed if a child that ran failed, else aborted if one was, else
    succeeded."""
    ran = [s for s in statuses if s != "revoked"]
    return "failed" if "failed" in ran else "aborted" if "aborted" in ran else "succeeded"


def tst_workout(v: TstView, near: dict[str, Any], further: dict[str, Any]) -> dict[str, bool]:
    """Drive one unit through the TST scenarios; the verdict (True: passed) per rule. ``near``
    and ``further`` are waypoints close to the unit (safety: never the spec's coordinates)."""
    ok: dict[str, bool] = {}
    me = f"/{v.name}"

    def judge(rule: str, passed: Any) -> None:
        ok[rule] = ok.get(rule, True) and bool(passed)

    def answered_ok(r: dict[str, Any] | None) -> bool:
        return r is not None and r.get("response") == "ok"

    def refused(r: dict[str, Any] | None) -> bool:
        return r is not None and r.get("response") == "failed" and bool(r.get("fail-reason"))

    def started(r: dict[str, Any] | None, root: str) -> bool:
        # 'running' is ERR-015's reading of 'started' (the validator judges the word)
        return r is not None and r.get("response") in ("started", "running") and \
            r.get("root-uuid") == root

    roots: set[str] = set()
    composites: list[tuple[str, str, list[str]]] = []  # (node-uuid, seq|conc, children)

    # The spec's own spelling, common_params: started, root-uuid is the root's node-uuid.
    solo = new_uuid()
    roots.add(solo)
    r = v.request(start(node("move-to", {"waypoint": near, "speed": "fast"}, solo, execunit=me,
                             spelling="common_params")))
    judge("TST-004", started(r, solo))
    if r is not None and isinstance(r.get("root-uuid"), str):
        roots.add(r["root-uuid"])  # the root's node-uuid as the unit knows it (root-flag)
    v.wait(lambda: v.final(solo), 4 * WAIT)  # it ends on its own

    # seq [move-to, conc [look-at-bearing, image-object-detection]]
    R, M, C, L, D = (new_uuid() for _ in range(5))
    roots.add(R)
    composites += [(R, "seq", [M, C]), (C, "conc", [L, D])]
    r = v.request(start(node("seq", {}, R, [
        node("move-to", {"waypoint": further, "speed": "fast"}, M),
        node("conc", {}, C, [node("look-at-bearing", {"bearing": 30.0}, L),
                             node("image-object-detection", {}, D)])], execunit=me)))
    judge("TST-004", started(r, R))
    v.wait(lambda: "running" in v.statuses(L) and "running" in v.statuses(D), 4 * WAIT)
    info = v.next_info()
    listed = {n.get("node-uuid") for n in (info or {}).get("nodes-executing", [])
              if isinstance(n, dict)}
    judge("TST-013", info is not None and ("nodes-executing" not in info
                                           or listed == {R, C, L, D}))
    # $pause and $continue of a composite reach its running nodes
    judge("TST-011", answered_ok(v.signal("signal-tst-node", C, "$pause")))
    judge("TST-012", v.wait(lambda: all(v.statuses(n)[-1:] == ["paused"] for n in (C, L, D))))
    judge("TST-011", answered_ok(v.signal("signal-tst-node", C, "$continue")))
    judge("TST-012", v.wait(lambda: all(v.statuses(n)[-1:] == ["running"] for n in (C, L, D))))
    # $enough to the whole tree: its running nodes end succeeded
    judge("TST-011", answered_ok(v.signal("signal-tst-tree", R, "$enough")))
    judge("TST-012", v.wait(lambda: v.final(L) == "succeeded" and v.final(D) == "succeeded"))
    v.wait(lambda: v.final(R))
    # a signal to a tree that has ended, and to a node never seen: failed, with a reason
    judge("TST-011", refused(v.signal("signal-tst-node", R, "$abort")))
    judge("TST-011", refused(v.signal("signal-tst-node", new_uuid(), "$pause")))

    # seq [look-at-bearing, look-at-bearing]: $abort of the first child
    S, L1, L2 = (new_uuid() for _ in range(3))
    roots.add(S)
    composites.append((S, "seq", [L1, L2]))
    v.request(start(node("seq", {}, S, [node("look-at-bearing", {"bearing": 10.0}, L1),
                                        node("look-at-bearing", {"bearing": 20.0}, L2)],
                         execunit=me)))
    v.wait(lambda: "running" in v.statuses(L1))
    judge("TST-011", answered_ok(v.signal("signal-tst-node", L1, "$abort")))
    judge("TST-012", v.wait(lambda: v.final(L1) == "aborted"))
    v.wait(lambda: v.final(S) or v.statuses(L2))
    if v.final(S) is None:  # it went on, or ignored $abort: end it
        v.signal("signal-tst-tree", S, "$enough")
        v.wait(lambda: v.final(S))

    # Trees it cannot run: answered failed with a reason, and nothing of them runs.
    F1, F2, F3, F4, F5 = (new_uuid() for _ in range(5))
    refusals = [
        ([F1], node("image-object-detection", {}, F1, execunit=f"/not-{v.name}")),
        ([F2], node("fly-to-the-moon", {}, F2, execunit=me)),
        ([F3], node("move-to", {"waypoint": "home", "speed": 7}, F3, execunit=me)),
        ([F4, F5], node("seq", {}, F4, [node("look-at-bearing", {"bearing": 0.0}, F5),
                                        node("look-at-bearing", {"bearing": 0.0}, F5)],
                        execunit=me)),
    ]
    answers = [(ids, v.request(start(tree))) for ids, tree in refusals]
    v.sync()
    for ids, answer in answers:
        judge("TST-005", refused(answer) and not any(v.feedback(i) for i in ids))
        if answer is not None and answer.get("root-uuid") == ids[0]:
            roots.add(ids[0])  # started after all (a fault): it is a root then

    # resend (12.1): answered again, started once
    X = new_uuid()
    roots.add(X)
    body = start(node("look-at-bearing", {"bearing": 45.0}, X, execunit=me))
    body["com-uuid"] = new_uuid()
    v.send(body)
    first = v.answer(body["com-uuid"])
    v.send(body)
    judge("TST-007", v.answer(body["com-uuid"], n=2) is not None)
    v.sync()
    judge("TST-006", first is not None and v.statuses(X).count("active") == 1)

    # signal-unit names the unit as 14.3.3 writes it ('/dji21'): every running node
    judge("TST-011", answered_ok(v.signal("signal-unit", me, "$abort")))
    judge("TST-012", v.wait(lambda: v.final(X) == "aborted"))
    v.signal("signal-unit", me, "$enough")  # whatever a fault left running ends
    v.sync()

    # Over everything it said: each node reached a final status and said nothing after it;
    # root-flag only on roots; composites followed their children; nothing listed as running.
    for node_uuid in {f.get("node-uuid") for f in v.feedback()}:
        statuses = v.statuses(str(node_uuid))
        finals = [i for i, s in enumerate(statuses) if s in FINAL]
        judge("TST-009", finals and finals[0] == len(statuses) - 1)
        judge("TST-008", {f.get("root-flag") for f in v.feedback(str(node_uuid))}
              == {node_uuid in roots})
    for parent, kind, children in composites:
        final = v.final(parent)
        ends = [v.final(c) for c in children]
        if final is None or None in ends:
            continue  # never ended: TST-009's
        judge("TST-010", final == outcome(ends))
        if kind == "seq":  # nothing runs after a child that did not succeed
            for i, end in enumerate(ends):
                if end != "succeeded":
                    judge("TST-010", all(set(v.statuses(c)) <= {"revoked"}
                                         for c in children[i + 1:]))
    ok.setdefault("TST-010", True)
    info = v.next_info()
    judge("TST-013", info is not None and not info.get("nodes-executing"))
    return ok

"""A workout for one simulated unit: every active scenario of spec 12 in one pass (ping,
start-task with and without task-uuid, every built-in signal, query-status over the history,
resend, invalid and unknown tasks, a malformed command, a reboot), judged rule by rule.

A deliberately small judge of the tests' own (the certification suite is a colleague's): it
shows that each fault of the simulator changes exactly the behaviour it names.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from typing import Any

from sim_observer import Observer

from conformance.sim.vehicle import GeoPoint, destination

FINAL = ("finished", "aborted", "failed")
WAIT = 2.0  # seconds for an answer on loopback (a deadline, not a duration claim)


class UnitView:
    """The messages of one unit (its topic base) inside a shared observer."""

    def __init__(self, obs: Observer, base: str) -> None:
        self.obs, self.base = obs, base
        self.command_topic = f"{base}/exec/command"

    def json_on(self, sub: str, mark: int = 0) -> list[Any]:
        return [x for x in self.obs.json_on(f"{self.base}/{sub}", mark) if isinstance(x, dict)]

    def send(self, body: dict[str, Any] | bytes) -> str:
        return self.obs.send(body, topic=self.command_topic)

    def answer(self, com: str, n: int = 1, timeout: float = WAIT) -> dict[str, Any] | None:
        def found(_: Any) -> Any:
            got = [r for r in self.json_on("exec/response") if r.get("response-to") == com]
            return got[n - 1] if len(got) >= n else None
        return self.obs.wait_for(found, timeout, fail=False)

    def request(self, body: dict[str, Any], timeout: float = WAIT) -> dict[str, Any] | None:
        return self.answer(self.send(body), timeout=timeout)

    def feedback(self, task_uuid: str) -> list[str]:
        # 'success' (12.1's word) reads as finished: ERR-006's warning, not a missing end.
        return ["finished" if f.get("status") == "success" else f.get("status")
                for f in self.json_on("exec/feedback") if f.get("task-uuid") == task_uuid]

    def wait_feedback(self, task_uuid: str, wanted: Callable[[list[str]], bool],
                      timeout: float = WAIT) -> list[str] | None:
        return self.obs.wait_for(lambda _: (fb := self.feedback(task_uuid)) and wanted(fb)
                                 and fb, timeout, fail=False)

    def next_info(self, mark: int, timeout: float = WAIT) -> dict[str, Any] | None:
        return self.obs.wait_for(lambda _: (got := self.json_on("direct_execution_info", mark))
                                 and got[0], timeout, fail=False)

    def position(self) -> GeoPoint | None:
        got = self.obs.wait_for(lambda _: self.json_on("sensor/position"), WAIT, fail=False)
        if not got:
            return None
        p = got[-1]
        return GeoPoint(p["latitude"], p["longitude"], p.get("altitude", 0.0))

    def heartbeat_uuid(self, mark: int = 0, timeout: float = WAIT) -> str | None:
        return self.obs.wait_for(lambda _: (got := self.json_on("heartbeat", mark))
                                 and got[-1].get("agent-uuid"), timeout, fail=False)


def start_body(name: str, params: dict[str, Any], task_uuid: str | None) -> dict[str, Any]:
    body: dict[str, Any] = {"command": "start-task", "task": {"name": name, "params": params}}
    if task_uuid is not None:
        body["task-uuid"] = task_uuid
    return body


NEAR = {"latitude": 58.39455, "longitude": 15.56455, "altitude": 10.0, "rostype": "GeoPoint"}


def workout(u: UnitView, reboot: Callable[[], None], malformed: set[str] | None = None
            ) -> dict[str, bool]:
    """Drive one unit through every active scenario; the verdict (True: passed) per rule.
    ``malformed`` collects the com-uuids of the malformed commands it sent."""
    ok: dict[str, bool] = {}

    def judge(rule: str, passed: bool) -> None:
        ok[rule] = ok.get(rule, True) and bool(passed)

    def signal(task: str, name: str) -> dict[str, Any] | None:
        return u.request({"command": "signal-task", "task-uuid": task, "signal": name})

    def query(task: str) -> str | None:
        r = u.request({"command": "query-status", "task-uuid": task})
        return None if r is None else r.get("response")

    def ping(wait: float = WAIT) -> tuple[str, dict[str, Any] | None]:
        """A ping and the first pong after it (matched by arrival: response-to is judged)."""
        mark = u.obs.mark()
        com = u.send({"command": "ping"})
        return com, u.obs.wait_for(lambda _: next((r for r in u.json_on("exec/response", mark)
                                                   if str(r.get("response")).lower() == "pong"),
                                                  None), wait, fail=False)

    # ping (12.2.1): a pong after the ping; its response-to is the ping's com-uuid
    com, pong = ping()
    judge("EXEC-PING-001", pong is not None)
    if pong is not None:
        judge("EXEC-PING-002", pong.get("response-to") == com)

    # start-task with a task-uuid: running, the same task-uuid back, feedback to a final status
    moving = str(uuid.uuid4())
    here = u.position()
    near = destination(here, 45.0, 15.0, 10.0) if here else None  # near the unit (safety)
    waypoint = {"latitude": near.latitude, "longitude": near.longitude, "altitude": 10.0,
                "rostype": "GeoPoint"} if near else NEAR
    r = u.request(start_body("move-to", {"waypoint": waypoint, "speed": "fast"}, moving))
    judge("EXEC-START-001", r is not None and r.get("response") == "running")
    if r is not None:  # judged on an answer that came (as the suite does)
        judge("EXEC-START-002", r.get("task-uuid") == moving)
    judge("EXEC-START-003", u.wait_feedback(moving, lambda fb: fb[-1] in FINAL, 4 * WAIT)
          is not None)
    mark = u.obs.mark()
    info = u.next_info(mark)
    judge("DEI-004", info is not None and moving not in str(info.get("tasks-executing")))

    # start-task without a task-uuid: one is generated
    mark = u.obs.mark()
    com = u.send(start_body("look-at-bearing", {"bearing": 30.0}, None))
    r = u.answer(com)
    looking = r.get("task-uuid") if r else None
    if r is None and u.heartbeat_uuid(u.obs.mark()) is None:
        ok["(died)"] = False  # the unit died on it: HB-012, for the Monitor to judge
        return ok
    if r is None and not u.json_on("exec/feedback", mark):
        ok["(dropped)"] = False  # lost without a trace: no task to follow (EXEC-START-001)
        return ok
    if r is not None:
        judge("EXEC-START-002", isinstance(looking, str) and bool(looking))
    if not isinstance(looking, str):  # not returned: follow the task by its feedback
        looking = u.obs.wait_for(lambda _: next((f.get("task-uuid") for f in u.json_on(
            "exec/feedback", mark) if f.get("task-uuid") not in (moving, None)), None),
            WAIT, fail=False)
    if not isinstance(looking, str):
        return ok
    info = u.next_info(u.obs.mark())
    judge("DEI-004", info is not None and looking in str(info.get("tasks-executing")))
    judge("EXEC-QUERY-001", query(looking) == "running")

    # $pause -> paused, $continue -> running, $enough -> finished
    judge("EXEC-SIG-001", signal(looking, "$pause") is not None)
    judge("EXEC-SIG-003", u.wait_feedback(looking, lambda fb: "paused" in fb) is not None)
    judge("EXEC-SIG-001", signal(looking, "$continue") is not None)
    judge("EXEC-SIG-003", u.wait_feedback(
        looking, lambda fb: "paused" in fb and "running" in fb[fb.index("paused"):]) is not None)
    judge("EXEC-SIG-001", signal(looking, "$enough") is not None)
    judge("EXEC-SIG-004", u.wait_feedback(looking, lambda fb: fb[-1] == "finished")
          is not None)
    for task in (looking, moving):  # the status its feedback last gave, over the history
        said = (u.feedback(task)[-1:] or ["?"])[0]
        allowed = {"finished": ("finished", "success"),  # ERR-006's reading
                   "aborted": ("aborted",), "failed": ("failed",)}.get(said, FINAL + (
                       "success",))  # no final feedback: any final status
        judge("EXEC-QUERY-001", query(task) in allowed)

    # $abort -> aborted
    detecting = str(uuid.uuid4())
    u.request(start_body("image-object-detection", {}, detecting))
    judge("EXEC-SIG-001", signal(detecting, "$abort") is not None)
    judge("EXEC-SIG-002", u.wait_feedback(detecting, lambda fb: "aborted" in fb) is not None)

    # a signal for a task never seen: failed; a query for it: unknown
    r = signal(str(uuid.uuid4()), "$abort")
    judge("EXEC-SIG-005", r is not None and r.get("response") == "failed")
    never = query(str(uuid.uuid4()))
    judge("EXEC-QUERY-002", never == "unknown")

    # resend (12.1): answered again, executed once
    body = start_body("image-object-detection", {}, str(uuid.uuid4()))
    body["com-uuid"] = str(uuid.uuid4())
    u.send(body)
    first = u.answer(body["com-uuid"])
    u.send(body)
    second = u.answer(body["com-uuid"], n=2)
    if first is not None:  # a resend is judged where the first send was answered
        judge("EXEC-RESEND-002", second is not None)
        u.next_info(u.obs.mark())  # by the next info message a second run would have begun
        judge("EXEC-RESEND-001", u.feedback(body["task-uuid"]).count("running") == 1)
    signal(body["task-uuid"], "$enough")

    # invalid parameters and a task not offered: refused, with a reason
    r = u.request(start_body("move-to", {"waypoint": "home", "speed": 7}, str(uuid.uuid4())))
    if r is None and u.heartbeat_uuid(u.obs.mark()) is None:
        ok["(died)"] = False  # the unit died on it: HB-012, for the Monitor to judge
        return ok
    judge("EXEC-START-004", r is not None and r.get("response") == "failed"
          and bool(r.get("fail-reason")))
    moon = str(uuid.uuid4())
    r = u.request(start_body("fly-to-the-moon", {}, moon))
    judge("EXEC-START-005", r is not None and r.get("response") == "failed")
    # A refused task never runs (5.3): three info messages later it is not listed either.
    mark, info = u.obs.mark(), None
    for _ in range(3):
        info = u.next_info(mark)
        mark = u.obs.mark()
    judge("DEI-004", info is not None and moon not in str(info.get("tasks-executing")))

    # a malformed command with a readable com-uuid: failed; the unit still pings
    bad = str(uuid.uuid4())
    if malformed is not None:
        malformed.add(bad)
    u.send(b'{"com-uuid": "' + bad.encode() + b'", "command": "signal-task", signal: $abort}')
    r = u.answer(bad)
    judge("EXEC-ROBUST-002", r is not None and r.get("response") == "failed")
    # Still alive after them: a pong, however late (lateness is EXEC-PING-001's and EXEC-010's);
    # judged only when the unit answered a ping before (a kind it answered)
    if pong is not None:
        judge("EXEC-ROBUST-001", ping(4 * WAIT)[1] is not None)

    # reboot: a new agent-uuid; the earlier task unknown (or still known with the same uuid)
    before = u.heartbeat_uuid()
    mark = u.obs.mark()
    reboot()  # returns once the unit is back and has sent its first heartbeat
    after = u.obs.wait_for(lambda _: next((h["agent-uuid"] for h in u.json_on("heartbeat", mark)
                                           if h.get("agent-uuid") != before), None),
                           WAIT / 2, fail=False) or u.heartbeat_uuid(mark)
    judge("REBOOT-001", after is not None and after != before)
    # Forgotten means: answered as the unit answers for a task it never saw (its word for
    # 'unknown' is EXEC-QUERY-002's business, as in the certification suite).
    remembered = query(moving)
    judge("REBOOT-002", remembered == never if after != before
          else remembered in ("finished", "success"))
    return ok

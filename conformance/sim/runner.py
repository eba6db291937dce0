"""Task execution of the reference unit: the tasks of one life, stepped with the vehicle, and
the feedback each status change sends (12.4).

One runner serves start-task and the leaves of TST trees (14: 'the Task execution is the same
as for level 2'): a task started by start-task reports on ``exec/feedback``, a TST leaf to its
node (``Task.node``, ``conformance.sim.tst_tree``). Free of threads, like ``UnitCore``: ``now``
is ``time.monotonic()`` seconds.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import TYPE_CHECKING

from conformance.sim.memory import forget_oldest_ended
from conformance.sim.tasks import Task
from conformance.sim.vehicle import GeoPoint, bearing

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

STEP = 0.1
"""Seconds between simulation steps while a task runs or the vehicle moves."""


class TaskRunner:
    """The tasks one ``UnitCore`` runs (task-uuid -> task, in start order) and its vehicle."""

    def __init__(self, unit: UnitCore) -> None:
        self.unit = unit
        self.faults = unit.faults
        self.vehicle = unit.vehicle
        self.tasks: OrderedDict[str, Task] = OrderedDict()
        self.last_step: float | None = None
        """When tasks and vehicle were last stepped (monotonic seconds)."""

    @property
    def now(self) -> float:
        """The clock of the last step (0 before the first): for what happens between steps."""
        return self.last_step if self.last_step is not None else 0.0

    def remember(self, task: Task) -> None:
        self.tasks[task.uuid] = task
        forget_oldest_ended(self.tasks)

    def busy(self) -> bool:
        """Whether a task runs or the vehicle still moves (then the unit steps every STEP)."""
        v = self.vehicle
        return (v.speed > 0 or v.target is not None or v.vertical != 0
                or any(not t.ended for t in self.tasks.values())
                or (v.look_at is not None and abs(((v.look_at - v.heading) + 180) % 360 - 180)
                    > 0.01))

    # --- stepping -----------------------------------------------------------------------------
    def step(self, now: float) -> None:
        """Advance the running tasks and the vehicle to ``now``."""
        last = self.last_step if self.last_step is not None else now
        self.last_step = now
        dt = min(now - last, 1.0)  # a stalled process does not teleport the vehicle
        v = self.vehicle
        mover = next((t for t in self.tasks.values()
                      if t.group == "motion" and t.status == "running"), None)
        watcher = next((t for t in reversed(self.tasks.values())
                        if t.look_at is not None and not t.ended), None)
        if watcher is not None:
            target = watcher.look_at
            v.look_at = bearing(v.position, target) if isinstance(target, GeoPoint) else target
        else:
            v.look_at = None
        while dt > 1e-9:  # integrate in slices of at most STEP, however late we run
            v.advance(min(dt, STEP))
            dt -= STEP
        for task in list(self.tasks.values()):
            if task.status != "running":
                continue
            if task.prepared_at is not None and now >= task.prepared_at:
                self.feedback(task, "running")  # variant preparing-status: ready now
            if task.fail_at is not None and now >= task.fail_at:
                self.end(task, "failed", "the task crashed on its parameters")
                continue
            if task is mover or task.group != "motion":
                self.advance(task, now)

    def start(self, task: Task, now: float) -> None:
        """Set a planned task going: its first leg, and as far as it gets by ``now``."""
        if task.legs:
            self.start_leg(task)
        self.advance(task, now)

    def advance(self, task: Task, now: float) -> None:
        """Take a running task through the legs it has completed by ``now``."""
        v = self.vehicle
        while task.status == "running":
            if task.leg >= len(task.legs):
                if task.loop_from is not None and task.loop_from < len(task.legs):
                    task.leg = task.loop_from
                    task.leg_started = now
                    self.start_leg(task)
                    return
                self.end(task, "finished")
                return
            leg = task.legs[task.leg]
            if leg.point is not None:
                if v.target is None:
                    self.start_leg(task)
                if not v.arrived:
                    break
                if not v.through:
                    v.stop()
            elif now - task.leg_started < leg.seconds:
                break
            task.leg += 1
            task.leg_started = now
            if task.leg < len(task.legs):
                self.start_leg(task)
        if (task.name in ("look-at-position", "look-at-positions") and not task.in_view_sent
                and task.look_at is not None and v.look_at is not None
                and abs(((v.look_at - v.heading) + 180) % 360 - 180) < 5.0):
            task.in_view_sent = True  # 9.4: feedback tells whether the position is in view
            self.feedback(task, "in-view-center")

    def start_leg(self, task: Task) -> None:
        leg = task.legs[task.leg]
        if leg.point is not None:
            after = task.leg + 1 if task.leg + 1 < len(task.legs) else task.loop_from
            through = after is not None and task.legs[after].point is not None
            self.vehicle.goto(leg.point, task.cruise, task.climb, through=through,
                              ramp=min(1.0, self.unit.task_seconds / 3))

    # --- status changes -------------------------------------------------------------------------
    def preempt(self, task: Task, reason: str) -> None:
        """The vehicle, the camera or the detector is ``task``'s now: the live task of the same
        group is aborted."""
        for other in list(self.tasks.values()):
            if other is not task and not other.ended and other.group == task.group:
                if other.status == "paused" and "preempt-paused-silently" in self.faults:
                    del self.tasks[other.uuid]  # dropped: no final status, not listed
                    continue
                self.end(other, "aborted", reason)

    def pause(self, task: Task, now: float) -> None:
        """$pause (12.2.2): a running task keeps its place and reports 'paused'."""
        if task.status != "running":
            return
        task.status = "paused"
        leg = task.legs[task.leg] if task.leg < len(task.legs) else None
        if leg is not None and leg.point is None:
            task.paused_left = leg.seconds - (now - task.leg_started)
        if task.group == "motion":
            self.vehicle.stop()
        self.feedback(task, "paused")

    def resume(self, task: Task, now: float) -> None:
        """$continue (12.2.2): a paused task runs on from where it paused."""
        if task.status != "paused":
            return
        task.status = "running"
        task.resume_clock(now)
        if task.group == "motion" and task.leg < len(task.legs):
            self.preempt(task, f"pre-empted by task {task.uuid}")  # the vehicle is its again
            self.start_leg(task)
        self.feedback(task, "running")

    def end(self, task: Task, status: str, reason: str = "") -> None:
        """A task reaches a final status: finished, aborted or failed (12.4)."""
        task.status, task.fail_reason = status, reason
        if task.group == "motion":
            self.vehicle.stop()
        if task.node is not None:  # a TST leaf: its node reports
            task.node(status, reason)
            return
        on_its_own = status == "finished" and not reason
        if not (on_its_own and "no-final-feedback" in self.faults
                or "no-final-status" in self.faults):
            self.feedback(task, status)
            if "feedback-after-final" in self.faults:
                self.feedback(task, status)
        if "response-on-finish" in self.faults:
            unit = self.unit
            unit.send("exec/response", {"agent-uuid": unit.agent_uuid,
                                        "com-uuid": unit.fresh_uuid(), "response": "finished",
                                        "response-to": task.uuid})

    def feedback(self, task: Task, status: str) -> None:
        """Send feedback for a status change of a task (12.4)."""
        if task.node is not None:  # a TST leaf: its node reports
            task.node(status, "")
            return
        if status != "preparing":  # any other status ends its preparing (preparing-status)
            task.prepared_at = None
        unit = self.unit
        agent = unit.executor_uuid if "feedback-stale-agent-uuid" in self.faults \
            else unit.agent_uuid
        if status == "finished" and "feedback-status-done" in self.faults:
            status = "done"
        if status == "finished" and "feedback-says-success" in self.faults:
            status = "success"  # ERR-006: 12.1's query-status word in 12.4's feedback
        body = {"agent-uuid": agent, "com-uuid": unit.fresh_uuid(), "status": status,
                "task-uuid": task.uuid}
        if "feedback-no-com-uuid" in self.faults:
            del body["com-uuid"]
        if "feedback-no-task-uuid" in self.faults:
            del body["task-uuid"]
        unit.send("exec/feedback", body)

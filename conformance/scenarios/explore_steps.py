"""The steps of an exploration (spec 12): one command (or a wait) at a time, sent through the
suite's commander, and after each the unit's answers judged by the Monitor.

A step is typed data (``Start(task, slot=0)``: ``explore_action.py``): the exploration's state
machine chooses it, a replay reads it from a stored story, and ``Explorer.do`` runs it the
same way for both. Tasks are named by their slot (the n-th start-task of the example),
commands by the step that first sent them (for a resend), so a stored story means the same
thing when it is run again with fresh uuids.

The oracle is the Monitor (docs/MODEL.md): every violation it
finds in the unit's traffic while a step runs, of a conversation rule the profile makes an
error, is a disagreement between the model and the unit at that step.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from conformance.judge import violation_verdict
from conformance.profile import Profile
from conformance.protocol import UNCHANGED
from conformance.rules import CATALOGUE, Mode
from conformance.scenarios.context import Context
from conformance.scenarios.deviation import FINAL_STATUSES
from conformance.scenarios.explore_action import (
    Action,
    Ping,
    Query,
    Resend,
    Signal,
    Start,
    Wait,
    slot_of,
    to_json,
)
from conformance.scenarios.explore_cover import MAX_WAIT, reached
from conformance.scenarios.params import valid_params
from conformance.scenarios.sender import Sent, new_uuid
from conformance.scenarios.signal import IMPLIED
from conformance.scenarios.traffic import Entry
from conformance.violation import Verdict, Violation

SHOWN = 300
"""Characters of a message shown in a story (the stored story keeps the same)."""
MAX_STEPS = 200
"""Steps kept per example (a story longer than the step count never happens)."""


def judged(v: Violation, profile: Profile) -> bool:
    """Whether the finding ``v`` is a disagreement: a rule about commands and their answers
    (conversation mode, or 12's own: EXEC-*) whose finding fails under the profile as the
    judge fails it (a decided rule or condition only where the profile adopts it: the public
    L2 agent's story told EXEC-FB-004, a decision, as a failure)."""
    r = CATALOGUE.get(v.rule)
    if r is None:
        return False
    about_commands = r.mode is Mode.CONVERSATION or v.rule.startswith("EXEC-")
    return about_commands and violation_verdict(
        r, profile.severity_of(v.rule), strict=profile.adopts(v.rule),
        condition=v.condition) is Verdict.FAIL


@dataclass
class Slot:
    """A task the exploration started (or tried to): its task-uuid once known and its state
    as the unit showed it (``starting``, ``refused``, ``running``, ``paused``, ``ended``)."""

    name: str
    task_uuid: str | None
    mark: int
    state: str = "starting"
    since: float = 0.0
    """When the exploration first saw it in ``state`` (its clock's now)."""


@dataclass
class Step:
    """One step of a story: what was done, what was sent, what came back, what was wrong."""

    action: Action
    sent: list[str] = field(default_factory=list)
    came: list[str] = field(default_factory=list)
    found: list[Violation] = field(default_factory=list)
    coms: list[str] = field(default_factory=list, repr=False)
    """com-uuids this step sent (its answers are the responses to them)."""
    at: float = field(default_factory=time.time, repr=False)
    """When the step began (Unix time, the clock of the messages' arrival times)."""

    def to_json(self) -> dict[str, Any]:
        return {"action": to_json(self.action), "sent": self.sent, "came": self.came,
                "found": [{"rule": v.rule, "expected": v.expected, "observed": v.observed}
                          for v in self.found]}


def _text_of(v: Violation) -> str:
    return " ".join((v.expected, v.observed, v.excerpt or "", v.detail or ""))


def blame(steps: list[Step], v: Violation) -> int:
    """The step ``v`` is about: the one under way when the traffic it judges came (a task
    that left tasks-executing, an answer, a feedback); for a deadline, whose finding is
    timed when the command was sent, that is the step that sent it. Without a time, the
    step whose command it names (by com-uuid), else the last step."""
    if v.time is not None and steps and steps[0].at <= v.time:
        return max(i for i, step in enumerate(steps) if step.at <= v.time)
    for i, step in enumerate(steps):
        if any(com in _text_of(v) for com in step.coms):
            return i
    return len(steps) - 1


def ours(found: list[Violation], uuids: set[str]) -> list[Violation]:
    """The violations about this example's commands and tasks (by com-uuid or task-uuid):
    one that names none of them is what an earlier example left behind (a task it made the
    unit run again), not this story's."""
    return [v for v in found if any(u in _text_of(v) for u in uuids)]


class Disagreement(AssertionError):
    """The unit's answers broke a rule of the model: each violation is told at the step it
    is about (``blame``); ``step`` is the first such step (an index into ``steps``)."""

    def __init__(self, steps: list[Step], found: list[Violation]) -> None:
        for v in found:
            at = steps[blame(steps, v)].found
            if v not in at:
                at.append(v)
        step = first_disagreement(steps)
        super().__init__(f"step {step + 1}: {', '.join(sorted({v.rule for v in found}))}")
        self.steps = steps
        self.step = step
        self.found = found


def first_disagreement(steps: list[Step]) -> int:
    """The first step where the model and the unit disagree (the last step if none)."""
    return next((i for i, step in enumerate(steps) if step.found), len(steps) - 1)


class UnitDied(Exception):
    """The unit stopped heartbeating during a step and did not come back (HB-012): no
    answer can come, so the exploration ends with the steps that led there."""


class Collector:
    """Violations the Monitor finds for the unit under test, in the order found (given each
    message's violations by the connection, on the MQTT thread)."""

    def __init__(self, unit: str, wanted: Callable[[Violation], bool]) -> None:
        self._unit = unit
        self._wanted = wanted
        self._lock = threading.Lock()
        self._found: list[Violation] = []
        self._count = 0

    def __call__(self, violations: list[Violation]) -> None:
        kept = [v for v in violations if v.unit == self._unit and self._wanted(v)]
        if kept:
            with self._lock:
                self._count += len(kept)
                self._found = (self._found + kept)[-100:]  # bounded: only the newest matter

    def mark(self) -> int:
        with self._lock:
            return self._count

    def since(self, mark: int) -> list[Violation]:
        with self._lock:
            new = self._count - mark
            return list(self._found[-new:]) if new > 0 else []


def _text(data: bytes | str) -> str:
    text = data.decode("utf-8", "backslashreplace") if isinstance(data, bytes) else data
    return text[:SHOWN] + ("..." if len(text) > SHOWN else "")


class Explorer:
    """Runs steps against the unit under test and judges each (``do``); ``begin`` and
    ``end`` frame one example: every task it started is aborted at its end, and its final
    status awaited, so the next example starts from a known state."""

    def __init__(self, ctx: Context, collector: Collector,
                 model_state: Callable[[str], str | None],
                 dead: Callable[[], str] = lambda: "") -> None:
        self.ctx = ctx
        self.collector = collector
        self.dead = dead
        """Why the unit counts as dead, or "" while it lives (asked when an answer did not
        come and neither did a heartbeat)."""
        self.died = ""
        self.model_state = model_state
        """The protocol model's state of a task-uuid (``conformance.protocol``: what the
        Monitor's model holds from the traffic), None where it knows nothing."""
        self.tasks = ctx.startable("explore")
        """Tasks the suite may start (tasks-available, the profile, docs/ARCHITECTURE.md
        'Safety')."""
        self.slots: list[Slot] = []
        self.commands: dict[int, Sent] = {}
        """Step index -> the command it sent (what a resend resends)."""
        self.steps: list[Step] = []
        self.total_steps = 0
        self._pending_until = 0.0
        """Unix time until which an answer or feedback the unit owes is not yet late."""
        self._refused_aborts: list[Slot] = []
        """Tasks whose teardown $abort the unit answered 'failed' (it no longer knows them)."""
        self.covered: Counter[str] = Counter()
        """The model's transitions the run's steps took (``explore_cover.TRANSITIONS``)."""
        self.last_start = 0.0
        """When the example's latest start-task was sent (its clock's now)."""

    # --- an example ---------------------------------------------------------------------------
    def begin(self) -> None:
        self.died = ""
        self.slots, self.commands, self.steps = [], {}, []
        self._pending_until = 0.0
        self._refused_aborts = []
        self.last_start = 0.0

    def end(self) -> None:
        """Abort what this example started, await each final status, then wait until what
        the unit still owes is late (one heartbeat past its deadline), and judge that too."""
        if self.ctx.commander.dry_run or self.died:
            return  # a dead unit answers nothing: the run's own teardown aborts its tasks
        t = self.ctx.timing
        found: list[Violation] = []
        for i, slot in enumerate(self.slots):
            self._refresh(slot)
            if slot.task_uuid is not None and slot.state not in ("refused", "ended"):
                # A step of the story too: a unit may break a rule on this very abort, and
                # every task is aborted all the same.
                try:
                    self.do(Signal("$abort", i, teardown=True))
                except Disagreement as d:
                    found += d.found
        # A task the unit no longer knows (its abort answered 'failed') that never said its
        # final status (12.4) is late once it has left tasks-executing for the response
        # deadline: the Monitor judges it then.
        if any(s.state not in ("refused", "ended") for s in self._refused_aborts):
            self._owe(t.response)
        mark = self.collector.mark()
        self.ctx.commander.abort_all(t.response)
        if self._pending_until:
            until = self._pending_until
            left = until - self.ctx.traffic.clock.now()
            self.ctx.traffic.wait_for(lambda e: e.time > until,
                                      left + t.periods(2, self._rate()),
                                      subtopic="heartbeat", what="the deadlines of the "
                                      "exploration's commands")
        found += ours(self.collector.since(mark), self._uuids())
        if found and self.steps:
            raise Disagreement(self.steps, found)

    # --- one step -----------------------------------------------------------------------------
    def do(self, action: Action) -> Step:
        """Run one step; raises ``Disagreement`` when the Monitor found a violation meanwhile."""
        self.covered.update(reached(self, action))
        step = Step(action, at=self.ctx.traffic.clock.now())
        if len(self.steps) < MAX_STEPS:
            self.steps.append(step)
        self.total_steps += 1
        mark = self.collector.mark()
        after = self.ctx.traffic.mark()
        getattr(self, "_" + action.do)(step, action)
        step.came += [f"{e.subtopic}: {_text(e.excerpt)}" for e in self._answers(after, step)]
        found = ours(self.collector.since(mark), self._uuids())
        if found:
            raise Disagreement(self.steps, found)
        return step

    def _uuids(self) -> set[str]:
        """The com-uuids and task-uuids of this example."""
        found = {com for step in self.steps for com in step.coms}
        found.update(self.ctx.commander.unit_task_uuid(s.task_uuid) for s in self.slots
                     if s.task_uuid)
        found.update(s.task_uuid for s in self.slots if s.task_uuid)
        return found

    def involved(self) -> set[int]:
        """The slots this example's disagreement is about: the tasks its findings name (by
        task-uuid) and the task of each step where one was found."""
        text = " ".join(_text_of(v) for step in self.steps for v in step.found)
        found = {i for i, s in enumerate(self.slots) if s.task_uuid and (
            s.task_uuid in text or self.ctx.commander.unit_task_uuid(s.task_uuid) in text)}
        found.update(slot for step in self.steps if step.found
                     for slot in [slot_of(step.action)] if slot is not None)
        return found

    def _answers(self, after: int, step: Step) -> list[Entry]:
        """What the unit said during the step: responses to its commands, and feedback."""
        coms = set(step.coms)
        return [e for e in self.ctx.traffic.since(after)
                if e.subtopic == "exec/feedback" or e.subtopic == "exec/response"
                and e.get("response-to") in coms][:20]

    def _rate(self) -> float | None:
        return self.ctx.rate_of("heartbeat")

    def _owe(self, seconds: float) -> None:
        self._pending_until = max(self._pending_until, self.ctx.traffic.clock.now() + seconds)

    def _send(self, step: Step, body: dict[str, Any]) -> tuple[Sent, Entry | None]:
        t = self.ctx.timing
        sent, answer = self.ctx.commander.request(body, t.response)
        self.commands[len(self.steps) - 1] = sent
        step.coms.append(sent.com_uuid)
        step.sent.append(_text(sent.payload))
        if answer is None:
            self._unanswered()
        return sent, answer

    def _unanswered(self) -> None:
        """A command's deadline passed: the Monitor judges it on the next heartbeat; a unit
        that sends none and does not come back has died on what this example sent."""
        self._owe(0.0)
        if not self._wait_heartbeat():
            self.died = self.dead()
            if self.died:
                raise UnitDied(self.died)

    def _wait_heartbeat(self, count: int = 1) -> bool:
        """Wait for ``count`` heartbeats (each within a period and the response margin);
        False when one did not come."""
        for _ in range(count):
            after = self.ctx.traffic.mark()
            if self.ctx.traffic.wait_for(lambda e: True, self.ctx.timing.periods(1, self._rate()),
                                         after=after, subtopic="heartbeat",
                                         what="a heartbeat (explore: wait)") is None:
                return False
        return True

    def _uuid(self, slot: int | None) -> str:
        """The task-uuid of slot ``slot``; a task-uuid the unit never saw for None."""
        if slot is None or slot >= len(self.slots) or self.slots[slot].task_uuid is None:
            return new_uuid()
        return self.ctx.commander.unit_task_uuid(str(self.slots[slot].task_uuid))

    def _refresh(self, slot: Slot) -> None:
        """The slot's state as the protocol model holds it (the Monitor's, fed every message
        before the traffic keeps it: what the unit's feedback and answers showed, 12.4); a
        task the model knows nothing of keeps the state it had."""
        if slot.task_uuid is None or slot.state == "refused":
            return
        held = self.model_state(self.ctx.commander.unit_task_uuid(slot.task_uuid))
        state = "ended" if held in FINAL_STATUSES else held
        if state in ("running", "paused", "ended") and state != slot.state:
            slot.state, slot.since = str(state), self.now()

    def now(self) -> float:
        return self.ctx.traffic.clock.now()

    def states(self) -> list[str]:
        """Each slot's state as the unit last showed it."""
        for slot in self.slots:
            self._refresh(slot)
        return [s.state for s in self.slots]

    # --- the commands (12.1) ------------------------------------------------------------------
    def _start(self, step: Step, action: Start) -> None:
        name = action.task
        allowed, why = self.ctx.safety.may_start(name, "explore")
        # A stored story replayed on a unit it may not move (docs/ARCHITECTURE.md 'Safety').
        if not allowed:
            self.slots.append(Slot(name, None, self.ctx.traffic.mark(), "refused"))
            step.came.append(f"not sent: {why}")
            return
        origin = self.ctx.position()
        # The profile's or the spec example's, never invented, inside the safe radius
        # (docs/ARCHITECTURE.md 'Safety'; ``may_start`` above knows there are some).
        params = valid_params(name, origin, self.ctx.safety, self.ctx.seed) \
            if origin is not None else {}
        body: dict[str, Any] = {"command": "start-task", "execution-unit": self.ctx.unit.name,
                                "task": {"name": name, "params": params}}
        if action.task_uuid:
            body["task-uuid"] = new_uuid()
        slot = Slot(name, body.get("task-uuid"), self.ctx.traffic.mark(), since=self.now())
        self.last_start = self.now()
        self.slots.append(slot)
        sent, answer = self._send(step, body)
        if answer is None:
            return
        got = answer.get("task-uuid")
        if slot.task_uuid is None and isinstance(got, str) and got:
            slot.task_uuid = got
        if answer.get("response") == "failed":
            slot.state = "refused"
            return
        slot.state = "running"
        if slot.task_uuid is not None:  # its first feedback (12.4), briefly
            self.ctx.commander.first_feedback(slot.task_uuid, self.ctx.timing.response,
                                              after=sent.mark)
            self._listed(slot.task_uuid, sent.mark)

    def _listed(self, task_uuid: str, after: int) -> None:
        """Until tasks-executing (5.3) lists the task, one period of direct_execution_info at
        most: a task seen listed that leaves it with no final status is EXEC-START-003's
        evidence, whatever step comes next (a unit that never lists it is DEI-004's)."""
        uuid_ = self.ctx.commander.unit_task_uuid(task_uuid)

        def lists(e: Entry) -> bool:
            executing = e.get("tasks-executing")
            return isinstance(executing, list) and any(
                isinstance(t, dict) and t.get("task-uuid") == uuid_ for t in executing)
        self.ctx.traffic.wait_for(
            lists, min(self.ctx.timing.response,
                       self.ctx.timing.periods(1, self.ctx.rate_of("direct_execution_info"))),
            after=after, subtopic="direct_execution_info",
            what=f"task {uuid_} in tasks-executing (explore)")

    def _signal(self, step: Step, action: Signal) -> None:
        signal, slot = action.signal, action.slot
        task_uuid = self._uuid(slot)
        state = self.states()[slot] if isinstance(slot, int) and slot < len(self.slots) else ""
        after = self.ctx.traffic.mark()
        _, answer = self._send(step, {"command": "signal-task", "signal": signal,
                                      "task-uuid": task_uuid})
        if answer is not None and answer.get("response") == "failed" \
                and action.teardown and isinstance(slot, int):
            self._refused_aborts.append(self.slots[slot])
        if answer is None or answer.get("response") == "failed" or signal not in IMPLIED \
                or (signal, state) in UNCHANGED:
            return
        # 12.2.2: the signal's effect, awaited; a unit that owes it is judged at its deadline.
        # Awaited for the response deadline at most (a story's step never takes longer). What
        # is still owed then shows later: the example's end aborts the task, and a final
        # status before the effect is the Monitor's finding at once (exec_feedback).
        wanted = {IMPLIED[signal]} | set(FINAL_STATUSES)
        t = self.ctx.timing
        final = self.ctx.commander.feedback(
            task_uuid, wanted if not action.teardown else set(FINAL_STATUSES),
            min(t.response, t.feedback), after=after, what=f"the feedback of {signal} (explore)")
        if final is None and action.teardown:
            self._owe(t.feedback - t.response)  # the final status of an abort: its deadline

    def _query(self, step: Step, action: Query) -> None:
        self._send(step, {"command": "query-status", "task-uuid": self._uuid(action.slot)})

    def _ping(self, step: Step, action: Ping) -> None:
        self._send(step, {"command": "ping"})

    def _resend(self, step: Step, action: Resend) -> None:
        earlier = self.commands.get(action.step)
        if earlier is None:  # the step it names sent nothing (a shrunk story): a no-op
            return
        c = self.ctx.commander
        mark = self.ctx.traffic.mark()
        c.resend(earlier)
        self.commands[len(self.steps) - 1] = earlier
        step.coms.append(earlier.com_uuid)
        step.sent.append(_text(earlier.payload))
        if c.response(earlier, self.ctx.timing.response, after=mark) is None:
            self._unanswered()

    def _wait(self, step: Step, action: Wait) -> None:
        self._wait_heartbeat(max(1, min(MAX_WAIT, action.periods)))

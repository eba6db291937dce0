"""The model of direct execution (spec 12), as data the suite owns: per task its state, per
command in every state which answers and which feedback are allowed, what follows, and what
tasks-executing (5.3) and query-status (12.1) must then show over the whole history.

One model for both users, so the suite and lint never disagree on a sequence: the exploration
(``conformance.scenarios.explore``) asks it which tasks are running, paused or ended and what a
command may get back; the Monitor's sequence checks (``conformance.checks.exec_sequence``) feed
it every exec message and report what it finds, so lint of a recording and the suite judge a
sequence with the same code. Pure: no MQTT, no paho, no clock of its own (times are the
messages'). Where the spec is silent the model follows the decisions in
``conformance/rules.toml`` (EXEC-SEQ-*) and ``docs/MODEL.md``.

Public API (stable):

- ``State``: ``UNKNOWN`` (never seen), ``RUNNING``, ``PAUSED``, ``FINISHED``, ``ABORTED``,
  ``FAILED``; ``.live``, ``.ended``.
- Tables, which the conversation checks and the scenarios read too (docs/MODEL.md), and
  ``Command``, ``Expectation``, ``Outcome``, ``Finding``: defined in
  ``conformance/expectation.py``, re-exported here:
  ``BUILTIN_SIGNALS``, ``SIGNAL_EFFECT``, ``SIGNAL_RULE``, ``UNCHANGED``, ``STOP_SIGNALS``,
  ``QUERY_ANSWERS``, ``REFUSED_QUERY``.
- ``Command``: one command (``com_uuid``, ``name``, ``task_uuid``, ``signal``, ``task_name``,
  ``content``: a digest); ``Command.read(payload)`` from JSON bytes or a dict (None if no
  com-uuid).
- ``Model(whole_life=False, response_timeout=5.0, feedback_timeout=10.0, tasks_kept=1024)``:
  ``whole_life`` says the observer saw every command of the unit's current life (the suite,
  which commands it; lint of a recording cannot know that).
  - ``expect(command) -> Expectation``: pure, changes nothing.
  - ``observe(message) -> list[Finding]``: feed any ``conformance.message.Message`` (commands,
    responses, feedback, heartbeats; other topics are ignored); the findings are the sequence
    rules' (EXEC-SEQ-*). Or per kind: ``command``, ``response``, ``feedback``, ``heartbeat``
    (a payload dict and a time).
  - ``tasks``: task-uuid -> ``TaskRecord`` (``state``, ``name``, ``statuses``, ...), in start
    order: the unit's one store of tasks, which the exec conversations read and annotate
    (``checks/conversation.py``); ``follow(task_uuid)``: its record, begun (running) if none;
    ``hear(task, status, t)``: a status applied without judging it (a task followed by another
    key, the conversations'); ``task(task_uuid)``: its record in this life, or None;
    ``forget(life, keep=False)``: a new life (12.1), which knows no task of the one before
    (``keep``: their records stay, ``lost``, for the conversations).
    ``states()``: task-uuid -> State; ``running()``, ``paused()``, ``live()``, ``ended()``:
    task-uuids; ``answered``: com-uuid -> (response, task-uuid) of the first answer;
    ``executing()``: the task-uuids tasks-executing must list (the live ones);
    ``query_answers(task_uuid)``: what query-status may answer for it now.
- ``Expectation``: ``command``, ``resend`` (an earlier command with the same com-uuid and
  content), ``responses`` (the allowed words), ``outcome(response) -> Outcome`` (a signal
  accepted in a word but 'ok' has the 'ok' one), ``may_end`` (live tasks it may end, each with
  a final status), ``untouched`` (tasks it must leave), ``rule`` (broken by other answers).
- ``Outcome``: ``response``, ``states`` (task-uuid -> State after it; ``NEW_TASK`` for the
  task a start-task without task-uuid begins, whose uuid the response names), ``implies``
  (task-uuid -> the feedback statuses of which one must follow within ``feedback_timeout``).
- ``Finding``: ``rule``, ``task_uuid``, ``com_uuid``, ``expected``, ``observed``, ``time``
  (the rules judged on feedback by the commands before it are in ``conformance.sequence_rules``:
  EXEC-SEQ-001, EXEC-SEQ-002, a resent signal applied again EXEC-RESEND-001).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import orjson

from conformance.expectation import (  # re-exported: the public API above
    BUILTIN_SIGNALS,
    COMMANDS,
    FINAL,
    NEW_TASK,
    NO_SUCH_TASK,
    QUERY_ANSWERS,
    REFUSED_QUERY,
    SIGNAL_EFFECT,
    SIGNAL_RULE,
    STOP_SIGNALS,
    UNCHANGED,
    Command,
    Expectation,
    Finding,
    Outcome,
)
from conformance.expectation import str_at as _str
from conformance.message import Message
from conformance.sequence_rules import keeps_running, reapplied, touched_by_another
from conformance.status import accepts_signal, meaning
from conformance.taskrecord import State, TaskRecord  # State: re-exported

__all__ = ["BUILTIN_SIGNALS", "COMMANDS", "COMMANDS_KEPT", "FINAL", "NEW_TASK", "NO_SUCH_TASK",
           "QUERY_ANSWERS", "REFUSED_QUERY", "SIGNAL_EFFECT", "SIGNAL_RULE", "STOP_SIGNALS",
           "TASKS_KEPT", "UNCHANGED", "Command", "Expectation", "Finding", "Model", "Outcome",
           "State", "TaskRecord"]

TASKS_KEPT = COMMANDS_KEPT = 1024


class Model:
    """Direct execution of one unit (one life at a time), from the traffic."""

    def __init__(self, *, whole_life: bool = False, response_timeout: float = 5.0,
                 feedback_timeout: float = 10.0, tasks_kept: int = TASKS_KEPT) -> None:
        self.whole_life = whole_life
        self.response_timeout = response_timeout
        self.feedback_timeout = feedback_timeout
        self.tasks_kept = tasks_kept
        self.tasks: OrderedDict[str, TaskRecord] = OrderedDict()
        """The unit's tasks (the one store: the conversation checks read these records)."""
        self.commands: OrderedDict[str, Command] = OrderedDict()
        self.answered: OrderedDict[str, tuple[str | None, str | None]] = OrderedDict()
        self.sent_at: OrderedDict[str, float] = OrderedDict()
        """com-uuid -> when the command last arrived (what may explain a change, EXEC-SEQ-002)."""
        self.first_sent: OrderedDict[str, float] = OrderedDict()
        """com-uuid -> when the command first arrived (feedback since may be its task's)."""
        self.life: str | None = None

    # --- what the explorer asks ---------------------------------------------------------------
    def task(self, task_uuid: str | None) -> TaskRecord | None:
        """The record of ``task_uuid`` in this life (None: unknown, or of a life before)."""
        task = self.tasks.get(task_uuid) if task_uuid else None
        return task if task is not None and not task.lost else None

    def _held(self) -> list[tuple[str, TaskRecord]]:
        """The tasks of this life, in start order."""
        return [(u, t) for u, t in self.tasks.items() if not t.lost]

    def _uuids(self) -> frozenset[str]:
        return frozenset(u for u, _ in self._held())

    def running(self) -> list[str]:
        return [u for u, t in self._held() if t.state is State.RUNNING]

    def paused(self) -> list[str]:
        return [u for u, t in self._held() if t.state is State.PAUSED]

    def live(self) -> list[str]:
        return [u for u, t in self._held() if t.state.live]

    def ended(self) -> list[str]:
        return [u for u, t in self._held() if t.state.ended]

    def states(self) -> dict[str, State]:
        """task-uuid -> its state, in start order."""
        return {u: t.state for u, t in self._held()}

    def executing(self) -> frozenset[str]:
        """5.3: the tasks tasks-executing may list, those that have not ended (a paused one
        may also be left out while paused: 5.3 says 'currently executing')."""
        return frozenset(self.live())

    def state(self, task_uuid: str | None) -> State:
        task = self.task(task_uuid)
        return task.state if task is not None else State.UNKNOWN

    def query_answers(self, task_uuid: str | None) -> frozenset[str]:
        """What query-status of ``task_uuid`` may answer now (12.1, over the whole history).
        A task the model never saw: 'unknown' when it saw the whole life, else anything."""
        task = self.task(task_uuid)
        if task is None:
            return frozenset(QUERY_ANSWERS[State.UNKNOWN]) if self.whole_life else frozenset(
                {"unknown", "running", "paused", "finished", "success", "failed", "aborted"})
        if task.refused:
            return REFUSED_QUERY
        return frozenset(QUERY_ANSWERS[task.state])

    def expect(self, command: Command) -> Expectation:
        """Which answers ``command`` may get now, and what each leads to (pure)."""
        before = self.commands.get(command.com_uuid)
        everyone = self._uuids()
        if before is not None and before.content == command.content \
                and command.com_uuid in self.answered:
            # 12.1: a resend is answered again, as before, and not executed again.
            response, _ = self.answered[command.com_uuid]
            return Expectation(command, True, (Outcome(response or ""),),
                               "EXEC-RESEND-001", untouched=everyone,
                               why="a resend: the first answer again, nothing executed")
        resend = before is not None and before.content == command.content
        name = command.name
        if name == "ping":
            return Expectation(command, resend, (Outcome("pong"),), "EXEC-PING-001",
                               untouched=everyone)
        if name == "query-status":
            answers = self.query_answers(command.task_uuid)
            rule = "EXEC-QUERY-001" if self.task(command.task_uuid) else "EXEC-QUERY-002"
            return Expectation(command, resend, tuple(Outcome(a) for a in sorted(answers)),
                               rule, untouched=everyone)
        if name == "start-task":
            return self._expect_start(command, resend)
        if name == "signal-task":
            return self._expect_signal(command, resend)
        return Expectation(command, resend, (Outcome("failed"),), "EXEC-ROBUST-002",
                           untouched=everyone, why="not one of 12.1's commands: refused")

    def _expect_start(self, command: Command, resend: bool) -> Expectation:
        live = frozenset(self.live())
        uuid = command.task_uuid
        known = self.task(uuid)
        if known is not None and known.state.live:
            # A task-uuid names one task: a start-task naming a live one starts nothing new.
            return Expectation(command, resend, (Outcome("failed"), Outcome("running")),
                               "EXEC-START-001", untouched=self._uuids(),
                               why="task-uuid of a live task: refused, or the same task")
        key = uuid if uuid else NEW_TASK
        running = Outcome("running", {key: State.RUNNING})
        named = uuid if known is None else None  # 12.1's 'finished': done at once (airborne)
        failed = Outcome("failed", {named: State.FAILED} if named else {})
        finished = Outcome("finished", {named: State.FINISHED} if named else {})
        # Spec silent on a second task: the unit may run both or end the first, only with a
        # final status (EXEC-START-003), never silently (docs/MODEL.md).
        return Expectation(command, resend, (running, failed, finished), "EXEC-START-001",
                           may_end=live, untouched=self._uuids() - live,
                           why="a new task; live tasks may end, each with a final status")

    def _expect_signal(self, command: Command, resend: bool) -> Expectation:
        uuid, signal = command.task_uuid, command.signal or ""
        others = self._uuids() - {uuid}
        task = self.task(uuid)
        if task is None or task.refused:
            answers = ("failed",) if self.whole_life else ("failed", "ok")
            return Expectation(command, resend, tuple(Outcome(a) for a in answers),
                               "EXEC-SIG-005", untouched=self._uuids(),
                               why="a task the unit does not know: refused (12.2.2)")
        if task.state.ended:
            return Expectation(command, resend, (Outcome("failed"), Outcome("ok")),
                               "EXEC-SIG-001", untouched=self._uuids(),
                               why="an ended task: nothing follows its final status")
        effect = SIGNAL_EFFECT.get(signal)
        failed = Outcome("failed")
        if effect is None:  # a task-specific signal: its effect is the task's own
            return Expectation(command, resend, (Outcome("ok"), failed), "EXEC-SIG-001",
                               untouched=others)
        status, after = effect
        ok = Outcome("ok") if (signal, task.state) in UNCHANGED else Outcome(
            "ok", {task.task_uuid: after}, {task.task_uuid: frozenset({status})})
        return Expectation(command, resend, (ok, failed), "EXEC-SIG-001",
                           may_end=frozenset({task.task_uuid}) if signal in STOP_SIGNALS
                           else frozenset(), untouched=others,
                           why=f"{signal} to a {task.state.value} task")

    # --- what the traffic shows ---------------------------------------------------------------
    def observe(self, message: Message) -> list[Finding]:
        """Feed one message; the sequence rules it breaks (EXEC-SEQ-*)."""
        topic = message.topic
        if topic.endswith("/heartbeat"):
            self.heartbeat(_load(message.payload), message.time)
            return []
        if topic.endswith("/exec/command"):
            m = _load(message.payload)
            cmd = Command.read(m) if m is not None else None
            if cmd is not None:
                self.command(cmd, message.time)
            return []
        if topic.endswith("/exec/response"):
            self.response(_load(message.payload), message.time)
            return []
        if topic.endswith("/exec/feedback"):
            return self.feedback(_load(message.payload), message.time)
        return []

    def heartbeat(self, m: Any, t: float) -> None:
        """12.1: a new agent-uuid is a new life, which lost the history of commands."""
        agent = _str(m, "agent-uuid")
        if agent is None or agent == self.life:
            return
        if self.life is not None:
            self.forget(agent)
        self.life = agent

    def forget(self, life: str | None, *, keep: bool = False) -> None:
        """12.1: a new life (agent-uuid ``life``) lost every task and com-uuid. ``keep``:
        the records stay, ``lost`` (the Monitor's: the conversations judge the old life's
        tasks by their own life)."""
        if not keep:
            self.tasks.clear()
        for task in self.tasks.values():  # kept: unknown to the model from here
            task.lost = True
        self.commands.clear()
        self.answered.clear()
        self.sent_at.clear()
        self.first_sent.clear()
        self.life = life

    def command(self, cmd: Command, t: float) -> None:
        before = self.commands.get(cmd.com_uuid)
        if before is not None and before.content != cmd.content:
            self.answered.pop(cmd.com_uuid, None)  # another command (EXEC-008, commander's)
        if before is None or before.content != cmd.content:
            _put(self.first_sent, cmd.com_uuid, t, COMMANDS_KEPT)
        _put(self.commands, cmd.com_uuid, cmd, COMMANDS_KEPT)
        _put(self.sent_at, cmd.com_uuid, t, COMMANDS_KEPT)

    def response(self, m: Any, t: float) -> None:
        to = _str(m, "response-to")
        cmd = self.commands.get(to) if to else None
        if cmd is None or to is None:
            return
        value, named = _str(m, "response"), _str(m, "task-uuid")
        if to in self.answered:
            return  # a resend's answer, or an answer too many: EXEC-RESEND-*, EXEC-009's
        _put(self.answered, to, (value, named), COMMANDS_KEPT)
        if cmd.name == "start-task":
            uuid = named or cmd.task_uuid
            if not uuid:
                return
            task = self.task(uuid)
            if value == "running":
                if task is not None and (task.state.live or self._said_since(task, to)):
                    # its feedback came first (12 orders no topics): a final status too
                    task.name, task.started_by = task.name or cmd.task_name, to
                elif task is None:
                    self._remember(uuid, cmd.task_name, State.RUNNING, to)
                else:  # ended or refused: a new task under its uuid, in its record
                    self._begin_anew(task, cmd.task_name, to)
            elif value == "failed" and task is None:
                self._remember(uuid, cmd.task_name, State.FAILED, to, refused=True, ended_at=t)
        elif cmd.name == "signal-task" and accepts_signal(value) and cmd.task_uuid:
            task = self.task(cmd.task_uuid)
            if task is not None and cmd.signal:
                task.acked = (*task.acked, (t, cmd.signal, to))[-8:]

    def _begin_anew(self, task: TaskRecord, name: str | None, com_uuid: str) -> None:
        """A start-task answered 'running' begins a new task under an ended task's uuid, in
        its record (one per task-uuid), moved by the feedback since the command was sent (the
        new task's, come before its answer); its statuses stay (the uuid's history)."""
        sent = self.first_sent.get(com_uuid, float("inf"))
        task.name, task.state, task.started_by, task.refused = name, State.RUNNING, com_uuid, False
        task.ended_at, task.acked = None, ()
        for t, status in [x for x in task.statuses if x[0] >= sent]:
            self._move(task, status, t)
        self.tasks.move_to_end(task.task_uuid)

    def _said_since(self, task: TaskRecord, com_uuid: str) -> bool:
        """The task was first seen in feedback after command ``com_uuid`` was sent: that
        command's task, whose feedback came before its answer."""
        sent = self.first_sent.get(com_uuid)
        return (task.started_by is None and not task.refused and sent is not None
                and bool(task.statuses) and task.statuses[0][0] >= sent)

    def feedback(self, m: Any, t: float) -> list[Finding]:
        uuid, raw = _str(m, "task-uuid"), _str(m, "status")
        status = meaning(raw) or raw
        if not uuid or status is None:
            return []
        task = self.follow(uuid)
        previous = task.last_status
        found: list[Finding] = []
        if task.state.live:  # the sequence rules (``conformance.sequence_rules``)
            for rule in (keeps_running, touched_by_another, reapplied):
                found += rule(self, task, status, previous, t)
        self.hear(task, status, t)
        return found

    def follow(self, task_uuid: str) -> TaskRecord:
        """The record of ``task_uuid``; one begun (running: 12.4 feedback comes from a task
        that runs) when none is held."""
        return self.task(task_uuid) or self._remember(task_uuid, None, State.RUNNING)

    def hear(self, task: TaskRecord, status: str, t: float) -> None:
        """12.4: its feedback said ``status`` (its meaning, ``conformance.status``): a final
        status ends it, 'running' and 'paused' move it; after the end nothing moves it
        (EXEC-FB-004 / EXEC-RESEND-001 are the conversations' to judge)."""
        task.said(status, t)
        self._move(task, status, t)

    @staticmethod
    def _move(task: TaskRecord, status: str, t: float) -> None:
        if task.state.ended:
            return
        if status in FINAL:
            task.state, task.ended_at = FINAL[status], t
        elif status == "running":
            task.state = State.RUNNING
        elif status == "paused":
            task.state = State.PAUSED

    def _remember(self, task_uuid: str, name: str | None, state: State, started_by: str | None
                  = None, refused: bool = False, ended_at: float | None = None) -> TaskRecord:
        """A new task under ``task_uuid``: in the record of a life before if one is kept
        (one record per task-uuid; what the conversations keep on it is theirs), else new."""
        task = self.tasks.pop(task_uuid, None)
        if task is None:
            task = TaskRecord(task_uuid, name, state, started_by, refused, ended_at=ended_at)
        else:
            task.name, task.state, task.started_by, task.refused = name, state, started_by, refused
            task.ended_at, task.acked, task.lost = ended_at, (), False
        self.tasks[task_uuid] = task
        if len(self.tasks) > self.tasks_kept:  # a lost, else the oldest ended task goes first
            oldest = next((u for u, x in self.tasks.items() if x.lost), None) or next(
                (u for u, x in self.tasks.items() if x.state.ended), next(iter(self.tasks)))
            del self.tasks[oldest]
        return task



def _load(payload: bytes) -> Any:
    try:
        return orjson.loads(payload)
    except (orjson.JSONDecodeError, TypeError):
        return None


def _put(d: OrderedDict[str, Any], key: str, value: Any, limit: int) -> None:
    d[key] = value
    d.move_to_end(key)
    if len(d) > limit:
        d.popitem(last=False)

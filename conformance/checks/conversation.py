"""Conversations (spec 12; docs/ARCHITECTURE.md 'Whose fault it is'): what one unit was
told on ``exec/command`` and how it answered, as the traffic showed it.

A command on ``exec/command`` opens a conversation (``exec_command``): its response
(``response-to`` = its com-uuid; ``exec_response``), then, for a started task, feedback until a
final status (``exec_feedback``); a resend (the same com-uuid, the same content) belongs to the
same conversation; query-status answers must agree with what the traffic showed of the task.
Deadlines pass on the unit's heartbeats and at the end (``exec_deadline``). The same code
judges a recording in ``lint`` and the suite's own commands in ``pytest --unit``; what exec and
TST conversations share is ``command_history``'s.

One task state: the tasks are the unit's ``protocol.Model``'s (``model``, made
with the conversations, fed every exec message first by ``exec_sequence``). The model owns a
task's record, its state and statuses; the conversations read them and keep on the record only
their evidence (which start-task began it, its final feedback, resends, tasks-executing), and
here their deadlines (``Expect``), commands and the task-uuids still open (``running``).

Blame goes to the root cause, so that one fault fails one rule:
- each command left unanswered fails its own rule, judged when the unit next answers or at the
  end; a unit that also answers none of two or more commands of different kinds, kinds it
  answered before, sent after its last answer, while it heartbeats past their deadline,
  stopped answering (EXEC-ROBUST-001, naming the command before them); the command a dying
  unit received last, and those after, are its death's (HB-012, which names every command of
  the period before its last heartbeat); those before it were left unanswered by a live unit;
- feedback after a final status that a resend caused is EXEC-RESEND-001's, not EXEC-FB-004's.

Everything is bounded: histories are LRUs, open expectations are capped and expire, and what
was dropped is counted and said in the report (``note``).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

from conformance import protocol
from conformance.checks.base import CheckContext, UnitState
from conformance.checks.command_history import (
    PENDING_KEPT,
    CommandHistory,
    SentCommand,
    died_on_any,
    per_unit,
    str_of,
)
from conformance.checks.stash import StashKey
from conformance.status import FINAL_STATUSES
from conformance.taskrecord import STATUSES_KEPT, State, TaskRecord
from conformance.topics import DIRECT_EXECUTION

COMMANDS_KEPT = 1024
"""Commands remembered per unit (resends, late answers, EXEC-006): at one a minute, 17 hours;
a few hundred bytes each, so a fleet of 200 units stays under about 100 MiB however long."""
TASKS_KEPT = protocol.TASKS_KEPT
"""Tasks kept per unit: the bound of the model's store, made with the conversations."""
LISTED_KEPT = 256
"""Task-uuids whose first listing in tasks-executing is remembered per unit (DEI-004)."""
FEEDBACK_WITHOUT_TASK_UUID: StashKey[bool] = StashKey("feedback-without-task-uuid")
"""The unit sent feedback without a task-uuid."""

ANSWER_RULE = {"ping": "EXEC-PING-001", "start-task": "EXEC-START-001",
               "signal-task": "EXEC-SIG-001", "query-status": "EXEC-QUERY-001"}
"""The rule a command's missing or unfitting answer breaks; any other command (unknown or
malformed) should be answered 'failed': EXEC-ROBUST-002."""
MALFORMED = "(malformed)"


class Command(SentCommand):
    """One command sent to a unit on exec/command, and what came back."""

    __slots__ = ("task_uuid", "task_name", "signal", "sender", "invalid")

    def __init__(self, com_uuid: str, name: str, t: float, m: Any, digest: bytes,
                 excerpt: bytes, invalid: bool, life: str | None) -> None:
        super().__init__(com_uuid, name, t, digest, excerpt, life)
        self.task_uuid = str_of(m, "task-uuid")
        task = m.get("task") if isinstance(m, dict) else None
        self.task_name = str_of(task, "name")
        self.signal = str_of(m, "signal")
        self.sender = str_of(m, "sender")
        self.invalid = invalid
        """start-task whose parameters break the task's specification (TASK-001)."""

    def describe(self) -> str:
        what = self.name if self.name != MALFORMED else "a malformed command"
        if self.task_name:
            what += f" '{self.task_name}'"
        if self.signal:
            what += f" {self.signal}"
        if self.name == "start-task" and not self.task_uuid:
            what += " without task-uuid"  # what public agents die on (12.1 makes it optional)
        elif self.invalid:
            what += " with parameters its task's specification refuses"
        return f"{what} (com-uuid {self.com_uuid})"


class Expect:
    """Feedback an accepted signal implies (12.2.2), due by ``deadline``."""

    __slots__ = ("task_uuid", "wanted", "rule", "deadline", "command")

    def __init__(self, task_uuid: str, wanted: set[str], rule: str, deadline: float,
                 command: Command) -> None:
        self.task_uuid, self.wanted, self.rule = task_uuid, wanted, rule
        self.deadline, self.command = deadline, command


class Conversations(CommandHistory):
    """What one unit was told on exec/command and how it answered (bounded), over the tasks
    of its ``model``."""

    def __init__(self, model: protocol.Model | None = None) -> None:
        super().__init__(COMMANDS_KEPT)
        self.model = model if model is not None else protocol.Model(tasks_kept=TASKS_KEPT)
        """The unit's model of direct execution: the one store of its tasks."""
        self.running: OrderedDict[str, None] = OrderedDict()
        """The task-uuids of the tasks a start-task began in this life that have not ended
        (at most PENDING_KEPT; their records are the model's)."""
        self.expects: list[Expect] = []
        self.stray_pongs: list[tuple[float, str]] = []
        self.last_command: Command | None = None
        self.levels_reported: set[str] = set()
        self.silent_until: float | None = None
        """The end of the latest heartbeat silence over 2 periods: perhaps a reboot that kept
        its agent-uuid, whose history loss is REBOOT-002's to judge, not EXEC-QUERY-001's."""
        self.lists_twice = False
        """tasks-executing listed a task twice that no resend explains (DEI-004): a task
        listed twice after its resend is then no sign it ran twice (EXEC-RESEND-001)."""
        self.first_listed: OrderedDict[str, float] = OrderedDict()
        """When tasks-executing first listed each task-uuid (the latest LISTED_KEPT), and
        the ones DEI-004 already named (time -1: once per task)."""

    @property
    def tasks(self) -> OrderedDict[str, TaskRecord]:
        """The model's tasks (the one store; not a copy)."""
        return self.model.tasks

    def followed(self, task_uuid: str | None) -> TaskRecord | None:
        """The task the conversations follow under ``task_uuid``: the model's record, unless
        nothing but a refused start-task showed it (it never ran), or a start-task naming its
        uuid is to begin it anew."""
        task = self.model.tasks.get(task_uuid) if task_uuid else None
        return task if task is not None and task.followed is not None else None

    def task(self, task_uuid: str, t: float, command: Command | None = None) -> TaskRecord:
        """Follow ``task_uuid`` from ``t``, in this life, with no evidence yet (``command``:
        the start-task that began it): the model's record, begun if it holds none."""
        task = self.model.follow(task_uuid)
        task.followed, task.command, task.life = t, command, self.life
        task.final = task.resent = task.left_at = task.listed_at = None
        task.listed, task.running_feedback, task.said_failed = False, 0, ()
        return task

    def unfollow(self, task_uuid: str) -> None:
        """12.1: a start-task naming ``task_uuid`` begins a new task under it."""
        task = self.model.tasks.get(task_uuid)
        if task is not None:
            task.followed = None

    def open(self) -> list[TaskRecord]:
        """The records of the tasks still open (``running``), oldest first: one a start-task
        naming its uuid is to begin anew stays open until the new one starts or it ends."""
        tasks = self.model.tasks
        return [t for t in map(tasks.get, self.running) if t is not None]

    def started(self, task: TaskRecord) -> None:
        self.running[task.task_uuid] = None
        self.running.move_to_end(task.task_uuid)
        if len(self.running) > PENDING_KEPT:
            self.running.popitem(last=False)
            self.dropped += 1

    def ended(self, task: TaskRecord, final: tuple[str, str | None, float]) -> None:
        task.final = final
        self.running.pop(task.task_uuid, None)

    def begin_life(self, agent: str) -> None:
        """12.1: a new agent-uuid; the model's tasks are of this life from here."""
        super().begin_life(agent)
        self.model.life = agent


def said(task: TaskRecord, last: int = 1) -> list[tuple[float, str]]:
    """(time, status) of the ``last`` latest statuses (the model's) the task said since the
    conversations follow it."""
    since = task.followed if task.followed is not None else float("inf")
    found: list[tuple[float, str]] = []
    for heard in reversed(task.statuses):
        if heard[0] < since or len(found) == last:
            break
        found.append(heard)
    return found


def latest(task: TaskRecord) -> tuple[float, str] | None:
    """(time, status) of the latest feedback the conversation judges the task by: its final
    status once it ended (12.4: nothing follows it), else its latest since it is followed."""
    if task.final is not None and task.final[0] in FINAL_STATUSES:
        return task.final[2], task.final[0]
    found = said(task)
    return found[0] if found else None


def latest_status(task: TaskRecord) -> str | None:
    """The status of ``latest`` (None: none said since it is followed)."""
    last = latest(task)
    return last[1] if last is not None else None


MOVES = frozenset({"running", "paused", *FINAL_STATUSES})
"""12.4: the statuses that set a task's state (a task-specific one leaves it as it was)."""


def state_of(task: TaskRecord) -> State:
    """The task's state as the conversations follow it: the latest status since they follow
    it that sets one (the model's state when its statuses kept go back no further); without
    one, running when a start-task answered 'running' began it (12.1), else unknown. The
    model's state but where they follow a task anew or on after its end (a start-task naming
    its uuid; a resend that ran it again, EXEC-RESEND-001; its start refused)."""
    heard = said(task, STATUSES_KEPT)
    status = next((s for _, s in heard if s in MOVES), None)
    if status is not None:
        return State(status)
    if len(heard) == STATUSES_KEPT:
        return task.state
    return State.RUNNING if task.command is not None else State.UNKNOWN


def task_uuid_sent(m: Any) -> str | None:
    """The task a response or feedback names: its task-uuid, else the ``uuid`` some agents
    send instead (docs/FIELD-NOTES.md 'Precision': other keys). The wrong key is EXEC-FB-001's (or
    EXEC-START-002's) finding; the task is still tracked by what the unit sends."""
    found = str_of(m, "task-uuid")
    if found is None and isinstance(m, dict) and "task-uuid" not in m:
        found = str_of(m, "uuid")
    return found


CONVERSATIONS: StashKey[Conversations] = StashKey("conversations")
"""The unit's exec conversations (made by ``conversations``)."""


def conversations(unit: UnitState, ctx: CheckContext | None = None) -> Conversations:
    """The unit's conversations and its model (made together, on first use; the model's
    timeouts are the profile's)."""
    c = unit.stash.get(CONVERSATIONS)
    if c is None:
        c = per_unit(unit, CONVERSATIONS, lambda: Conversations(_model(ctx)))
        c.model.life = c.life
    return c


def answered(unit: UnitState, com_uuid: str) -> bool:
    """Whether the command ``com_uuid`` got an answer (late ones too): a scenario that gave up
    waiting just before it came found no answer, but the Monitor judged it late."""
    c = unit.stash.get(CONVERSATIONS)
    cmd = c.commands.get(com_uuid) if c is not None else None
    return cmd is not None and cmd.answers > 0


def _model(ctx: CheckContext | None) -> protocol.Model:
    if ctx is None:
        return protocol.Model(tasks_kept=TASKS_KEPT)
    return protocol.Model(response_timeout=ctx.profile.response_timeout,
                          feedback_timeout=ctx.profile.feedback_timeout, tasks_kept=TASKS_KEPT)


def commands_died_on(unit: UnitState, last: float, period: float) -> list[Command]:
    """The commands a unit whose last heartbeat was at ``last`` may have died on, the last
    first (``command_history.died_on_any``: those unanswered in the period before it and the
    first in the period after), else the last it received before it fell silent: HB-012's
    finding names them."""
    c = unit.stash.get(CONVERSATIONS)
    if c is None:
        return []
    found = died_on_any(c, last, period)
    if found:
        return found
    latest = None
    for cmd in c.commands.values():
        if cmd.last_sent <= last + period and (latest is None
                                               or cmd.last_sent >= latest.last_sent):
            latest = cmd
    return [latest] if latest is not None else []


def dropped(unit: UnitState) -> int:
    """Open expectations dropped for bounded memory (said in the report)."""
    c = unit.stash.get(CONVERSATIONS)
    return c.dropped if c is not None else 0


def expects_answers(unit: UnitState, c: Conversations) -> bool:
    """12.1: a unit answers commands when it declares direct execution or has answered any."""
    return c.answered_any or unit.claims(DIRECT_EXECUTION)

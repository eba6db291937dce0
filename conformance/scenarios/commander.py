"""The commander side of spec 12: send commands to the unit under test and wait for its answers.

Only the unit's own ``exec/command`` topic is ever published to (the MQTT client's publish
policy enforces it as well: docs/ARCHITECTURE.md 'Safety'). Every task the commander starts is
remembered until a final status is seen, so ``abort_all`` can end it at teardown, on failure and on
Ctrl-C. Under ``--dry-run`` nothing is published: ``send`` prints what it would publish and
raises ``DryRun``. Whether a task has ended is the Monitor's model's to say (``task_state``,
the suite's), and read from the raw feedback only without one.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from typing import Any

from conformance.protocol import NO_SUCH_TASK, State
from conformance.scenarios.deviation import (
    FINAL_STATUSES,
    SHORT,
    UNANSWERED,
    Deviations,
    Kind,
    meaning,
)
from conformance.scenarios.sender import Sender, Sent, new_uuid
from conformance.scenarios.traffic import Entry, Traffic
from conformance.topics import UnitAddress

"""A task name no unit offers: a start-task of it is refused and can move nothing."""


@dataclass
class OpenTask:
    """A task this commander started and has not seen end: what it must abort (its state is
    the model's, ``Commander.task_state``)."""

    task_uuid: str
    name: str
    mark: int
    """Traffic mark from when the task was started: its feedback arrives after this (read
    only without the model)."""
    com_uuids: list[str] = field(default_factory=list)
    stuck: bool = False
    """Its $abort went unanswered: teardown between scenarios does not abort it again
    (i20 6: the same stuck tasks were aborted in every scenario); the run's last does."""


def _describe(body: dict[str, Any]) -> str:
    """A command in a few words: ``start-task move-to``, ``signal-task $abort 3f2a1b0c``."""
    command = body.get("command")
    if not isinstance(command, str):
        return ""
    task = body.get("task")
    name = task.get("name") if isinstance(task, dict) else None
    signal = body.get("signal")
    uuid_ = body.get("task-uuid")
    words = [command, name if isinstance(name, str) else "",
             signal if isinstance(signal, str) else "",
             uuid_[:8] if isinstance(uuid_, str) and command != "start-task" else ""]
    return " ".join(w for w in words if w)


class Commander(Sender):
    """Sends spec-12 commands to one unit and waits, with deadlines, for responses and feedback.

    ``publish(topic, payload)`` does the MQTT publish; ``gaps()`` returns how many connection
    gaps the client has lived through (a command sent across a gap is resent with the same
    com-uuid, as 2 and 12.1 prescribe for unreliable links).
    """

    responses = "exec/response"

    def __init__(self, unit: UnitAddress, traffic: Traffic,
                 publish: Callable[[str, bytes], None], *, dry_run: bool = False,
                 say: Callable[[str], None] = print, gaps: Callable[[], int] = lambda: 0,
                 wait_connected: Callable[[float], bool] = lambda timeout: True,
                 deviations: Deviations | None = None,
                 step: Callable[[str], None] | None = None,
                 task_state: Callable[[str], State | None] | None = None,
                 away: Callable[[], object] = lambda: None) -> None:
        super().__init__(unit, unit.topic("exec/command"), traffic, publish, dry_run=dry_run,
                         say=say, wait_connected=wait_connected, gaps=gaps, away=away)
        self._step = step
        self.task_state = task_state
        """The state the Monitor's model holds of a task-uuid (``protocol.Model``), None where
        it holds nothing; without it (no Monitor) a task's end is read from its feedback."""
        self.open_tasks: dict[str, OpenTask] = {}
        self._closed: set[object] = set()
        """task-uuids that need no $abort any more (refused, or their $abort was answered)."""
        self._start_commands: dict[str, Sent] = {}
        """com-uuid -> start-task sent: the unit's answers name the task-uuids it generated."""
        self.deviations = deviations if deviations is not None else Deviations()
        self._unit_uuid: dict[str, str] = {}
        """task-uuid sent -> the task-uuid the unit runs the task under, when it differs."""
        self._answered_kinds: set[str] = set()
        """Commands (start-task, ...) the unit has answered at least once."""
        self._none_answered: str | None = None
        """Why the unit answers no command ("" when it answers some), once probed."""
        self.deliberately_invalid: set[bytes] = set()
        """Payloads sent broken on purpose (robustness, invalid parameters): not the unit's
        fault, so the passive checks are not fed these."""
        self.silent_starts = False
        """A start-task answered 'running' got no feedback within the wait: the unit reports
        status changes only (12.4 asks for no feedback on a start its answer said runs)."""

    # --- publishing ----------------------------------------------------------------------
    def send(self, body: dict[str, Any], *, com_uuid: str | None = None,
             invalid: bool = False) -> Sent:
        """Publish a command; ``com-uuid`` and ``sender`` are filled in when missing."""
        payload, body = self.compose(body, com_uuid)
        return self._send_payload(payload, body, invalid=invalid)

    def send_raw(self, payload: bytes, *, com_uuid: str = "") -> Sent:
        """Publish a payload as is (robustness: malformed JSON, arrays, non-UTF-8)."""
        return self._send_payload(payload, {}, invalid=True, com_uuid=com_uuid)

    def resend(self, sent: Sent) -> Sent:
        """Publish the very same command again (12.1: resend with the same com-uuid)."""
        return self._send_payload(sent.payload, sent.body,
                                  invalid=sent.payload in self.deliberately_invalid)

    def _send_payload(self, payload: bytes, body: dict[str, Any], *, invalid: bool,
                      com_uuid: str = "") -> Sent:
        if invalid:
            self.deliberately_invalid.add(payload)
        sent = self.publish_command(payload, body, com_uuid=com_uuid)
        if self._step is not None:
            self._step(f"sent {_describe(body) or 'a malformed command'} "
                       f"(com-uuid {sent.com_uuid[:8]})")
        return sent

    def _remember(self, sent: Sent) -> None:
        self._track(sent, None)

    def _forget(self, sent: Sent) -> None:
        with self._lock:
            self._start_commands.pop(sent.com_uuid, None)
            for task_uuid, task in list(self.open_tasks.items()):
                if sent.com_uuid in task.com_uuids:
                    task.com_uuids.remove(sent.com_uuid)
                    if not task.com_uuids:
                        del self.open_tasks[task_uuid]

    # --- waiting for answers ---------------------------------------------------------------
    def response(self, sent: Sent, timeout: float, *, after: int | None = None) -> Entry | None:
        """The unit's response whose ``response-to`` is the command's com-uuid (12.3)."""
        answer = self.await_response(
            sent, timeout, after=after,
            what=f"the response to {_describe(sent.body) or 'a malformed command'}")
        if self._step is not None:
            self._step(f"  answered {answer.get('response')!r}" if answer is not None else
                       f"  no response within {timeout:.1f} s")
        return answer

    def request(self, body: dict[str, Any], timeout: float, *,
                invalid: bool = False) -> tuple[Sent, Entry | None]:
        """Send and wait for the response; resend once with the same com-uuid when the
        connection dropped meanwhile (2: 'resending commands with the same UUID')."""
        kind = UNANSWERED.get(str(body.get("command"))) if not invalid else None
        if kind is not None and self.deviations.get(kind) is not None and not self._answered(
                str(body.get("command"))):
            timeout *= SHORT  # none of this kind was ever answered: no full deadline again
        sent = self.send(body, invalid=invalid)
        answer = self.response(sent, timeout)
        if answer is None and self._gaps() != sent.gaps_before:
            self.resend(sent)
            answer = self.response(sent, timeout)
        self._track(sent, answer)
        if kind is not None:
            if answer is not None:
                with self._lock:
                    self._answered_kinds.add(str(body.get("command")))
            elif not self._answered(str(body.get("command"))) and \
                    not self.broken_since(sent.gaps_before):
                self.deviations.note(
                    kind, f"the unit answered no {body.get('command')} within "
                    f"{timeout:.1f} s", f"later ones get {SHORT * 100:.0f} % of the response "
                    "deadline")
        return sent, answer

    def _answered(self, command: str) -> bool:
        with self._lock:
            return command in self._answered_kinds

    def _track(self, sent: Sent, answer: Entry | None) -> None:
        """Remember every task this commander may have started, to abort it at the end."""
        if sent.body.get("command") != "start-task":
            return
        with self._lock:
            self._start_commands[sent.com_uuid] = sent
        task = sent.body.get("task")
        name = task.get("name", "") if isinstance(task, dict) else ""
        uuids = {u for u in (sent.body.get("task-uuid"), answer.get("task-uuid") if answer
                             else None) if isinstance(u, str) and u}
        refused = answer is not None and answer.get("response") == "failed"
        self._follow(sent, answer, name, refused)
        with self._lock:
            for task_uuid in uuids:
                if refused:  # never started: nothing to abort
                    self.open_tasks.pop(task_uuid, None)
                    self._closed.add(task_uuid)
                elif task_uuid not in self._closed:
                    known = self.open_tasks.setdefault(
                        task_uuid, OpenTask(task_uuid, name, sent.mark))
                    known.com_uuids.append(sent.com_uuid)

    def _follow(self, sent: Sent, answer: Entry | None, name: str, refused: bool) -> None:
        """12.2.3: the answer carries the task-uuid sent. A unit that runs the task under one
        of its own anyway (EXEC-START-002) is followed under that one from now on."""
        wanted, got = sent.body.get("task-uuid"), answer.get("task-uuid") if answer else None
        if refused or not (isinstance(wanted, str) and isinstance(got, str) and got.strip()) \
                or got == wanted:
            return
        with self._lock:
            self._unit_uuid[wanted] = got
        self.deviations.note(
            Kind.TASK_UUID_IGNORED,
            f"start-task '{name}' sent task-uuid {wanted}, the unit answered {got}",
            "the suite follows the task-uuid the unit uses")

    def unit_task_uuid(self, task_uuid: str) -> str:
        """The task-uuid the unit uses for the task started as ``task_uuid``."""
        with self._lock:
            return self._unit_uuid.get(task_uuid, task_uuid)

    def track_response(self, sent: Sent, answer: Entry | None) -> None:
        """Track a task started by a command sent with ``send`` (not ``request``)."""
        self._track(sent, answer)

    def feedback(self, task_uuid: str, statuses: Collection[str] | None, timeout: float, *,
                 after: int, what: str = "") -> Entry | None:
        """The first feedback for ``task_uuid`` after ``after`` whose status means one of
        ``statuses`` (any status when None), waiting up to ``timeout`` seconds.

        Adapts to the unit's systematic deviations (``deviation``): a status outside 12.4's
        list that plainly means a wanted one (``done`` for finished) matches, and is noted;
        feedback without a task-uuid ends the wait at once (None: ``blind`` says why)."""
        uuid_ = self.unit_task_uuid(task_uuid)
        blind: list[Entry] = []

        def match(e: Entry) -> bool:
            found = e.get("task-uuid")
            if found in (None, ""):
                blind.append(e)
                return True
            if found != uuid_:
                return False
            status = e.get("status")
            if statuses is None:
                return True
            means = meaning(status)
            if means in statuses and means != status:
                self.deviations.note(
                    Kind.STATUS_VOCABULARY,
                    f"the unit sends feedback status {status!r} (not in 12.4's list) for "
                    f"{means!r}", f"the suite takes {status!r} as {means!r}")
            return means in statuses

        wanted = ("the feedback" if statuses is None else "the final feedback"
                  if set(statuses) == FINAL_STATUSES else
                  "the '" + "' or '".join(sorted(statuses)) + "' feedback")
        found = self.traffic.wait_for(
            match, timeout, after=after, subtopic="exec/feedback",
            what=what or f"{wanted} of {self.task_name(task_uuid)} {uuid_[:8]}")
        if found is not None and blind and found is blind[-1]:
            self.deviations.note(
                Kind.FEEDBACK_WITHOUT_TASK_UUID,
                f"the unit sends feedback without a task-uuid ({found.excerpt[:120]!r})",
                "feedback cannot be told apart by task: what it would show is could-not-test")
            return None
        return found

    def first_feedback(self, task_uuid: str, timeout: float, *, after: int) -> Entry | None:
        """A started task's first feedback (12.4), waited for up to ``timeout`` seconds: once
        a start answered 'running' came without one (``silent_starts``), later starts are not
        waited for (None at once: the answer's 'running' is the task's status)."""
        if self.silent_starts:
            return None
        found = self.feedback(task_uuid, None, timeout, after=after)
        if found is None and not self.blind() and not self.silent_starts:
            self.silent_starts = True
            if self._step is not None:
                self._step(f"  no feedback for task {task_uuid[:8]} after its 'running' "
                           "answer: later starts are not waited for")
        return found

    def blind(self) -> str | None:
        """Why feedback for a task cannot be found: the unit sends it without task-uuid."""
        return self.deviations.reason(Kind.FEEDBACK_WITHOUT_TASK_UUID)

    def task_name(self, task_uuid: str) -> str:
        """The name of the task the suite started as ``task_uuid`` ("task" when unknown)."""
        with self._lock:
            task = self.open_tasks.get(task_uuid) or self.open_tasks.get(
                self._unit_uuid.get(task_uuid, ""))
        return task.name if task and task.name else "task"

    def statuses(self, task_uuid: str, after: int) -> list[str]:
        """Every feedback status seen for ``task_uuid`` after ``after``, in order."""
        uuid_ = self.unit_task_uuid(task_uuid)
        return [str(e.get("status")) for e in self.traffic.since(after, "exec/feedback")
                if e.get("task-uuid") == uuid_]

    def is_final(self, task_uuid: str) -> bool:
        """Whether the task has ended (12.4: a final status): as the model holds it, else
        from its feedback since it was started."""
        held = self.task_state(self.unit_task_uuid(task_uuid)) if self.task_state else None
        if held is not None:
            return held.ended
        task = self.open_tasks.get(task_uuid)
        mark = task.mark if task else 0
        return any(meaning(s) in FINAL_STATUSES for s in self.statuses(task_uuid, mark))

    # --- whether the unit answers commands at all ------------------------------------------
    def answers_none(self, timeout: float) -> str:
        """Why the unit counts as answering no command at all, or "" when it answers some.

        One kind of command unanswered never implies the others are (a unit may ignore ping
        and run tasks): after an unanswered ping, one harmless command of each other kind
        (start-task of a task no unit offers, signal-task and query-status for a task-uuid
        it never saw; 12.1 asks each to be answered) is sent at once and awaited
        ``timeout`` seconds. The answer is kept: asked again, it is not probed again."""
        if self._none_answered is not None:
            return self._none_answered
        ghost = new_uuid()
        probes = [self.send({"command": "start-task", "execution-unit": self.unit.name,
                             "task": {"name": NO_SUCH_TASK, "params": {}},
                             "task-uuid": ghost}),
                  self.send({"command": "signal-task", "signal": "$abort",
                             "task-uuid": new_uuid()}),
                  self.send({"command": "query-status", "task-uuid": new_uuid()})]
        clock = self.traffic.clock
        end = clock.monotonic() + timeout
        answered = False
        lost = False  # a probe lived through an outage, or the unit was not back: no verdict
        for sent in probes:
            answer = self.response(sent, max(0.0, end - clock.monotonic()))
            command = str(sent.body.get("command"))
            if sent.body.get("command") == "start-task":
                with self._lock:  # no unit offers it: nothing to abort, answered or not
                    self._closed.add(ghost)
                    self.open_tasks.pop(ghost, None)
            if answer is not None:
                answered = True
                with self._lock:
                    self._answered_kinds.add(command)
            elif self.broken_since(sent.gaps_before):
                lost = True
            else:
                self.deviations.note(
                    UNANSWERED[command], f"the unit answered no {command} within "
                    f"{timeout:.1f} s", f"later ones get {SHORT * 100:.0f} % of the response "
                    "deadline")
        if lost and not answered:
            return ""  # asked again later, once the broker delivers
        self._none_answered = "" if answered else (
            f"the unit answers no command: ping, start-task, signal-task and query-status got "
            f"no response within {timeout:.1f} s (EXEC-PING-001)")
        return self._none_answered

    # --- the four commands of 12.1 ---------------------------------------------------------
    def ping(self, timeout: float) -> tuple[Sent, Entry | None]:
        return self.request({"command": "ping"}, timeout)

    def start_task(self, name: str, params: dict[str, Any], timeout: float, *,
                   task_uuid: str | None = "new", invalid: bool = False
                   ) -> tuple[Sent, Entry | None]:
        """start-task (10, 12.2.3). ``task_uuid=None`` leaves it out: the unit generates one."""
        body: dict[str, Any] = {"command": "start-task", "execution-unit": self.unit.name,
                                "task": {"name": name, "params": params}}
        if task_uuid is not None:
            body["task-uuid"] = new_uuid() if task_uuid == "new" else task_uuid
        return self.request(body, timeout, invalid=invalid)

    def signal(self, task_uuid: str, signal: str, timeout: float) -> tuple[Sent, Entry | None]:
        return self.request({"command": "signal-task", "signal": signal,
                             "task-uuid": self.unit_task_uuid(task_uuid)}, timeout)

    def query(self, task_uuid: str, timeout: float) -> tuple[Sent, Entry | None]:
        return self.request({"command": "query-status",
                             "task-uuid": self.unit_task_uuid(task_uuid)}, timeout)

    # --- safety ----------------------------------------------------------------------------
    def abort_all(self, timeout: float, *, stuck: bool = True) -> list[str]:
        """Send ``$abort`` to every task this commander started that has not ended
        (docs/ARCHITECTURE.md 'Safety'); wait up to ``timeout`` seconds in all for the answers (a
        fifth of it when the unit has answered no signal-task so far). Returns the task-uuids
        aborted.

        ``stuck=False`` (between scenarios) leaves out the tasks whose $abort went unanswered
        before: sending it again in every scenario proves nothing and costs a deadline each
        time; the run's last teardown (``stuck=True``) tries them once more."""
        if self.dry_run:
            return []
        # Tasks whose uuid the unit generated and whose answer came after the scenario stopped
        # looking (a Ctrl-C, a timeout): their answers are in the traffic.
        with self._lock:
            starts = dict(self._start_commands)
        for e in self.traffic.since(0, "exec/response"):
            start = starts.get(e.get("response-to"))
            if start is not None and isinstance(e.get("task-uuid"), str):
                self._track(start, e)
        with self._lock:
            tasks = list(self.open_tasks.values())
        ended = [t for t in tasks if self.is_final(t.task_uuid)]
        pending = [t for t in tasks if t not in ended and (stuck or not t.stuck)]
        with self._lock:
            for task in ended:
                self._closed.add(task.task_uuid)
                self.open_tasks.pop(task.task_uuid, None)
        if pending and self.deviations.get(Kind.SIGNAL_UNANSWERED) is not None \
                and not self._answered("signal-task"):
            timeout *= SHORT
        sent: list[tuple[OpenTask, Sent]] = []
        for task in pending:
            try:
                sent.append((task, self.send({"command": "signal-task", "signal": "$abort",
                                              "task-uuid": task.task_uuid})))
            except Exception as e:  # keep aborting the others; say which one failed
                self._say(f"could not abort task {task.task_uuid} ({task.name}): {e}")
        aborted = []
        for task, s in sent:
            # Answered (ok: it ends; failed: it was not running): done. Unanswered: it stays
            # open, and the next abort_all (at the latest at the session's end) tries again.
            if self.response(s, timeout / max(1, len(sent))) is not None:
                aborted.append(task.task_uuid)
                with self._lock:
                    self._closed.add(task.task_uuid)
                    self.open_tasks.pop(task.task_uuid, None)
            else:
                task.stuck = True
        return aborted

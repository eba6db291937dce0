"""The command executor of the reference unit: it answers what arrives on ``exec/command``
(12.1: ping, start-task, signal-task, query-status) on ``exec/response`` (12.3), and answers a
resent command again instead of running it twice.

The tasks it starts run on the unit's ``TaskRunner`` (``conformance.sim.runner``). Hostile
input never raises: what cannot be read (``conformance.sim.command_reading``) is refused when
its com-uuid can be read (EXEC-ROBUST-002), else dropped.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from conformance.sim.command_reading import (
    EXAMPLE_FIELDS,
    decode,
    readable_com_uuid,
    unlike_examples,
)
from conformance.sim.memory import Resends
from conformance.sim.tasks import BUILTIN_SIGNALS, SKIP_WAYPOINT, Task, plan
from conformance.sim.tst import misdirected
from conformance.sim.variants import PREPARING_SECONDS

if TYPE_CHECKING:
    from conformance.sim.unit import UnitCore

COMMANDS = ("ping", "start-task", "signal-task", "query-status")  # 12.1
LATE_PONG_PERIODS = 3.0
"""Fault pong-late: a pong is held back 3 periods (1.5 s at the fault matrix's 2 Hz, past its
1 s response timeout; 3 s at the workout's 1 Hz, past its 2 s), so it arrives before the
suite's reboot kills the process that held it."""
QUERY_WORDS_12_1 = {"finished": "success", "paused": "running", "aborted": "failed"}
"""Variant success-vocabulary: query-status answered in 12.1's words only (running, failed,
success, unknown), 12.4's paused and aborted read as the nearest of them."""


class CommandExecutor:
    """Answers the ``exec/command`` messages of one ``UnitCore``."""

    def __init__(self, unit: UnitCore) -> None:
        self.unit = unit
        self.faults = unit.faults
        self.variants = unit.variants
        self.runner = unit.runner
        self.subscribed = "late-subscriber" not in self.variants
        """Variant late-subscriber: False until the first command, which is lost."""
        self.history: Resends[dict[str, Any] | None] = Resends()
        """com-uuid -> the response sent (None: deliberately not answered), for resends."""
        self.went_on: set[str] = set()
        """Fault abort-running-goes-on: the task-uuids whose $abort it accepted and ignored."""
        self.delayed: list[tuple[float, dict[str, Any]]] = []
        """Fault pong-late: (when, response) of answers held back."""
        self.deferred: list[tuple[dict[str, Any], str | None, float]] | None = None
        """Variant feedback-first: the responses of the command being handled, sent after
        the feedback it causes."""

    def command(self, payload: bytes, now: float, size: int) -> None:
        """Handle one command of ``size`` bytes (``payload`` may be only its head)."""
        if not self.subscribed:
            self.subscribed = True
            return
        msg, problem = decode(payload, size)
        if problem is not None:
            self._malformed(payload, msg, problem)
            return
        assert isinstance(msg, dict)
        com = msg["com-uuid"]
        if com in self.history and not self._forgets_ended(com) and self._resent(com, msg):
            return
        command = msg.get("command")
        if "strict" in self.variants and command in EXAMPLE_FIELDS:
            reason = unlike_examples(command, msg, self.unit.address.name)
            if reason is not None:
                sent = msg.get("task-uuid")
                self._answer(com, "failed", fail_reason=reason, task_uuid=sent if isinstance(
                    sent, str) and 0 < len(sent) <= 128 else None)
                return
        self._dispatch(com, command, msg, now)

    def _malformed(self, payload: bytes, msg: Any, problem: str) -> None:
        """A command that cannot be read: refused where its com-uuid can be (12.1), unless a
        fault crashes on it or leaves it unanswered."""
        readable = readable_com_uuid(payload, msg)
        if "crash-on-malformed" in self.faults:
            self.unit.crashed = True
            return
        if readable is not None and "malformed-unanswered" not in self.faults:
            self._answer(readable, "failed", fail_reason=problem)

    def _resent(self, com: str, msg: dict[str, Any]) -> bool:
        """A command whose com-uuid was seen before (12.1: a resend): answered again, not run
        twice; False where a fault runs it again."""
        if ("resend-answered-failed" in self.faults or "resend-refused" in self.variants) \
                and msg.get("command") == "start-task":
            self._refuse_resend(com, msg)
            return True
        if "resend-executes-twice" in self.faults or (
                "resend-signal-reapplied" in self.faults and msg.get("command") == "signal-task"):
            return False
        cached = self.history.resent(com)
        if cached is not None and "resend-unanswered" not in self.faults:
            self._send_response(dict(cached))
        return True

    def _dispatch(self, com: str, command: Any, msg: dict[str, Any], now: float) -> None:
        """One of 12.1's commands run; any other refused."""
        if command == "ping":
            self._answer(com, "pong", kind="ping")
        elif command in ("start-task", "signal-task"):
            if "feedback-first" in self.variants:
                self.deferred = []
            try:
                if command == "start-task":
                    self._start_task(com, msg, now)
                else:
                    self._signal_task(com, msg, now)
            finally:
                deferred, self.deferred = self.deferred or [], None
                for args in deferred:
                    self._send_response(*args)
        elif command == "query-status":
            self._query_status(com, msg)
        elif not isinstance(command, str):
            self._answer(com, "failed", fail_reason="the command has no 'command' field (one of "
                         f"{', '.join(COMMANDS)})")
        elif "silent-unknown-command" not in self.variants:  # 12.1 asks nothing of others
            self._answer(com, "failed", fail_reason=f"unknown command {command[:64]!r}: this "
                         f"unit understands {', '.join(COMMANDS)} (12.1)" + misdirected(command))

    def send_delayed(self, now: float) -> float | None:
        """Send the held-back answers that are due; when the next one is (None: none left)."""
        while self.delayed and self.delayed[0][0] <= now:
            self.unit.send("exec/response", self.delayed.pop(0)[1])
        return self.delayed[0][0] if self.delayed else None

    # --- responses --------------------------------------------------------------------------------
    def _answer(self, com: str, response: str, *, task_uuid: str | None = None,
                fail_reason: str | None = None, kind: str = "") -> None:
        """Send a response (12.3) and remember it for a resend."""
        body: dict[str, Any] = {"agent-uuid": self.unit.agent_uuid, "response": response,
                                "response-to": com}
        if "terse" in self.variants:  # 12.3: fail-reason when failed; task-uuid for start-task
            fail_reason = fail_reason if response == "failed" else None
            task_uuid = task_uuid if kind == "start" else None
        elif "verbose" in self.variants:  # both on every response, as 12.3.3's example has
            fail_reason = "" if fail_reason is None else fail_reason
            task_uuid = "" if task_uuid is None else task_uuid  # '': it concerns no task
        if task_uuid is not None:
            body["task-uuid"] = task_uuid
        if fail_reason is not None:
            body["fail-reason"] = "" if "fail-reason-empty" in self.faults else fail_reason
        if kind == "ping":
            if "pong-missing" in self.faults:
                return
            if "pong-late" in self.faults:
                self.history.remember(com, body)
                self._send_response(dict(body), command_com=com,
                                    delay=LATE_PONG_PERIODS * self.unit.period)
                return
            if "pong-response-to-uppercase" in self.faults:
                body["response-to"] = com.upper()
        if kind == "signal" and "signal-response-tst-form" in self.faults:
            body = {"response": "ok" if response == "ok" else response, "response-to": com}
            if response == "failed":
                body["fail-reason"] = fail_reason or ""
        silent = kind == "signal" and "signal-unanswered" in self.faults
        self.history.remember(com, None if silent else body)
        if not silent:
            self._send_response(dict(body), command_com=com)

    def _send_response(self, body: dict[str, Any], command_com: str | None = None,
                       delay: float = 0.0) -> None:
        if self.deferred is not None:
            self.deferred.append((body, command_com, delay))
            return
        unit = self.unit
        com = body.get("response-to", "") if command_com is None else command_com
        body["com-uuid"] = com if "response-reuses-com-uuid" in self.faults else unit.fresh_uuid()
        if "agent-uuid" in body:
            if "response-no-agent-uuid" in self.faults:
                del body["agent-uuid"]
            elif "response-stale-agent-uuid" in self.faults:
                body["agent-uuid"] = unit.executor_uuid
            else:
                body["agent-uuid"] = unit.agent_uuid
        if delay:  # in the runtime's monotonic clock, from the last step
            self.delayed.append((self.runner.now + delay, body))
            return
        unit.send("exec/response", body)
        if "response-twice" in self.faults:  # a retry loop that does not wait for the PUBACK
            unit.send("exec/response", body)

    def _refuse_resend(self, com: str, msg: dict[str, Any]) -> None:
        """Variant resend-refused and fault resend-answered-failed (both seen in the field):
        the resent start-task is taken for a new one and answered 'failed'; with the fault the
        running task gets a 'failed' feedback too, although it runs on."""
        cached = self.history.get(com)
        task_uuid = cached.get("task-uuid") if cached else msg.get("task-uuid")
        task = self.runner.tasks.get(task_uuid) if isinstance(task_uuid, str) else None
        reason = ("A task is already running" if "resend-refused" in self.variants else
                  f"task-uuid {task_uuid} is already used by another task")
        body: dict[str, Any] = {"agent-uuid": self.unit.agent_uuid, "response": "failed",
                                "response-to": com, "task-uuid": task_uuid,
                                "fail-reason": reason}
        self._send_response(body, command_com=com)
        if task is not None and not task.ended and "resend-answered-failed" in self.faults:
            self.runner.feedback(task, "failed")

    def _forgets_ended(self, com: str) -> bool:
        """Fault resend-after-end-runs-again: a start-task whose task has ended is forgotten,
        task and com-uuid, so its resend runs it again."""
        if "resend-after-end-runs-again" not in self.faults:
            return False
        cached = self.history.get(com)
        task_uuid = cached.get("task-uuid") if cached else None
        task = self.runner.tasks.get(task_uuid) if isinstance(task_uuid, str) else None
        if task is None or not task.ended or task.com_uuid != com:
            return False
        del self.runner.tasks[task.uuid]
        return True

    # --- start-task -----------------------------------------------------------------------------
    def _start_task(self, com: str, msg: dict[str, Any], now: float) -> None:
        unit, tasks = self.unit, self.runner.tasks
        task_field = msg.get("task")
        sent_uuid = msg.get("task-uuid")
        if sent_uuid is not None and (not isinstance(sent_uuid, str) or not sent_uuid
                                      or len(sent_uuid) > 128):
            self._answer(com, "failed", fail_reason="task-uuid must be a UUID string",
                         task_uuid=None)
            return
        if sent_uuid is None and "dies-on-missing-task-uuid" in self.faults:
            unit.dead = True  # msg["task-uuid"] raised a KeyError in the MQTT thread
            return
        task_uuid = sent_uuid if sent_uuid is not None else unit.task_uuid()
        if sent_uuid is not None and "task-uuid-ignored" in self.faults:
            task_uuid = unit.task_uuid()
        if not isinstance(task_field, dict) and "malformed-unanswered" in self.faults:
            return  # nothing to start: malformed, and dropped as the others are
        if not isinstance(task_field, dict) or not isinstance(task_field.get("name"), str):
            self._answer(com, "failed", task_uuid=task_uuid, fail_reason="start-task needs "
                         "'task': {'name': ..., 'params': {...}} (12.2.3, section 10)")
            return
        if sent_uuid is None and "start-no-task-uuid-unanswered" in self.faults:
            return  # msg["task-uuid"]: a KeyError the MQTT library catches; the command is lost
        if (task_uuid in tasks and "resend-executes-twice" in self.faults
                and tasks[task_uuid].com_uuid == com):
            del tasks[task_uuid]  # the resend starts the same task again from scratch
        if task_uuid in tasks:
            self._answer(com, "failed", task_uuid=task_uuid, fail_reason=f"task-uuid "
                         f"{task_uuid} is already used by another task")
            return
        name = task_field["name"]
        params = task_field.get("params", {})
        spec = unit.specs.get(name)
        problems = self._refused(com, task_uuid, name, params)
        if problems is None:
            return
        task = Task(task_uuid, name, params if isinstance(params, dict) else {}, spec, com,
                    leg_started=now)
        if problems:
            task.fail_at = now + 0.5  # fault accept-invalid-params: it fails once it runs
        else:
            plan(task, unit.vehicle, unit.task_seconds)
        if task.spec is not None:
            self.runner.preempt(task, f"pre-empted by task {task_uuid}")
        self.runner.remember(task)
        self._answer_started(task, com, sent_uuid, now)

    def _refused(self, com: str, task_uuid: str, name: str, params: Any) -> list[str] | None:
        """None when the task is refused (answered 'failed': not available, or its parameters
        invalid, 12.2.3), else the problems of its parameters that a fault lets through."""
        spec = self.unit.specs.get(name)
        if spec is None:
            if "accept-unknown-task" not in self.faults:
                known = ", ".join(self.unit.specs)
                reason = (f"task {name[:64]!r} is not available on this "
                          f"{self.unit.address.agent_type} unit; tasks-available: {known}")
                self._fail_task(com, task_uuid, name, reason)
                return None
            return []
        problems = spec.problems(params)
        if problems and "dies-on-invalid-params" in self.faults:
            self.unit.dead = True  # reading the parameters raised in the MQTT thread
            return None
        if problems and "accept-invalid-params" not in self.faults:
            self._fail_task(com, task_uuid, name,
                            f"invalid parameters for {name}: " + "; ".join(problems))
            return None
        return problems

    def _answer_started(self, task: Task, com: str, sent_uuid: Any, now: float) -> None:
        """Answer a start-task that starts its task ('running', 12.2.3), and run it: its first
        feedback, then its schedule."""
        task_uuid = task.uuid
        response = "started" if "start-answered-started" in self.faults else "running"
        shown = None if (sent_uuid is not None and "start-response-no-task-uuid" in self.faults
                         or sent_uuid is None and "start-no-generated-task-uuid" in self.faults
                         ) else task_uuid
        if "start-response-unpublished" in self.faults:
            self.history.remember(com, None)  # built into a response that is never published
        else:
            self._answer(com, response, task_uuid=shown, fail_reason="", kind="start")
        if "feedback-status-typo" in self.faults:
            self.runner.feedback(task, "Starting")
        elif "starting-feedback" in self.variants:
            self.runner.feedback(task, "starting")  # 12.4's word for a task getting ready
        if "preparing-status" in self.variants:  # 12.4: a task specific string, for a while
            self.runner.feedback(task, "preparing")
            task.prepared_at = now + PREPARING_SECONDS
        elif "silent-start" not in self.variants:  # its answer already said 'running'
            self.runner.feedback(task, "running")
        self.runner.start(task, now)

    def _fail_task(self, com: str, task_uuid: str, name: str, reason: str) -> None:
        task = Task(task_uuid, str(name)[:128], {}, None, com, status="failed",
                    fail_reason=reason)
        self.runner.remember(task)
        self._answer(com, "failed", task_uuid=task_uuid, fail_reason=reason, kind="start")

    # --- signal-task ----------------------------------------------------------------------------
    def _signal_task(self, com: str, msg: dict[str, Any], now: float) -> None:
        runner = self.runner
        task_uuid, signal = msg.get("task-uuid"), msg.get("signal")
        shown = task_uuid if isinstance(task_uuid, str) and len(task_uuid) <= 128 else None

        def refuse(reason: str) -> None:
            self._answer(com, "failed", task_uuid=shown, fail_reason=reason, kind="signal")

        if not isinstance(task_uuid, str) or not isinstance(signal, str):
            refuse("signal-task needs a task-uuid and a signal (strings, 12.2.2)")
            return
        task = runner.tasks.get(task_uuid)
        if task is None:
            if "signal-unknown-task-ok" in self.faults:
                self._answer(com, "ok", task_uuid=shown, fail_reason="", kind="signal")
            else:
                refuse(f"no task with task-uuid {task_uuid[:64]} is known")
            return
        if task.ended:
            refuse(f"task {task_uuid} has already ended ({task.status})")
            return
        signals = task.spec.signals if task.spec else BUILTIN_SIGNALS
        if "signal-nonstandard" in self.faults and signal == "$resume":
            signal = "$continue"
        if signal not in signals:
            refuse(f"task {task.name} does not understand {signal[:64]!r}; it understands "
                   f"{', '.join(signals)}")
            return
        self._answer(com, self._accepts(signal), task_uuid=task_uuid, fail_reason="",
                     kind="signal")
        runner.step(now)
        paused = task.status == "paused"
        if paused and signal == "$abort" and "abort-paused-resumes" in self.faults:
            runner.resume(task, now)  # continue() before cancel(): it runs again, then ends
        self._signal_effect(task, signal, paused, now)
        if task.status == "running":
            runner.advance(task, now)

    def _signal_effect(self, task: Task, signal: str, paused: bool, now: float) -> None:
        """What an accepted signal does to ``task`` (12.2.2; the faults' ways of getting it
        wrong)."""
        runner = self.runner
        if signal == "$abort":
            self._abort(task, paused)
        elif signal == "$enough":
            runner.end(task, "aborted" if "enough-aborts" in self.faults else "finished",
                       "ended by $enough")
        elif signal == "$pause":
            if "pause-ignored" not in self.faults:
                runner.pause(task, now)
            if "pause-pauses-all" in self.faults:  # the controller all tasks share pauses
                for other in list(runner.tasks.values()):
                    if other is not task and other.node is None:
                        runner.pause(other, now)
        elif signal == "$continue":
            runner.resume(task, now)
        elif signal == SKIP_WAYPOINT:
            if task.leg < len(task.legs):
                runner.vehicle.stop()
                task.leg += 1
                task.leg_started = now
                if task.leg < len(task.legs) and task.status == "running":
                    runner.start_leg(task)

    def _abort(self, task: Task, paused: bool) -> None:
        """$abort accepted: the task ends 'aborted' (faults: it goes on)."""
        if "abort-running-goes-on" in self.faults:
            self.went_on.add(task.uuid)
        elif "abort-ignored" not in self.faults:
            self.runner.end(task, "aborted", "aborted by $abort")
            if paused and "feedback-after-abort-paused" in self.faults:
                self.runner.feedback(task, "paused")  # its pause timer fires after the end
            if "abort-aborts-all" in self.faults:  # the cancel goes to the shared controller
                for other in list(self.runner.tasks.values()):
                    if other is not task and not other.ended and other.node is None:
                        self.runner.end(other, "aborted", "aborted by $abort of another")

    def _accepts(self, signal: str) -> str:
        """The word a signal is accepted with: 'ok', or 12.1's 'running' (variant
        signal-running; fault abort-running-goes-on for $abort)."""
        if "signal-running" in self.variants or (
                signal == "$abort" and "abort-running-goes-on" in self.faults):
            return "running"
        return "ok"

    # --- query-status ---------------------------------------------------------------------------
    def _query_status(self, com: str, msg: dict[str, Any]) -> None:
        if "query-unanswered" in self.faults:
            return  # never answered (every agent seen in the field)
        task_uuid = msg.get("task-uuid")
        if not isinstance(task_uuid, str) or not task_uuid or len(task_uuid) > 128:
            self._answer(com, "failed", fail_reason="query-status needs the task-uuid of the "
                         "task to query (12.1)", kind="query")
            return
        task = self.runner.tasks.get(task_uuid)
        if task is not None and task.ended and "query-forgets-finished" in self.faults:
            task = None
        if task is not None and task.status == "paused" and "query-paused-unknown" in self.faults:
            task = None  # it looks among running and ended tasks only
        if task is None:
            if "query-unknown-failed" in self.faults:
                self._answer(com, "failed", task_uuid=task_uuid, fail_reason="no such task",
                             kind="query")
            else:  # 12.1: 'unknown' for a task this life has never seen
                self._answer(com, "unknown", task_uuid=task_uuid, fail_reason="", kind="query")
            return
        status = task.status
        if status == "paused" and "query-paused-finished" in self.faults:
            status = "finished"  # not running any more: counted as done
        if "success-vocabulary" in self.variants:  # 12.1's list: running, failed, success
            status = QUERY_WORDS_12_1.get(status, status)
        if status == "finished" and "query-answers-success" in self.faults:
            status = "success"
        reason = task.fail_reason if status == "failed" else ""
        self._answer(com, status, task_uuid=task_uuid, fail_reason=reason, kind="query")

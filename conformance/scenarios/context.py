"""What every active scenario works with: the unit, its traffic, the commander, deadlines.

Deadlines come from the profile and the unit's declared rates, times ``--timing-scale`` for slow
links (docs/ARCHITECTURE.md 'Waits'). Scenarios report what they saw with ``record``, as evidence
for the judge (``Monitor.record``): a violation, or ``seen`` (``violation.Observed``: examined;
not applicable or untestable, with the reason). They make no verdict.
"""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from conformance.checks.base import geopoint
from conformance.profile import Profile
from conformance.scenarios.commander import Commander
from conformance.scenarios.deviation import FINAL_STATUSES, Deviation, Kind, meaning
from conformance.scenarios.safety import Position, Safety
from conformance.scenarios.traffic import LAG_SLACK, Entry, Traffic
from conformance.scenarios.tst_commander import TstCommander
from conformance.topics import UnitAddress
from conformance.violation import Observed, Violation

# 9: tasks that run until they get $enough (look-at-*, observe-position, detection): the best
# subjects for signals and queries, because they do not end on their own mid-test.
RUNS_UNTIL_ENOUGH = ("look-at-bearing", "look-at-position", "look-at-positions",
                     "image-object-detection", "observe-position")


class Recorder(Protocol):
    def __call__(self, rule: str, *, violation: Violation | None = None,
                 seen: Observed | None = None, reason: str = "",
                 missing: bool = True) -> None: ...


@dataclass(frozen=True)
class Timing:
    """Deadlines in seconds: the profile's, times ``scale`` (--timing-scale)."""

    profile: Profile
    scale: float = 1.0

    @property
    def response(self) -> float:
        return self.profile.response_timeout * self.scale

    @property
    def feedback(self) -> float:
        return self.profile.feedback_timeout * self.scale

    def feedback_for(self, task: str) -> float:
        """The feedback deadline of ``task``: its own in the profile's ``tasks``, else the
        profile's ``feedback_timeout`` (a deadline of ours: 12.4 gives none)."""
        return self.profile.task_feedback_timeouts.get(task, self.profile.feedback_timeout) \
            * self.scale

    def scaled(self) -> Profile:
        """The profile with these deadlines (the Monitor's in a certification)."""
        return dataclasses.replace(
            self.profile, response_timeout=self.response, feedback_timeout=self.feedback,
            task_feedback_timeouts={t: self.feedback_for(t)
                                    for t in self.profile.task_feedback_timeouts})

    def periods(self, count: float, rate_hz: float | None) -> float:
        """``count`` periods of a message declared at ``rate_hz``, plus the response margin."""
        rate = rate_hz if rate_hz and rate_hz > 0 else 1.0
        return (count / rate + self.profile.response_timeout) * self.scale

    @property
    def reboot(self) -> float:
        return self.profile.reboot_timeout * self.scale


@dataclass
class Context:
    """One certification run's view of the unit under test, shared by the scenarios."""

    unit: UnitAddress
    profile: Profile
    traffic: Traffic
    commander: Commander
    safety: Safety
    timing: Timing
    seed: int
    record: Recorder
    reboot: Callable[[], str | None] | None = None
    """Reboots the unit; returns None when done, or what went wrong. None: no way to reboot."""
    reboot_how: str = ""
    notes: dict[str, Any] = field(default_factory=dict)
    """What scenarios leave for later ones (e.g. tasks that ended, for query and reboot)."""
    tst: TstCommander | None = None
    """Sends TST commands (14) to the tst/command topic the run was told; None: no TST."""
    settle: Callable[[], None] = lambda: None
    """Waits until the Monitor has judged what the conversations left open (their deadlines
    passed on a heartbeat of the unit): conversation verdicts are the Monitor's."""

    # --- what the unit says about itself -------------------------------------------------
    def heartbeat(self) -> dict[str, Any]:
        e = self.traffic.latest("heartbeat")
        return e.body if e and isinstance(e.body, dict) else {}

    def execution_info(self) -> dict[str, Any]:
        e = self.traffic.latest("direct_execution_info")
        return e.body if e and isinstance(e.body, dict) else {}

    @property
    def agent_uuid(self) -> str | None:
        value = self.heartbeat().get("agent-uuid")
        return value if isinstance(value, str) else None

    def rate_of(self, subtopic: str) -> float | None:
        e = self.traffic.latest(subtopic)
        rate = e.get("rate") if e else None
        return float(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) \
            and rate > 0 else None

    def levels(self) -> list[str]:
        levels = self.heartbeat().get("levels")
        return [str(x) for x in levels] if isinstance(levels, list) else []

    def tasks_available(self) -> dict[str, list[str]]:
        """Task name -> the signals it understands, as direct_execution_info lists them."""
        out: dict[str, list[str]] = {}
        for task in self.execution_info().get("tasks-available") or []:
            if isinstance(task, dict) and isinstance(task.get("name"), str):
                signals = task.get("signals")
                out[task["name"]] = [s for s in signals if isinstance(s, str)] \
                    if isinstance(signals, list) else []
        return out

    def position(self) -> Position | None:
        """The unit's last reported position (6.1 sensor/position), or None when it has none
        in range."""
        e = self.traffic.latest("sensor/position")
        # Degrees in range, or no position: a position in 1e-7 degrees (SENS-003's fault) is
        # no place to send the unit to (the commands made from it would be the suite's fault).
        point = geopoint(e.body) if e else None
        if point is None:
            return None
        return Position(point[0], point[1], point[2] or 0.0)

    def rng(self, salt: str) -> random.Random:
        """A random generator derived from --seed and a name: the same run, the same values."""
        return random.Random(f"{self.seed}:{salt}")

    # --- waiting on direct_execution_info -----------------------------------------------------
    def info_deadline(self, periods: float = 2.0) -> float:
        """Seconds to wait for ``periods`` direct_execution_info messages."""
        return self.timing.periods(periods, self.rate_of("direct_execution_info"))

    def executing(self, entry: Entry) -> list[str]:
        """The task-uuids a direct_execution_info message lists in tasks-executing; an entry
        that names its task ``uuid`` (seen in the field; DEI-001 judges the key) is followed by
        what it says (docs/FIELD-NOTES.md 'Precision': other keys)."""
        tasks = entry.get("tasks-executing") or []
        uuids = (t.get("task-uuid", t.get("uuid")) for t in tasks if isinstance(t, dict)) \
            if isinstance(tasks, list) else ()
        return [u for u in uuids if isinstance(u, str)]

    def wait_listed(self, task_uuid: str, *, after: int) -> Entry | None:
        """The first direct_execution_info after ``after`` that lists ``task_uuid`` in
        tasks-executing, or the task's final feedback if that comes first (a task that ended
        between two infos cannot be listed); None after two declared periods."""
        task_uuid = self.commander.unit_task_uuid(task_uuid)

        def listed_or_ended(e: Entry) -> bool:
            if e.subtopic == "direct_execution_info":
                return task_uuid in self.executing(e)
            return e.subtopic == "exec/feedback" and e.get("task-uuid") == task_uuid \
                and meaning(e.get("status")) in FINAL_STATUSES
        return self.traffic.wait_for(listed_or_ended, self.info_deadline(), after=after,
                                     what=f"task {task_uuid[:8]} in tasks-executing")

    # --- helpers for scenarios --------------------------------------------------------------
    def violation(self, rule: str, *, expected: str, observed: str, subtopic: str = "exec/response",
                  entry: Entry | None = None, detail: str = "", command: str = ""
                  ) -> Violation:
        """A finding of this scenario; ``command`` the com-uuid a finding of no answer is
        about (a late answer the Monitor sees later takes its place: only late)."""
        lag = self.traffic.command_lag
        if entry is None and lag >= LAG_SLACK:  # nothing came, though waited for longer
            late = (f"the broker delivered the suite's command {lag:.1f} s late: the wait "
                    f"for the answer was lengthened as much")
            detail = f"{detail}; {late}" if detail else late
        # The topic labels the payload shown: the entry's own (an answer shown for missing
        # feedback is a response), else the one where the answer was awaited.
        return Violation.of(rule, expected=expected, observed=observed,
                            topic=self.unit.topic(entry.subtopic if entry else subtopic),
                            time=entry.time if entry else None,
                            payload=entry.excerpt if entry else None, detail=detail,
                            unit=str(self.unit), command=command if entry is None else "")

    def startable(self, scenario: str = "", prefer: tuple[str, ...] = RUNS_UNTIL_ENOUGH
                  ) -> list[str]:
        """Tasks in tasks-available the suite may start in ``scenario``, the ``prefer``red
        ones first, those that do not move the unit before those that do."""
        names = [n for n in self.tasks_available() if self.safety.may_start(n, scenario)[0]]
        return sorted(names, key=lambda n: (n not in prefer, self.safety.moves(n),
                                            prefer.index(n) if n in prefer else 0, n))

    def none_startable(self, scenario: str = "") -> str:
        """Why no task in tasks-available may be started in ``scenario``: each task's reason
        (the missing parameters, motion, the profile), or that none is offered."""
        why = [self.safety.may_start(n, scenario)[1] for n in self.tasks_available()]
        return "no task the suite may start: " + ("; ".join(w for w in why if w)
                                                   or "tasks-available is empty")

    def end_task(self, task_uuid: str, signals: list[str], *, after: int,
                 gaps_before: int | None = None) -> Entry | None:
        """End a running task: ``$enough`` or ``$abort`` when it lists them, then wait for its
        final status (12.4). Returns the final feedback, or None past the deadline, or at once
        when the unit refuses the signal (the task is no longer running)."""
        final = self.commander.feedback(task_uuid, FINAL_STATUSES, 0, after=after)
        if final is not None or self.commander.blind():
            # Still end it (docs/ARCHITECTURE.md 'Safety'), without waiting for feedback.
            if final is None:
                self.commander.signal(task_uuid, "$abort", self.timing.response)
            return final
        # 12.2.2: the built-in signals; $abort when the task does not list $enough.
        signal = "$enough" if "$enough" in signals else "$abort"
        _, answer = self.commander.signal(task_uuid, signal, self.timing.response)
        if answer is not None and answer.get("response") == "failed":
            return self.commander.feedback(task_uuid, FINAL_STATUSES, 0, after=after)
        return self.wait_final(task_uuid, after=after, gaps_before=gaps_before)

    def listing(self, task_uuid: str) -> Entry | None:
        """The latest direct_execution_info, when it lists ``task_uuid`` in tasks-executing."""
        info = self.traffic.latest("direct_execution_info")
        unit_uuid = self.commander.unit_task_uuid(task_uuid)
        return info if info is not None and unit_uuid in self.executing(info) else None

    def wait_ended(self, task_uuid: str, timeout: float, *, after: int,
                   listed: Entry | None) -> tuple[bool, float]:
        """Wait up to ``timeout`` seconds for the task's final feedback (12.4) or its leaving
        tasks-executing (5.3: the unit says it ended) in a direct_execution_info later than
        ``listed`` (one that listed it), or later than one after ``after`` that listed it.
        Whether it ended, and the seconds of ``timeout`` left."""
        unit_uuid = self.commander.unit_task_uuid(task_uuid)
        seen = [listed] if listed is not None else []

        def over(e: Entry) -> bool:
            if e.subtopic == "direct_execution_info":
                if unit_uuid in self.executing(e):
                    seen.append(e)
                    return False
                return bool(seen) and e.seq > seen[0].seq
            return e.subtopic == "exec/feedback" and e.get("task-uuid") in (
                unit_uuid, None, "") and meaning(e.get("status")) in FINAL_STATUSES
        clock = self.traffic.clock
        started = clock.monotonic()
        ended = self.traffic.wait_for(over, timeout, after=after,
                                      what=f"the end of task {unit_uuid[:8]}") is not None
        return ended, max(0.0, timeout - (clock.monotonic() - started))

    def wait_final(self, task_uuid: str, *, after: int, why: str = "",
                   listed: Entry | None = None, gaps_before: int | None = None,
                   timeout: float | None = None) -> Entry | None:
        """The task's final feedback (12.4), waiting ``timeout`` (default: the task's feedback
        deadline, ``Timing.feedback_for``); once a task's final status has failed to come (a
        systematic deviation), only the response deadline. Not noted as the unit's deviation
        when the suite's link was lost since ``gaps_before`` (the task's start-task's
        ``Sent.gaps_before``): it may have come meanwhile, nor while the unit still lists the
        task in tasks-executing (it has not ended: a slow task, not a missing status).

        ``listed``: a direct_execution_info that listed the task (default: the latest, if it
        does). Then a later one that no longer lists it (5.3: the unit says the task ended)
        ends the wait early: its final status gets the response deadline more to arrive, or
        none once the deviation is known (what the unit showed: it ends tasks unsaid)."""
        known = self.commander.deviations.get(Kind.NO_FINAL_FEEDBACK)
        timeout = timeout if timeout is not None else self.timing.feedback_for(
            self.commander.task_name(task_uuid))
        timeout = self.timing.response if known else timeout
        listed = listed if listed is not None else self.listing(task_uuid)
        deadline = timeout
        ended, left = self.wait_ended(task_uuid, timeout, after=after, listed=listed)
        # Ended: its final status gets the response deadline more (none once known); else
        # the whole deadline was waited.
        timeout = min(0.0 if known else self.timing.response, left) if ended else 0.0
        final = self.commander.feedback(task_uuid, FINAL_STATUSES, timeout, after=after)
        lost = gaps_before is not None and self.commander.gaps() != gaps_before
        running = final is None and not ended and self.listing(task_uuid) is not None
        if final is None and not lost and not running and not self.commander.blind():
            self.commander.deviations.note(
                Kind.NO_FINAL_FEEDBACK,
                f"no final status for task {self.commander.unit_task_uuid(task_uuid)}"
                f"{' ' + why if why else ''}"
                + (" after it left tasks-executing" if ended else f" within {deadline:.1f} s"),
                f"later waits for a final status end when the task leaves tasks-executing, "
                f"or after {self.timing.response:.1f} s; what they judge is could-not-test")
        return final

    def final_known(self) -> Deviation | None:
        """The no-final-status deviation, if noted already (take it before a wait)."""
        return self.commander.deviations.get(Kind.NO_FINAL_FEEDBACK)

    def untestable(self, noted: Deviation | None = None) -> str | None:
        """Why a missing feedback is could-not-test rather than the unit's failure (again):
        its feedback carries no task-uuid, or ``noted`` (``final_known()`` taken before the
        wait) says no final status comes, which was held against it once already."""
        blind = self.commander.blind()
        if blind:
            return blind
        if noted is not None:
            return self.commander.deviations.reason(Kind.NO_FINAL_FEEDBACK)
        return None

def describe(entry: Entry | None) -> str:
    """A short text for a person: the body of a message, or that none came."""
    if entry is None:
        return "no message"
    return entry.excerpt[:160].decode("utf-8", "backslashreplace")

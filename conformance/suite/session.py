"""One certification run: the unit under test, the passive Monitor, the active scenarios, and
the reports. Created by the plugin when ``--unit`` is given.

Data flows one way (DESIGN): every message of ``<unit>/#`` goes to the ``Monitor`` (the same
passive checks as the linter) and to ``Traffic`` (which the scenarios wait on); scenarios
record their verdicts into the same Monitor; the Monitor's report is what the tests, the JSON
and HTML reports and the JUnit properties show.

Its parts: the link to the broker ``connection.py`` (and ``probe.py`` when the unit is not
there), how long the unit is watched ``observation.py``, rebooting it ``reboot.py``, the verdicts
and the conclusion come from the one judge (``conformance.judge``), the header ``header.py``.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from conformance import __version__
from conformance.checks import Monitor
from conformance.checks.conversation import answered
from conformance.checks.exec_sequence import state_held
from conformance.client import MqttClient
from conformance.clock import REAL, VirtualClock
from conformance.conclusion import INTERRUPTED, NOT_CERTIFIED, Conclusion
from conformance.conclusion import of as conclusion_of
from conformance.display import LINE_CHARS, shorten, shown
from conformance.facts import CTRL_C, RunFacts, RunKind
from conformance.judge import judge, unexamined
from conformance.protocol import State
from conformance.reporting import write_all
from conformance.reporting.bounds import file_stem
from conformance.reporting.text import RERUN_OF
from conformance.results import RunReport
from conformance.rules import CATALOGUE, Mode
from conformance.scenarios import (
    RULE_SCENARIO,
    Commander,
    Context,
    Safety,
    Timing,
    Traffic,
    TstCommander,
    scenarios_for,
)
from conformance.scenarios.deviation import Deviation, Deviations
from conformance.scenarios.params import task_moves
from conformance.scenarios.traffic import OutOfTime
from conformance.suite.connection import Connection
from conformance.suite.events import Events, clock
from conformance.suite.header import header_lines
from conformance.suite.observation import Observation
from conformance.suite.probe import NotAlive
from conformance.suite.progress import Progress
from conformance.suite.reboot import Reboot
from conformance.suite.scenario_run import run_scenario
from conformance.suite.settings import Settings
from conformance.topics import UnitAddress, level_name
from conformance.violation import Observed, RuleResult, Verdict

if TYPE_CHECKING:
    from conformance.sim.virtual import VirtualClient

CERTIFICATION = pytest.StashKey["Certification"]()


class Certification:
    """The state of one ``pytest --unit`` run (one unit, one broker, one profile)."""

    def __init__(self, config: pytest.Config, settings: Settings) -> None:
        self.config = config
        self.settings = settings
        self.unit: UnitAddress = settings.unit
        self.profile = settings.profile
        self.timing = Timing(self.profile, settings.timing_scale)
        operator = settings.tst_operator
        # --broker virtual (the test suite's matrices): the unit, this suite and the Monitor
        # on one simulated clock (conformance.clock); every other run in real time.
        self.traffic = Traffic(self.unit, tst_operator=operator.base if operator else None,
                               clock=VirtualClock() if settings.virtual else REAL)
        # The Monitor puts what is wrong in the suite's own commands (some broken on purpose:
        # the robustness scenario) on the commander's account, which a certification does not
        # report; it judges the unit's answers with the deadlines the scenarios wait for.
        self.monitor = Monitor(self.timing.scaled(), units=[self.unit],
                               kind=RunKind.CERTIFICATION)
        self._lock = threading.RLock()
        self.events = Events()
        """What happened to the connection and the unit, for the terminal summary."""
        self.connection = Connection(settings, self.monitor, self.traffic, self._lock,
                                     self.events)
        self.reboot = Reboot(config, self.connection, self.timing.reboot,
                             self._reboot_requested, self.events)
        when = time.strftime('%Y%m%dT%H%M%S', time.localtime())
        self.stem = f"{file_stem(self.unit.name)}-{when}"  # a bounded file name
        self.report_paths: dict[str, Path] = {}
        self.report_error = ""
        """Why the last report could not be written ('' when it was)."""
        self.collect_only = False  # --collect-only: nothing is connected, run or written
        self.error = ""
        """Why the run stopped before the tests (broker unreachable, unit not alive)."""
        self.scenarios_done: dict[str, bool] = {}
        """Scenario -> whether it ran (False: its rules could not be tested)."""
        self.revived = 0  # how often the unit was restarted after it died (scenario_run.revive)
        self._passive_ready = False
        self._last_write = 0.0
        self.selected: list[str] = []
        """The rules whose tests were selected to run (after -k, -m, --rule)."""
        self.ran: set[str] = set()
        """The rules whose tests ran (a test that never ran judged nothing)."""
        self.enacted: dict[str, Verdict] = {}
        """The verdict each rule's test showed when it ran (``suite.verdict.enact``)."""
        self._judged_at: tuple[tuple[int, float | None], RunReport] | None = None
        self.out_of_time: str | None = None
        """--max-duration passed: what the run was waiting for then."""
        self.interrupted = False
        self.selection = ""
        """How the rules were selected (``-k 'HB-003'``, ``--rule=HB-003``): a partial run."""
        self.broker_lost: float | None = None
        """When the broker was lost for good (it did not come back within the budget)."""
        self.explored = ""
        """What the exploration did (``suite/exploration.py``), for the report's meta."""
        self.explore_story = ""
        """The story exploration found, as told (the HTML report shows it step by step)."""
        self.unexplored = ""
        """Why the exploration did not run for want of time (``RunFacts.unexplored``)."""
        self.replays: dict[str, tuple[float, str]] = {}
        """Rule -> (when exploration began, the replay line of the story that found it)."""
        self._commanders(config, settings)

    def _commanders(self, config: pytest.Config, settings: Settings) -> None:
        """What drives the unit: the commanders (12, 14), the safety decision, the scenarios'
        context and the observation's waits, all reporting on the progress line."""
        self.progress = Progress(config)
        self.traffic.waits.on_tick = self.progress.tick
        self.traffic.waits.on_end = self.progress.end
        self.deviations = Deviations(on_new=self._adapted)
        self.commander = Commander(
            self.unit, self.traffic, self.connection.publish, dry_run=settings.dry_run,
            say=self._say, gaps=self.connection.gaps,
            wait_connected=self.connection.wait_connected, deviations=self.deviations,
            step=self.progress.step, task_state=self.model_state,
            away=self.connection.away_since)
        self.tst = TstCommander(
            self.unit, settings.tst_topic, self.traffic, self.connection.publish,
            dry_run=settings.dry_run, say=self._say,
            wait_connected=self.connection.wait_connected, deviations=self.deviations,
            gaps=self.connection.gaps, away=self.connection.away_since)
        self.commander.refuse = self.tst.refuse = self.connection.refuse_payload
        self.safety = Safety(self.unit, self.profile, allow_motion=settings.allow_motion,
                             task_moves=task_moves)
        self.context = Context(self.unit, self.profile, self.traffic, self.commander,
                               self.safety, self.timing, settings.seed, self.record,
                               reboot=self.reboot if self.reboot.available() else None,
                               reboot_how=self.reboot.how(), tst=self.tst,
                               settle=lambda: self.observation.settle())
        self.observation = Observation(self.context, self.monitor, self._lock,
                                       observe=settings.observe)
        self.started = self.observation.started

    @property
    def client(self) -> MqttClient | VirtualClient | None:
        """The suite's MQTT client (None before ``start``)."""
        return self.connection.client

    def start(self) -> None:
        """Connect, observe ``<unit>/#`` and wait for the unit's first live heartbeat.

        Raises ``BrokerError`` (broker unreachable or refusing) or ``NotAlive``."""
        self.traffic.waits.deadline = self.traffic.clock.monotonic() + self.settings.max_duration
        if self.config.get_verbosity() >= 0:  # the first seconds: say what is awaited
            where = ("the in-memory broker double and the bundled reference unit, in virtual "
                     "time" if self.settings.virtual else
                     "the embedded broker and the bundled reference unit" if
                     self.settings.embedded else f"{self.settings.broker}")
            self._say(f"waraps-conformance: connecting to {where}, then waiting up to "
                      f"{self.alive_timeout():.0f} s for a heartbeat of {self.unit}")
        revive = None
        if self.reboot.available() and not self.settings.embedded:
            # Restarted once before the run, outside the observation (not a REBOOT-* stimulus).
            restart = Reboot(self.config, self.connection, self.timing.reboot,
                             lambda t: None, self.events)
            revive = (restart.how(), self.timing.reboot, restart)
        self.connection.open(self.alive_timeout(), revive)
        if self.connection.client is not None:
            # A lost broker is waited for within broker_budget(): retry often enough to see
            # it come back inside that budget (paho's backoff would otherwise reach 30 s).
            self.connection.client.reconnect_backoff(2.0)

    def alive_timeout(self) -> float:
        """Seconds to wait for the first heartbeat: the profile's alive_timeout, else 5 s
        (the declared rate is not known before the first heartbeat), times --timing-scale."""
        base = self.profile.alive_timeout or 5.0
        return base * self.settings.timing_scale

    def _say(self, text: str) -> None:
        tw = self.config.get_terminal_writer()
        capman = self.config.pluginmanager.getplugin("capturemanager")
        if capman is not None:
            with capman.global_and_fixture_disabled():
                tw.line(shown(text))
        else:
            tw.line(shown(text))

    def _adapted(self, deviation: Deviation) -> None:
        """A systematic deviation, seen for the first time: say so once (summary and -v)."""
        self.progress.step(self.events.at(self.traffic.clock.now(), f"adapted to {deviation}"))

    def _reboot_requested(self, t: float) -> None:
        with self._lock:
            self.monitor.reboot_requested(t)

    # --- verdicts ------------------------------------------------------------------------------
    def record(self, rule: str, *, violation: Any = None, seen: Observed | None = None,
               reason: str = "", missing: bool = True) -> None:
        """Where scenarios report what they saw (``Context.record``): into the Monitor, for the
        judge. What a
        scenario found missing from a unit that has died is not a fault of its own: the death
        is the finding (HB-012), so the rule could not be tested."""
        excused = ""  # ``missing`` False: a finding of what came (a new name), not of silence
        if violation is not None and missing and CATALOGUE[rule].mode is not Mode.PASSIVE:
            lost, back = self.connection.lost_since(), self.connection.away_since()
            if lost is not None:
                excused = self.outage(lost)
            elif back is not None:
                excused = self.not_back(back)
            else:
                excused = self.unit_died(settle=True)
        with self._lock:
            if violation is not None and violation.command and answered(
                    self.monitor.state(self.unit), violation.command):
                return  # answered meanwhile: late (the Monitor's own finding), not unanswered
            self.monitor.record(self.unit, rule, violation=violation, seen=seen,
                                reason=reason, excused=excused)

    @staticmethod
    def outage(lost: float) -> str:
        """Why nothing the unit should have sent since ``lost`` is its fault."""
        return f"the broker link was lost at {clock(lost)}: no answer could arrive"

    @staticmethod
    def not_back(since: float) -> str:
        """Why nothing the unit should have sent while it was not back on the broker (after
        a reconnect or a stall at ``since``) is its fault."""
        return (f"the unit was not heard again after the broker's outage or stall "
                f"({clock(since)}): the command may never have reached it")

    def broker_budget(self) -> float:
        """Seconds a lost broker is waited for before the run stops (and, at teardown, before
        the suite gives up aborting its tasks): 10 s, or 3 response timeouts if longer."""
        return max(10.0 * self.settings.timing_scale, 3 * self.timing.response)

    def check_broker(self, rules: tuple[str, ...] = ()) -> None:
        """Before a test judges anything: the broker is there, or comes back within the budget.
        Lost for good, the run stops (not certified, exit 6) with no traceback: ``rules``
        could not be tested, the test is skipped and the plugin stops the session."""
        if self.broker_lost is None:
            lost = self.connection.lost_since()
            if lost is None or self.connection.wait_connected(self.broker_budget()):
                lost = self.connection.await_delivery(self.timing.response, self.broker_budget())
                if lost is None:  # it delivers (a stall that delivers again is a gap)
                    return
            self.broker_lost = lost
            self.events.at(self.traffic.clock.now(), f"the broker has not come back within "
                                        f"{self.broker_budget():g} s: the run stops here, "
                                        f"not certified")
        why = self.facts().not_run_reason()[len("not run: "):]
        for rule in rules:
            self.record(rule, seen=Observed.UNTESTABLE, reason=why)
        self.write_reports(force=True)
        pytest.skip(f"could not test: {why}")

    def model_state(self, task_uuid: str) -> State | None:
        """The state of a task as the Monitor's model holds it (``protocol.Model``, fed every
        message before the traffic keeps it: the one lint and the suite judge a sequence
        with), None where it holds nothing."""
        with self._lock:
            state = state_held(self.monitor.state(self.unit), task_uuid)
        return None if state is State.UNKNOWN else state

    def unit_died(self, *, settle: bool = False) -> str:
        """Why the unit counts as dead, or "" while it lives (``Observation.unit_died``)."""
        return self.observation.unit_died(settle=settle)

    def facts(self) -> RunFacts:
        """What the judge must know of this run so far (``conformance.facts.RunFacts``)."""
        cut = self.out_of_time or (CTRL_C if self.interrupted else "")
        return RunFacts(
            kind=RunKind.CERTIFICATION, unit=str(self.unit), strict=self.profile.is_strict,
            error=self.error, broker_lost=self.broker_lost,
            interrupted=bool(cut), cut_short=cut, selection=self.selection,
            # A rule the exploration (or its replay) judged was judged, selected or not.
            selected=tuple(dict.fromkeys([*self.selected, *self.replays]))
            if self.selected or self.selection else (),
            ran=tuple(sorted(self.ran | set(self.replays))),
            enacted_pass=tuple(sorted(r for r, shown in self.enacted.items()
                                      if shown is not Verdict.FAIL)),
            unexplored=self.unexplored)

    def report(self, **extra: Any) -> RunReport:
        """The run's report, judged (``conformance.judge``) under the run's facts: every rule's
        verdict and the conclusion every output shows."""
        with self._lock:
            report = self.monitor.report(**self.meta(), **extra)
        return judge(report, self.facts())

    def _judged(self) -> RunReport:
        """The report as each rule's test enacts it: judged under the facts known mid-run (a
        selection and a cut short run mark rules not run only in ``report``). Made once per
        change of what the Monitor knows: a hundred rule tests in a row read the same one."""
        with self._lock:
            key = (self.monitor.version, self.broker_lost)
            if self._judged_at is not None and self._judged_at[0] == key:
                return self._judged_at[1]
            report = self.monitor.report(**self.meta())
        facts = self.facts()
        judged = judge(report, RunFacts(kind=facts.kind, unit=facts.unit, strict=facts.strict,
                                        broker_lost=facts.broker_lost))
        self._judged_at = (key, judged)
        return judged

    def conclusion(self, report: RunReport) -> Conclusion:
        """What the run concludes: the judge's conclusion stored in ``report``."""
        return conclusion_of(report)

    def verdict(self, report: RunReport) -> str:
        """The run's verdict (``conclusion``)."""
        return self.conclusion(report).verdict

    def counts(self, report: RunReport) -> dict[str, int]:
        """Verdict counts, with the rules that never ran counted as 'not run'."""
        return self.conclusion(report).counts

    def meta(self) -> dict[str, Any]:
        s = self.settings
        hb = self.traffic.latest("heartbeat")
        return {
            "broker": str(s.broker) if not s.embedded else
            f"embedded ({self.connection.broker_url})",
            "started": self.started, "suite_version": __version__,
            "unit": str(self.unit), "seed": str(s.seed), "timing_scale": f"{s.timing_scale:g}",
            "profile_source": self.profile.source, "dry_run": str(s.dry_run).lower(),
            "allow_motion": str(s.allow_motion).lower(),
            "allow_hostile": str(s.allow_hostile).lower(),
            "safety": self.connection.motion.decision.sentence(),
            "reboot": self.reboot.how() if self.context.reboot else "none",
            "agent_uuid": str(hb.get("agent-uuid")) if hb else "",
            "commands_sent": str(self.commander.sent_count + self.tst.sent_count),
            "tst_command_topic": s.tst_topic,
            "explore": self.explored or ("off" if s.explore == 0 else "not run"),
            "explore_story": self.explore_story,
            "rerun": self.rerun_command(),
        }

    def rerun_command(self, rule: str | None = None) -> str:
        """The pytest command that repeats this run (of ``rule`` alone, when given); a rule
        only exploration found, by replaying its story (``-k RULE`` sends no such order)."""
        since, replay = self.replays.get(rule or "", (0.0, ""))
        if replay and rule and all((v.time or since) >= since
                                   for v in self.result(rule).violations):
            return replay
        return self.settings.rerun_command(rule, self._observe_for(rule) if rule else 0)

    def _observe_for(self, rule: str) -> int:
        """Seconds of observation a rerun of ``rule`` needs (0: the passive window will do)."""
        if rule in RULE_SCENARIO:
            return 0
        return self.observation.observe_for(
            [v.time for v in self.result(rule).violations if v.time is not None])

    def violation_total(self, rule: str) -> int:
        """How many violations of ``rule`` the unit committed in all (not only those kept)."""
        unit = self._judged().units.get(str(self.unit))
        return unit.violation_counts.get(rule, 0) if unit is not None else 0

    def result(self, rule: str) -> RuleResult:
        report = self._judged()
        unit = report.units.get(str(self.unit))
        if unit is None or rule not in unit.rules:
            return unexamined(rule)
        return unit.rules[rule]

    def run_evidence(self, rule: str) -> None:
        """Run (once) every scenario whose traffic is evidence for ``rule``."""
        for name in scenarios_for(rule):
            self.run_scenario(name)

    def run_scenario(self, name: str) -> None:
        """Run a scenario once (later calls return at once): ``scenario_run.run_scenario``."""
        run_scenario(self, name)

    def announce(self, text: str) -> None:
        """Something the run did to the unit (a restart after its death): on the terminal
        now (not under -q) and in the summary."""
        line = self.events.at(self.traffic.clock.now(), text)
        if self.config.get_verbosity() >= 0:
            self.progress.line(line)

    def say_aborted(self, aborted: list[str]) -> None:
        self.events.append(f"aborted {len(aborted)} task(s) or TST tree(s) the suite had "
                           f"started: {', '.join(aborted)}")

    def out_of_time_reached(self, e: OutOfTime) -> None:
        """--max-duration passed while waiting for ``e``: the run stops (the summary says so)."""
        self.out_of_time = (f"--max-duration {self.settings.max_duration:g} s reached while "
                            f"waiting for {e}")
        self.events.at(self.traffic.clock.now(), f"{self.out_of_time}: the run stops here")

    def fail_if_out_of_time(self) -> None:
        """The test under way fails, without a traceback, once --max-duration has passed."""
        if self.out_of_time:
            pytest.fail(self.out_of_time, pytrace=False)

    def claims(self, level: str) -> bool:
        """Whether the unit claims ``level`` (5.1: its heartbeat's levels)."""
        # ERR-008: a level written with an underscore is the same claim
        return level in map(level_name, self.context.levels())

    def wait_passive_window(self) -> None:
        """Wait for the passive window (``Observation.wait_passive_window``), then judge the
        end-of-run checks."""
        if self._passive_ready:
            return
        self.check_broker()
        try:
            self.observation.wait_passive_window()
        except OutOfTime as e:
            self.out_of_time_reached(e)
        self.fail_if_out_of_time()
        self.check_broker()
        with self._lock:
            self.monitor.finish(self.traffic.clock.now())
        self._passive_ready = True

    # --- reports and the end ---------------------------------------------------------------------
    def write_reports(self, *, force: bool = False, **extra: Any) -> dict[str, Path]:
        """Write reports/<unit>-<time>.json and .html (atomically; at most once a second unless
        ``force``), so they survive a Ctrl-C."""
        now = self.traffic.clock.monotonic()
        if not force and now - self._last_write < 1.0:
            return self.report_paths
        self._last_write = now

        report = self.report(**extra)
        unit = report.units.get(str(self.unit))
        for r in unit.rules.values() if unit is not None else ():
            if r.verdict in (Verdict.FAIL, Verdict.WARN):  # the rerun lines the terminal prints
                report.meta[RERUN_OF + r.rule] = self.rerun_command(r.rule)
        try:
            self.report_paths = write_all(report, self.settings.reports_dir, self.stem)
        except OSError as e:
            # The next write tries again; the final one says it, and the run keeps its own
            # exit status (a folder removed or filled during the run is no traceback).
            self.report_error = (f"could not write the reports into "
                                 f"{self.settings.reports_dir}: {e.strerror or e}")
            if not force:
                self.events.append(self.report_error)
        else:
            self.report_error = ""
        return self.report_paths

    def finish(self, *, interrupted: bool, exitstatus: int) -> int:
        """End the run: abort every task the suite started (also after a failure or Ctrl-C),
        judge the end of the observation, write the final reports, disconnect. Returns the
        run's exit status (``exit_status``)."""
        if self.collect_only:
            return exitstatus
        status = exitstatus
        self.interrupted = self.interrupted or interrupted
        self.traffic.waits.deadline = None  # the teardown's waits have deadlines of their own
        aborted: list[str] = []
        lost = self.connection.lost_since()
        if lost is not None and self.connection.client is not None and self.broker_lost is None:
            # Lost during the last test: the run is over, the broker gets the budget to return.
            if not self.connection.wait_connected(self.broker_budget()):
                self.broker_lost = lost
        elif lost is None and self.connection.client is not None and self.broker_lost is None:
            self.broker_lost = self.connection.await_delivery(  # a silent unit is probed
                self.timing.response, self.broker_budget(), silent_periods=1.0)
        started = bool(self.commander.open_tasks or self.tst.open_trees)
        try:
            if self.settings.dry_run:
                pass
            elif self.connection.is_connected or (started and self.connection.wait_connected(
                    self.broker_budget())):
                aborted = self.commander.abort_all(self.timing.response)
                aborted += self.tst.abort_all(self.timing.response)
            elif started:
                self.events.append("the broker did not come back: the tasks the suite started "
                                   "could not be aborted")
        except Exception as e:  # the reports must still be written
            self.events.append(f"aborting the suite's tasks failed: {e}")
        if aborted:
            self.say_aborted(aborted)
        try:
            with self._lock:
                # Lost for good: the observation ended then (an outage is no death).
                self.monitor.finish(self.broker_lost or self.traffic.clock.now())
            finished = self.traffic.clock.now()
            status = exit_status(self.conclusion(self.report(finished=finished)), exitstatus)
            self.write_reports(force=True, finished=finished, exit_status=str(status))
        finally:
            self.close()
        return status

    def close(self) -> None:
        self.connection.close()

    def header(self) -> list[str]:
        """The lines pytest shows before the tests (``header_lines``); the unit's own words
        in them (agent-uuid, agent-type, levels) escaped and excerpted, never a
        password."""
        return [shown(shorten(line, LINE_CHARS)) for line in header_lines(
            self.settings, broker=self.connection.broker_url, heartbeat=self.context.heartbeat(),
            levels=self.context.levels(),
            reboot=self.reboot.how() if self.context.reboot else None,
            reports=self.settings.reports_dir / self.stem, rerun=self.rerun_command(),
            decision=self.connection.motion.decision)]



def exit_status(conclusion: Conclusion, pytest_status: int) -> int:
    """The run's exit status: the verdict model's (README 'Exit status'), except pytest's own
    internal and usage errors, no test selected, and a test that failed without a rule
    failing (the suite's own error: never hidden behind a 0)."""
    if pytest_status in (pytest.ExitCode.INTERNAL_ERROR, pytest.ExitCode.USAGE_ERROR):
        return int(pytest_status)
    if conclusion.exit_code:
        return conclusion.exit_code
    if pytest_status in (pytest.ExitCode.NO_TESTS_COLLECTED, pytest.ExitCode.TESTS_FAILED):
        return int(pytest_status)
    return 0

__all__ = ["CERTIFICATION", "INTERRUPTED", "NOT_CERTIFIED", "Certification",
           "NotAlive"]

"""One certification run: the unit under test, the passive Monitor, the active scenarios, and
the reports. Created by the plugin when ``--unit`` is given.

Data flows one way, so lint and the suite judge the same evidence alike: every message of ``<unit>/#`` goes to the ``Monitor`` (the same
passive checks as the linter) and to ``Traffic`` (which the scenarios wait on); scenarios
record their verdicts into the same Monitor; the Monitor's report is what the tests, the JSON
and HTML reports and the JUnit properties show.

``Certification`` keeps the run's lifecycle (start, the broker and --max-duration checked
before each test, the passive window, finish, close) and wires its parts, each with one job:
the link to the broker ``connection.py`` (and ``probe.py`` when the unit is not there), how
long the unit is watched ``observation.py``, rebooting it ``reboot.py``, what the scenarios and
the tests gather for the judge ``evidence.py``, the judged report ``judging.py`` (the verdicts
and the conclusion come from the one judge, ``conformance.judge``), the report files
``writing.py``, the header ``header.py``.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

import pytest

from conformance import __version__
from conformance.checks import Monitor
from conformance.checks.exec_sequence import state_held
from conformance.client import MqttClient
from conformance.clock import REAL, VirtualClock
from conformance.conclusion import INTERRUPTED, NOT_CERTIFIED, Conclusion
from conformance.conclusion import of as conclusion_of
from conformance.display import LINE_CHARS, shorten, shown
from conformance.facts import CTRL_C, RunFacts, RunKind
from conformance.protocol import State
from conformance.report_meta import RunMeta
from conformance.results import RunReport
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
from conformance.suite.events import Events
from conformance.suite.evidence import Evidence
from conformance.suite.header import header_lines
from conformance.suite.judging import Judging
from conformance.suite.observation import Observation
from conformance.suite.probe import NotAlive
from conformance.suite.progress import Progress
from conformance.suite.reboot import Reboot
from conformance.suite.scenario_run import run_scenario
from conformance.suite.settings import Settings
from conformance.suite.writing import Reports
from conformance.topics import UnitAddress, level_name
from conformance.violation import Observed, RuleResult

if TYPE_CHECKING:
    from conformance.sim.virtual import VirtualClient

CERTIFICATION = pytest.StashKey["Certification"]()


class Certification:
    """One ``pytest --unit`` run (one unit, one broker, one profile): its lifecycle and the
    run's own facts, wiring the parts that each do one job (``evidence``, ``judging``,
    ``reports``, the connection, the commanders, the observation)."""

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
        self.connection.say = self._say
        self.reboot = Reboot(config, self.connection, self.timing.reboot,
                             self._reboot_requested, self.events)
        self.collect_only = False  # --collect-only: nothing is connected, run or written
        self.error = ""
        """Why the run stopped before the tests (broker unreachable, unit not alive)."""
        self.revived = 0  # how often the unit was restarted after it died (scenario_run.revive)
        self._passive_ready = False
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
        self._commanders(config, settings)
        self.evidence = Evidence(self.unit, self.monitor, self._lock, self.connection,
                                 lambda: self.unit_died(settle=True))
        self.judging = Judging(self.unit, self.monitor, self._lock, self.facts, self.meta)
        self.reports = Reports(self.unit, settings.reports_dir, self.traffic.clock, self.events,
                               self.judging.report, self.rerun_command)

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
        """A line of its own (``Progress.line``), never appended to pytest's row of results;
        escaped, never a password."""
        self.progress.line(shown(text))

    def _adapted(self, deviation: Deviation) -> None:
        """A systematic deviation, seen for the first time: say so once (summary and -v)."""
        self.progress.step(self.events.at(self.traffic.clock.now(), f"adapted to {deviation}"))

    def _reboot_requested(self, t: float) -> None:
        with self._lock:
            self.monitor.reboot_requested(t)

    # --- evidence and verdicts ----------------------------------------------------------------
    def record(self, rule: str, *, violation: Any = None, seen: Observed | None = None,
               reason: str = "", missing: bool = True) -> None:
        """Where scenarios report what they saw (``Context.record``): ``Evidence.record``."""
        self.evidence.record(rule, violation=violation, seen=seen, reason=reason,
                             missing=missing)

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
        self.reports.write(force=True)
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
        selected, ran, passed = self.evidence.judged_rules()
        return RunFacts(
            kind=RunKind.CERTIFICATION, unit=str(self.unit), strict=self.profile.is_strict,
            error=self.error, broker_lost=self.broker_lost,
            interrupted=bool(cut), cut_short=cut, selection=self.selection,
            selected=selected if self.evidence.selected or self.selection else (),
            ran=ran, enacted_pass=passed, unexplored=self.unexplored)

    def report(self, **extra: Any) -> RunReport:
        """The run's report, judged under the run's facts (``Judging.report``)."""
        return self.judging.report(**extra)

    def result(self, rule: str) -> RuleResult:
        """``rule``'s result as its test enacts it (``Judging.result``)."""
        return self.judging.result(rule)

    def meta(self) -> dict[str, Any]:
        """The report's fields for ``Monitor.report``, its ``meta`` (``RunMeta``) with them."""
        s = self.settings
        hb = self.traffic.latest("heartbeat")
        return {
            "broker": str(s.broker) if not s.embedded else
            f"embedded ({self.connection.broker_url})",
            "started": self.started, "suite_version": __version__,
            "meta": RunMeta(
                unit=str(self.unit), seed=str(s.seed), timing_scale=f"{s.timing_scale:g}",
                profile_source=self.profile.source, dry_run=str(s.dry_run).lower(),
                allow_motion=str(s.allow_motion).lower(),
                allow_hostile=str(s.allow_hostile).lower(),
                safety=self.connection.motion.decision.sentence(),
                reboot=self.reboot.how() if self.context.reboot else "none",
                agent_uuid=str(hb.get("agent-uuid")) if hb else "",
                commands_sent=str(self.commander.sent_count + self.tst.sent_count),
                tst_command_topic=s.tst_topic,
                explore=self.explored or ("off" if s.explore == 0 else "not run"),
                explore_story=self.explore_story,
                rerun=self.rerun_command()),
        }

    def rerun_command(self, rule: str | None = None) -> str:
        """The pytest command that repeats this run (of ``rule`` alone, when given); a rule
        only exploration found, by replaying its story (``-k RULE`` sends no such order)."""
        since, replay = self.evidence.replays.get(rule or "", (0.0, ""))
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

    # --- the end ---------------------------------------------------------------------------------
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
            final = self.judging.conclude(finished=self.traffic.clock.now())
            status = exit_status(conclusion_of(final), exitstatus)
            self.reports.write(force=True, exit_status=str(status), final=final)
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
            reports=self.settings.reports_dir / self.reports.stem, rerun=self.rerun_command(),
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

"""One certification run: the unit under test, the passive Monitor, the active scenarios, and
the reports. Created by the plugin when ``--unit`` is given.

Data flows one way (DESIGN): every message of ``<unit>/#`` goes to the ``Monitor`` (the same
passive checks as the linter) and to ``Traffic`` (which the scenarios wait on); scenarios
record their verdicts into the same Monitor; the Monitor's report is what the tests, the JSON
and HTML reports and the JUnit properties show.

Its parts: the link to the broker ``connection.py`` (and ``probe.py`` when the unit is not
there), how long the unit is watched ``observation.py``, rebooting it ``reboot.py``, what the
report concludes ``outcome.py``, the header ``header.py``.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from conformance import __version__
from conformance.checks import Monitor
from conformance.client import MqttClient
from conformance.results import RunReport
from conformance.rules import CATALOGUE, Mode
from conformance.scenarios import (
    SCENARIOS,
    Commander,
    Context,
    DryRun,
    Safety,
    Timing,
    Traffic,
    TstCommander,
)
from conformance.scenarios.deviation import Deviation, Deviations
from conformance.scenarios.params import task_moves
from conformance.scenarios.traffic import OutOfTime
from conformance.suite import outcome
from conformance.suite.connection import Connection
from conformance.suite.events import Events
from conformance.suite.header import header_lines
from conformance.suite.observation import Observation
from conformance.suite.outcome import COMMANDER_RULES, INTERRUPTED, NOT_CERTIFIED
from conformance.suite.probe import NotAlive
from conformance.suite.reboot import Reboot
from conformance.suite.settings import Settings
from conformance.topics import DIRECT_EXECUTION, UnitAddress
from conformance.violation import RuleResult, Verdict

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
        self.traffic = Traffic(self.unit, tst_operator=operator.base if operator else None)
        # The Monitor puts what is wrong in the suite's own commands (some broken on purpose:
        # the robustness scenario) on the commander's account, which a certification does not
        # report; it judges the unit's answers with the deadlines the scenarios wait for.
        self.monitor = Monitor(dataclasses.replace(
            self.profile, response_timeout=self.timing.response,
            feedback_timeout=self.timing.feedback), units=[self.unit], kind="certification")
        self._lock = threading.RLock()
        self.events = Events()
        """What happened to the connection and the unit, for the terminal summary."""
        self.connection = Connection(settings, self.monitor, self.traffic, self._lock,
                                     self.events)
        self.reboot = Reboot(config, self.connection, self.timing.reboot,
                             self._reboot_requested, self.events)
        self.stem = f"{self.unit.name}-{time.strftime('%Y%m%dT%H%M%S', time.localtime())}"
        self.report_paths: dict[str, Path] = {}
        self.collect_only = False
        """--collect-only: nothing is connected, run or written."""
        self.error: str | None = None
        """Why the run stopped before the tests (broker unreachable, unit not alive)."""
        self._done: dict[str, bool] = {}
        self._passive_ready = False
        self._last_write = 0.0
        self.selected: list[str] = []
        """The rules whose tests were selected to run (after -k, -m, --rule)."""
        self.ran: set[str] = set()
        """The rules whose tests ran (a test that never ran judged nothing)."""
        self.out_of_time: str | None = None
        """--max-duration passed: what the run was waiting for then."""
        self.interrupted = False
        self.explored = ""
        """What the exploration did (``suite/exploration.py``), for the report's meta."""
        from conformance.suite.progress import Progress

        self.progress = Progress(config)
        self.traffic.waits.on_tick = self.progress.tick
        self.traffic.waits.on_end = self.progress.end
        self.deviations = Deviations(on_new=self._adapted)
        self.commander = Commander(
            self.unit, self.traffic, self.connection.publish, dry_run=settings.dry_run,
            say=self._say, gaps=self.connection.gaps,
            wait_connected=self.connection.wait_connected, deviations=self.deviations,
            step=self.progress.step)
        self.tst = TstCommander(
            self.unit, settings.tst_topic, self.traffic, self.connection.publish,
            dry_run=settings.dry_run, say=self._say,
            wait_connected=self.connection.wait_connected)
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
    def client(self) -> MqttClient | None:
        """The suite's MQTT client (None before ``start``)."""
        return self.connection.client

    def start(self) -> None:
        """Connect, observe ``<unit>/#`` and wait for the unit's first live heartbeat.

        Raises ``BrokerError`` (broker unreachable or refusing) or ``NotAlive``."""
        self.traffic.waits.deadline = time.monotonic() + self.settings.max_duration
        self.connection.open(self.alive_timeout())

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
                tw.line(text)
        else:
            tw.line(text)

    def _adapted(self, deviation: Deviation) -> None:
        """A systematic deviation, seen for the first time: say so once (summary and -v)."""
        self.progress.step(self.events.at(time.time(), f"adapted to {deviation}"))

    def _reboot_requested(self, t: float) -> None:
        with self._lock:
            self.monitor.reboot_requested(t)

    # --- verdicts ------------------------------------------------------------------------------
    def record(self, rule: str, *, violation: Any = None, verdict: Verdict | None = None,
               reason: str = "") -> None:
        """Where scenarios report (``Context.record``): into the Monitor's results. What a
        scenario found missing from a unit that has died is not a fault of its own: the death
        is the finding (HB-012), so the rule could not be tested."""
        if violation is not None and CATALOGUE[rule].mode is not Mode.PASSIVE:
            died = self.unit_died(settle=True)
            if died:
                violation, verdict, reason = None, Verdict.COULD_NOT_TEST, died
        with self._lock:
            self.monitor.record(self.unit, rule, violation=violation, verdict=verdict,
                                reason=reason)

    def unit_died(self, *, settle: bool = False) -> str:
        """Why the unit counts as dead, or "" while it lives (``Observation.unit_died``)."""
        return self.observation.unit_died(settle=settle)

    def report(self, **extra: Any) -> RunReport:
        with self._lock:
            report = self.monitor.report(**self.meta(), **extra)
        outcome.set_commander_rules_aside(report, self.unit)
        if self.error or self.interrupted:
            outcome.mark_not_run(report, self.unit, self.selected or list(CATALOGUE), self.ran,
                                 self.not_run_reason())
        report.meta["verdict"] = self.verdict(report)
        return report

    def not_run_reason(self) -> str:
        if self.error:
            return f"not run: {self.error.splitlines()[0]}"
        return f"not run: {self.out_of_time or 'the run was interrupted'}"

    def verdict(self, report: RunReport) -> str:
        """The run's verdict (``outcome.verdict``)."""
        return outcome.verdict(report, error=self.error, interrupted=self.interrupted)

    def counts(self, report: RunReport) -> dict[str, int]:
        """Verdict counts, with the rules that never ran counted as 'not run'."""
        return outcome.counts(report)

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
            "reboot": self.reboot.how() if self.context.reboot else "none",
            "agent_uuid": str(hb.get("agent-uuid")) if hb else "",
            "commands_sent": str(self.commander.sent_count + self.tst.sent_count),
            "tst_command_topic": s.tst_topic,
            "explore": self.explored or ("off" if s.explore == 0 else "not run"),
            "rerun": self.rerun_command(),
        }

    def rerun_command(self, rule: str | None = None) -> str:
        """The pytest command that repeats this run (of ``rule`` alone, when given)."""
        return self.settings.rerun_command(rule, self._observe_for(rule) if rule else 0)

    def _observe_for(self, rule: str) -> int:
        """Seconds of observation a rerun of ``rule`` needs (0: the passive window will do)."""
        from conformance.scenarios import RULE_SCENARIO

        if rule in RULE_SCENARIO:
            return 0
        return self.observation.observe_for(
            [v.time for v in self.result(rule).violations if v.time is not None])

    def violation_total(self, rule: str) -> int:
        """How many violations of ``rule`` the unit committed in all (not only those kept)."""
        unit = self.report().units.get(str(self.unit))
        return unit.violation_counts.get(rule, 0) if unit is not None else 0

    def result(self, rule: str) -> RuleResult:
        report = self.report()
        unit = report.units.get(str(self.unit))
        if unit is None or rule not in unit.rules:
            return RuleResult(rule, Verdict.SKIP, "not examined")
        return unit.rules[rule]

    def run_evidence(self, rule: str) -> None:
        """Run (once) every scenario whose traffic is evidence for ``rule``."""
        from conformance.scenarios import scenarios_for

        for name in scenarios_for(rule):
            self.run_scenario(name)

    def run_scenario(self, name: str) -> None:
        """Run a scenario once (later calls return at once); ping first, as the gate, and the
        scenarios it works on (``Scenario.needs``)."""
        if name in self._done:
            return
        scenario = SCENARIOS[name]
        for needed in scenario.needs:
            self.run_scenario(needed)
        silent = self.unit_died() if name != "reboot" else ""
        if silent:
            # A dead unit answers nothing: each wait would only run out (HB-012 is the
            # finding). The reboot scenario may bring it back, so it still runs.
            for rule in scenario.rules:
                self.record(rule, verdict=Verdict.COULD_NOT_TEST, reason=silent)
            self._done[name] = False
            return
        if scenario.level is not None:
            if not self._claims(scenario.level):
                self._done[name] = False
                return  # every rule of it: skip, not claimed (the Monitor's reason)
            # Ping gates the other direct-execution scenarios, except robustness, whose rule
            # asks exactly whether the unit still pings.
            if name not in ("ping", "robust") and scenario.level == DIRECT_EXECUTION:
                self.run_scenario("ping")
                if not self._answers_commands():
                    for rule in scenario.rules:
                        self.record(rule, verdict=Verdict.COULD_NOT_TEST,
                                    reason="the unit answers no command: ping got no response "
                                    f"within {self.timing.response:.1f} s (EXEC-PING-001)")
                    self._done[name] = False
                    return
            self.observation.wait_execution_info()
        try:
            scenario.run(self.context)
        except DryRun as e:
            for rule in scenario.rules:
                self.record(rule, verdict=Verdict.COULD_NOT_TEST, reason=str(e))
        except OutOfTime as e:
            self._out_of_time(e)
        finally:
            self._done[name] = True
            if not self.settings.dry_run:
                aborted = self.commander.abort_all(self.timing.response)
                aborted += self.tst.abort_all(self.timing.response)
                if aborted and self.out_of_time:
                    self._say_aborted(aborted)
            self.write_reports()
        self._fail_if_out_of_time()

    def _say_aborted(self, aborted: list[str]) -> None:
        self.events.append(f"aborted {len(aborted)} task(s) or TST tree(s) the suite had "
                           f"started: {', '.join(aborted)}")

    def _out_of_time(self, e: OutOfTime) -> None:
        self.out_of_time = (f"--max-duration {self.settings.max_duration:g} s reached while "
                            f"waiting for {e}")
        self.events.at(time.time(), f"{self.out_of_time}: the run stops here")

    def _fail_if_out_of_time(self) -> None:
        if self.out_of_time:
            pytest.fail(self.out_of_time, pytrace=False)

    def _claims(self, level: str) -> bool:
        # ERR-008: a level written with an underscore is the same claim
        return level in (lv.replace("_", " ") for lv in self.context.levels())

    def _answers_commands(self) -> bool:
        if self.settings.dry_run:
            return True  # nothing was sent: let every scenario say what it would send
        return self.result("EXEC-PING-001").verdict is not Verdict.FAIL or bool(
            self.traffic.since(0, "exec/response"))

    def wait_passive_window(self) -> None:
        """Wait for the passive window (``Observation.wait_passive_window``), then judge the
        end-of-run checks."""
        if self._passive_ready:
            return
        try:
            self.observation.wait_passive_window()
        except OutOfTime as e:
            self._out_of_time(e)
        self._fail_if_out_of_time()
        with self._lock:
            self.monitor.finish(time.time())
        self._passive_ready = True

    # --- reports and the end ---------------------------------------------------------------------
    def write_reports(self, *, force: bool = False, **extra: Any) -> dict[str, Path]:
        """Write reports/<unit>-<time>.json and .html (atomically; at most once a second unless
        ``force``), so they survive a Ctrl-C."""
        now = time.monotonic()
        if not force and now - self._last_write < 1.0:
            return self.report_paths
        self._last_write = now
        from conformance.reporting import write_all

        report = self.report(**extra)
        try:
            self.report_paths = write_all(report, self.settings.reports_dir, self.stem)
        except OSError as e:
            if force:
                raise
            # The next write (at the latest the final one) tries again.
            self.events.append(f"could not write the reports into "
                               f"{self.settings.reports_dir}: {e}")
        return self.report_paths

    def finish(self, *, interrupted: bool, exitstatus: int) -> None:
        """End the run: abort every task the suite started (also after a failure or Ctrl-C),
        judge the end of the observation, write the final reports, disconnect."""
        if self.collect_only:
            return
        self.interrupted = self.interrupted or interrupted
        self.traffic.waits.deadline = None  # the teardown's waits have deadlines of their own
        aborted: list[str] = []
        try:
            if self.connection.is_connected and not self.settings.dry_run:
                aborted = self.commander.abort_all(self.timing.response)
                aborted += self.tst.abort_all(self.timing.response)
        except Exception as e:  # the reports must still be written
            self.events.append(f"aborting the suite's tasks failed: {e}")
        if aborted:
            self._say_aborted(aborted)
        try:
            with self._lock:
                self.monitor.finish(time.time())
            extra = {"error": self.error} if self.error else {}
            self.write_reports(force=True, finished=time.time(),
                               interrupted=str(interrupted).lower(),
                               exit_status=str(int(exitstatus)), **extra)
        finally:
            self.close()

    def close(self) -> None:
        self.connection.close()

    def header(self) -> list[str]:
        """The lines pytest shows before the tests (``header_lines``)."""
        return header_lines(
            self.settings, broker=self.connection.broker_url, heartbeat=self.context.heartbeat(),
            levels=self.context.levels(),
            reboot=self.reboot.how() if self.context.reboot else None,
            reports=self.settings.reports_dir / self.stem, rerun=self.rerun_command())


__all__ = ["CERTIFICATION", "COMMANDER_RULES", "INTERRUPTED", "NOT_CERTIFIED", "Certification",
           "NotAlive"]

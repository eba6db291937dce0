"""One certification run: the connection, the unit's traffic, the passive Monitor, the active
scenarios, and the reports. Created by the plugin when ``--unit`` is given.

Data flows one way (DESIGN): every message of ``<unit>/#`` goes to the ``Monitor`` (the same
passive checks as the linter) and to ``Traffic`` (which the scenarios wait on); scenarios
record their verdicts into the same Monitor; the Monitor's report is what the tests, the JSON
and HTML reports and the JUnit properties show.
"""

from __future__ import annotations

import dataclasses
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from conformance import __version__
from conformance.checks import Monitor
from conformance.client import BrokerError, BrokerURL, Message, MqttClient
from conformance.results import COMMANDER_REASON, RunReport
from conformance.rules import CATALOGUE, Mode, Side
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
from conformance.suite.settings import Settings
from conformance.topics import UnitAddress
from conformance.validator import Validator
from conformance.violation import RuleResult, Verdict

NOT_CERTIFIED = "not certified"
INTERRUPTED = "interrupted"

CERTIFICATION = pytest.StashKey["Certification"]()

# Rules about what a commander sends (the catalogue's side). In a certification the suite
# itself is the commander, so they say nothing about the unit: `waraps-conformance lint` judges
# commanders.
COMMANDER_RULES = frozenset(r.id for r in CATALOGUE.values() if r.side is Side.COMMANDER)
PERIODIC = ("heartbeat", "sensor_info", "direct_execution_info", "tst_execution_info")
MAX_PROBE_TOPICS = 500


class NotAlive(Exception):
    """The unit under test sent no heartbeat in time; the message says what was seen."""


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
        self.client: MqttClient | None = None
        self.reference: Any = None  # the bundled reference unit under --broker embedded
        self.broker_url: BrokerURL = settings.broker
        self.started = time.time()
        self._started_monotonic = time.monotonic()
        self.stem = f"{self.unit.name}-{time.strftime('%Y%m%dT%H%M%S', time.localtime())}"
        self.report_paths: dict[str, Path] = {}
        self.collect_only = False
        """--collect-only: nothing is connected, run or written."""
        self.error: str | None = None
        """Why the run stopped before the tests (broker unreachable, unit not alive)."""
        self.events: list[str] = []
        """What happened to the connection and the unit, for the terminal summary."""
        self._gap_start: float | None = None
        self._alive = threading.Event()
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
        from conformance.suite.progress import Progress

        self.progress = Progress(config)
        self.traffic.waits.on_tick = self.progress.tick
        self.traffic.waits.on_end = self.progress.end
        self.deviations = Deviations(on_new=self._adapted)
        self.commander = Commander(
            self.unit, self.traffic, self._publish, dry_run=settings.dry_run, say=self._say,
            gaps=lambda: len(self.client.gaps) if self.client else 0,
            wait_connected=lambda t: self.client.wait_connected(t) if self.client else False,
            deviations=self.deviations, step=self.progress.step)
        self.tst = TstCommander(
            self.unit, settings.tst_topic, self.traffic, self._publish, dry_run=settings.dry_run,
            say=self._say,
            wait_connected=lambda t: self.client.wait_connected(t) if self.client else False)
        self.safety = Safety(self.unit, self.profile, allow_motion=settings.allow_motion,
                             task_moves=task_moves)
        self.context = Context(self.unit, self.profile, self.traffic, self.commander,
                               self.safety, self.timing, settings.seed, self.record,
                               reboot=self._reboot_method(), reboot_how=self._reboot_how(),
                               tst=self.tst, settle=self._settle)

    # --- connection and the alive check -------------------------------------------------------
    def start(self) -> None:
        """Connect, observe ``<unit>/#`` and wait for the unit's first live heartbeat.

        Raises ``BrokerError`` (broker unreachable or refusing) or ``NotAlive``."""
        self.traffic.waits.deadline = time.monotonic() + self.settings.max_duration
        if self.settings.embedded:
            from conformance.sim.reference import Reference

            self.reference = Reference(self.unit, faults=self.settings.sim_faults,
                                       rate=self.settings.sim_rate, seed=self.settings.seed,
                                       tst=self.settings.sim_tst,
                                       tst_operator=self.settings.tst_operator).start()
            self.broker_url = BrokerURL.parse(self.reference.url)
        probe = _Probe(self.broker_url, self.unit)
        self.client = MqttClient(self.broker_url, on_message=self._on_message,
                                 may_publish=self._may_publish,
                                 on_connection_change=self._on_connection)
        self.client.connect(timeout=5.0 * self.settings.timing_scale)
        self.client.subscribe(self.unit.base + "/#")
        if self.settings.tst_operator is not None:  # 14.1: commands and answers there
            self.client.subscribe(self.settings.tst_operator.base + "/tst/#")
        probe.start()
        try:
            deadline = self.alive_timeout()
            if not self._alive.wait(deadline):
                raise NotAlive(self._not_alive(deadline, probe.topics()))
        finally:
            probe.close()

    def alive_timeout(self) -> float:
        """Seconds to wait for the first heartbeat: the profile's alive_timeout, else 5 s
        (the declared rate is not known before the first heartbeat), times --timing-scale."""
        base = self.profile.alive_timeout or 5.0
        return base * self.settings.timing_scale

    def _not_alive(self, waited: float, seen: dict[str, bytes]) -> str:
        topic = self.unit.topic("heartbeat")
        lines = [f"the unit {self.unit} is not alive: no heartbeat on {topic} within "
                 f"{waited:.1f} s (broker {self.broker_url})."]
        if self.traffic.subtopics():
            lines.append(f"Its own topics were seen ({', '.join(sorted(self.traffic.subtopics()))}"
                         f"), but no live heartbeat (retained ones do not count).")
        def base(topic: str) -> str:
            lead = "/" if topic.startswith("/") else ""
            return lead + "/".join(topic.lstrip("/").split("/")[:5])

        others = sorted({base(t) for t in seen if t.lstrip("/").split("/")[1:2] == ["unit"]
                         and len(t.lstrip("/").split("/")) > 5} - {self.unit.base})
        prefix = self.unit.prefix
        import difflib

        # Only a unit whose address is close to this one is worth a line (a typo, a leading
        # '/', another role or type): other units' topics say nothing about this one.
        close = difflib.get_close_matches(self.unit.base, others, n=1, cutoff=0.8)
        if close:
            if _is_address(close[0]):
                lines.append(f"A unit publishes at {close[0]}: did you mean --unit "
                             f"{close[0]}?")
            else:
                lines.append(f"A unit publishes at {close[0]}.")
        elif others:
            lines.append(f"{len(others)} other unit(s) publish under {prefix}/, none at a "
                         "similar address.")
        # A unit publishing where it should not (a leading '/', an unknown agent type or
        # role) breaks the naming rules of spec 3: say which, that is the finding.
        broken: dict[str, str] = {}
        validator = Validator(self.profile)
        for topic, payload in sorted(seen.items()):
            if close and base(topic) != close[0]:
                continue
            for v in validator.validate(topic, payload).violations:
                if self.profile.severity_of(v.rule).value == "error":
                    broken.setdefault(v.rule, f"{v.rule} {CATALOGUE[v.rule].title} ({topic})")
        if broken and close:
            lines.append("Its topics break: " + "; ".join(broken[r] for r in sorted(broken)))
        if not seen:
            lines.append(f"Nothing at all was published under {prefix}/ meanwhile: is the unit "
                         f"running and connected to this broker, under this prefix?")
        if self.settings.timing_scale == 1.0:
            lines.append("On a slow link, give it longer with --timing-scale 3.")
        return "\n".join(lines)

    def _on_message(self, message: Message) -> None:
        """Every message of ``<unit>/#``, on the MQTT network thread: keep it quick."""
        with self._lock:
            self.monitor.feed(message)
        self.traffic.add(message)
        if not message.retain and message.topic.endswith("/heartbeat") \
                and message.topic == self.unit.topic("heartbeat"):
            self._alive.set()

    def _on_connection(self, connected: bool, reason: str) -> None:
        now = time.time()
        with self._lock:
            if not connected:
                self._gap_start = now
                # Mark the gap at once: rates, silences and uuid changes across it are not
                # judged (the Monitor merges this with its end when the link comes back).
                self.monitor.connection_gap(now, now)
                self.events.append(f"{_clock(now)} broker connection lost ({reason})")
            elif self._gap_start is not None:
                start, self._gap_start = self._gap_start, None
                self.monitor.connection_gap(start, now)
                self.events.append(f"{_clock(now)} broker connection back after "
                                   f"{now - start:.1f} s: rates, silences and uuid changes over "
                                   f"the gap are not judged")

    def _may_publish(self, topic: str) -> bool:
        # DESIGN 'Safety': only the command topic of the unit under test, and the one TST
        # command topic the run was told (14.1: the unit's own, or an operator's).
        return topic == self.unit.topic("exec/command") or topic == self.settings.tst_topic

    def _publish(self, topic: str, payload: bytes) -> None:
        assert self.client is not None
        # QoS 1 without waiting for the PUBACK: the unit's answer is what the scenario waits
        # for, and paho resends an unacknowledged command after a reconnect.
        self.client.publish(topic, payload, qos=1, timeout=0)

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
        text = f"{_clock(time.time())} adapted to {deviation}"
        self.events.append(text)
        self.progress.step(text)

    # --- reboot -------------------------------------------------------------------------------
    def _reboot_how(self) -> str:
        if self.settings.reboot_cmd:
            return f"--reboot-cmd {self.settings.reboot_cmd!r}"
        if self.settings.embedded:
            return "the bundled reference unit's reboot"
        return "a pytest_waraps_reboot hook"

    def _reboot_method(self) -> Callable[[], str | None] | None:
        hooks = self.config.pluginmanager.hook.pytest_waraps_reboot.get_hookimpls()
        if not (self.settings.reboot_cmd or self.settings.embedded or hooks):
            return None
        return self._reboot

    def _reboot(self) -> str | None:
        """Reboot the unit; None when done, else what went wrong. The time of the reboot is
        marked as a gap in the observation: a rebooting unit is allowed its silence there
        (REBOOT-001 judges the reboot itself)."""
        now = time.time()
        with self._lock:
            self.monitor.reboot_requested(now)
        self.events.append(f"{_clock(now)} reboot requested ({self._reboot_how()})")
        if self.config.pluginmanager.hook.pytest_waraps_reboot(
                config=self.config, unit=str(self.unit)):
            return None
        if self.settings.reboot_cmd:
            try:
                done = subprocess.run(self.settings.reboot_cmd, shell=True, capture_output=True,
                                      text=True, timeout=self.timing.reboot)
            except subprocess.TimeoutExpired:
                return f"did not finish within {self.timing.reboot:.1f} s"
            if done.returncode != 0:
                err = (done.stderr or done.stdout).strip().splitlines()
                return f"exit status {done.returncode}" + (f": {err[-1]}" if err else "")
            return None
        if self.reference is not None:
            self.reference.reboot()
            return None
        return "no way to reboot the unit"

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
        """Why the unit counts as dead, or "" while it lives: no heartbeat for 3
        declared periods (HB-012's window) and none within 10 periods or the response
        deadline, whichever is longer (a dropout of a few periods, HB-010's, is not death).
        A unit that heartbeats answers at once. ``settle``: a unit still within its 3
        periods is waited for too (before a verdict, not before a command)."""
        from conformance.checks.identity import SILENCE_PERIODS

        latest = self.traffic.latest("heartbeat")
        rate = self.context.rate_of("heartbeat")
        if latest is None or rate is None:
            return ""
        period = self.timing.scale / rate
        if not settle and time.time() - latest.time <= SILENCE_PERIODS * period:
            return ""
        left = latest.time + max(10 * period, self.timing.response) - time.time()
        if left > 0 and self.traffic.wait_for(lambda e: True, left, after=latest.seq,
                                              subtopic="heartbeat",
                                              what="the unit's heartbeat") is not None:
            return ""
        return (f"the unit fell silent at {_clock(latest.time)} and did not come back "
                f"(HB-012): no answer could come")

    def report(self, **extra: Any) -> RunReport:
        with self._lock:
            report = self.monitor.report(**self.meta(), **extra)
        # The suite's own commands are not the unit's to answer for: the report says what the
        # pytest outcome says (a failure stays one: it would be the suite's own bug).
        unit = report.units.get(str(self.unit))
        if unit is not None:
            for rule in COMMANDER_RULES & unit.rules.keys():
                if unit.rules[rule].verdict is not Verdict.FAIL:
                    unit.rules[rule] = RuleResult(rule, Verdict.SKIP, COMMANDER_REASON)
        if self.error or self.interrupted:
            self._mark_not_run(report)
        report.meta["verdict"] = self.verdict(report)
        return report

    def not_run_reason(self) -> str:
        if self.error:
            return f"not run: {self.error.splitlines()[0]}"
        return f"not run: {self.out_of_time or 'the run was interrupted'}"

    def _mark_not_run(self, report: RunReport) -> None:
        """A run that did not complete: every selected rule whose test did not run is listed
        as not run (could-not-test, never a pass); a failure already seen stays one."""
        from conformance.results import UnitReport

        name = str(self.unit)
        unit = report.units.get(name)
        if unit is None:
            u = self.unit
            unit = report.units[name] = UnitReport(name, u.agent_type, u.role, u.name)
        why = self.not_run_reason()
        not_run = []
        for rule in self.selected or list(CATALOGUE):
            if rule in self.ran:
                continue
            found = unit.rules.get(rule)
            if found is not None and found.verdict is Verdict.FAIL:
                continue
            unit.rules[rule] = RuleResult(rule, Verdict.COULD_NOT_TEST, why)
            not_run.append(rule)
        report.meta["not_run"] = " ".join(not_run)

    def verdict(self, report: RunReport) -> str:
        """The run's verdict: 'not certified' when the broker or the unit could not be
        reached, 'interrupted' when it did not complete, else the worst rule verdict."""
        if self.error:
            return NOT_CERTIFIED
        if self.interrupted:
            return INTERRUPTED
        return report.worst().value

    def counts(self, report: RunReport) -> dict[str, int]:
        """Verdict counts, with the rules that never ran counted as 'not run'."""
        counts = dict(report.verdict_counts())
        not_run = len(report.meta.get("not_run", "").split())
        if not_run:
            counts[Verdict.COULD_NOT_TEST.value] -= not_run
            counts["not run"] = not_run
        return counts

    def meta(self) -> dict[str, Any]:
        s = self.settings
        hb = self.traffic.latest("heartbeat")
        return {
            "broker": str(s.broker) if not s.embedded else f"embedded ({self.broker_url})",
            "started": self.started, "suite_version": __version__,
            "unit": str(self.unit), "seed": str(s.seed), "timing_scale": f"{s.timing_scale:g}",
            "profile_source": self.profile.source, "dry_run": str(s.dry_run).lower(),
            "allow_motion": str(s.allow_motion).lower(),
            "reboot": self._reboot_how() if self.context.reboot else "none",
            "agent_uuid": str(hb.get("agent-uuid")) if hb else "",
            "commands_sent": str(self.commander.sent_count + self.tst.sent_count),
            "tst_command_topic": s.tst_topic,
            "rerun": self.rerun_command(),
        }

    def rerun_command(self, rule: str | None = None) -> str:
        s = self.settings
        parts = ["pytest", "--unit", str(self.unit)]
        parts += ["--broker", str(s.broker)]
        parts += [f"--sim-fault={f}" for f in s.sim_faults]
        if s.embedded and s.sim_rate != 1.0:
            parts += ["--sim-rate", f"{s.sim_rate:g}"]
        if s.sim_tst:
            parts.append("--sim-tst")
        if s.tst_command_topic:
            parts += ["--tst-command-topic", s.tst_command_topic]
        if self.profile.source.startswith("<built-in"):
            if self.profile.name != "default":
                parts += ["--profile", self.profile.name]
        else:  # '=': a path in its own argument could be taken for a test path by pytest
            parts += [f"--profile={self.profile.source}"]
        if s.timing_scale != 1.0:
            parts += ["--timing-scale", f"{s.timing_scale:g}"]
        parts += ["--seed", str(s.seed)]
        observe = self._observe_for(rule) if rule else 0
        if observe or s.observe:
            parts += ["--observe", f"{max(observe, int(s.observe))}"]
        if rule:
            parts += ["-k", rule]
        return " ".join(parts)

    def _observe_for(self, rule: str) -> int:
        """Seconds of observation a rerun of ``rule`` needs: when its first violation came
        later than the passive window would last (a silence, a uuid change), as long as it
        took then, so that the rerun sees it too; else 0."""
        from conformance.scenarios import RULE_SCENARIO

        if rule in RULE_SCENARIO:
            return 0
        times = [v.time for v in self.result(rule).violations if v.time is not None]
        if not times:
            return 0
        took = min(times) - self.started
        rates = [r for r in (self.context.rate_of(k) for k in PERIODIC) if r]
        window = (self.profile.min_intervals + 2) / (min(rates) if rates else 1.0)
        return int(took) + 2 if took > window else 0

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
            if name not in ("ping", "robust") and scenario.level == "direct execution":
                self.run_scenario("ping")
                if not self._answers_commands():
                    for rule in scenario.rules:
                        self.record(rule, verdict=Verdict.COULD_NOT_TEST,
                                    reason="the unit answers no command: ping got no response "
                                    f"within {self.timing.response:.1f} s (EXEC-PING-001)")
                    self._done[name] = False
                    return
            self._wait_execution_info()
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
        self.events.append(f"{_clock(time.time())} {self.out_of_time}: the run stops here")

    def _fail_if_out_of_time(self) -> None:
        if self.out_of_time:
            pytest.fail(self.out_of_time, pytrace=False)

    def _settle(self) -> None:
        """Wait until the Monitor has judged what the TST conversations left open: one
        heartbeat of the unit after the latest deadline (none open: at once)."""
        from conformance.checks.tst_conversation import open_until

        with self._lock:
            until = open_until(self.monitor.state(self.unit), self.monitor.ctx)
        if until is None:
            return
        wait = until - time.time() + self.timing.periods(2, self.context.rate_of("heartbeat"))
        self.traffic.wait_for(lambda e: e.time > until, max(0.0, wait), subtopic="heartbeat")

    def _claims(self, level: str) -> bool:
        # ERR-008: a level written with an underscore is the same claim
        return level in (lv.replace("_", " ") for lv in self.context.levels())

    def _answers_commands(self) -> bool:
        if self.settings.dry_run:
            return True  # nothing was sent: let every scenario say what it would send
        return self.result("EXEC-PING-001").verdict is not Verdict.FAIL or bool(
            self.traffic.since(0, "exec/response"))

    def _wait_execution_info(self) -> None:
        """Before commanding: the unit's direct_execution_info (its tasks and signals)."""
        if self.traffic.latest("direct_execution_info") is None:
            rate = self.context.rate_of("heartbeat")
            self.traffic.wait_for(lambda e: True, self.timing.periods(3, rate),
                                  subtopic="direct_execution_info")

    def wait_passive_window(self) -> None:
        """Wait until the Monitor has judged every declared rate over at least the profile's
        ``min_intervals`` intervals (silences and gaps do not count) and every sensor that
        sensor_info lists has had its chance to be seen; deadline: twice that window plus 5 s.
        Then judge the end-of-run checks."""
        if self._passive_ready:
            return
        need = self.profile.min_intervals
        rates = [r for r in (self.context.rate_of(k) for k in PERIODIC) if r]
        slowest = min(rates) if rates else 1.0
        # --observe: at least that long since the run started (a rerun of a rule whose
        # evidence came late, e.g. a silence).
        observed_until = self._started_monotonic + self.settings.observe
        deadline = max(time.monotonic() + 2 * (need + 2) / slowest + 5.0, observed_until)

        period = 1.0 / slowest
        rates_ready: list[float] = []

        def enough() -> bool:
            if time.monotonic() < observed_until:
                return False
            if not rates_ready:
                unit = self.report().units.get(str(self.unit))
                if unit is None:
                    return False
                # RateStat.intervals counts silences in while too few others were seen:
                # more than need + silences means the others alone are enough.
                if any(s.declared_hz and s.intervals < need + s.silences for s in unit.rates):
                    return False
                rates_ready.append(time.monotonic())
            # SI-003: a listed sensor gets three more periods to show up, once. The Monitor's
            # view, not the topic's: it also reads 5.2's 'sensor.info' (ERR-001).
            with self._lock:
                state = self.monitor.state(self.unit)
                listed, seen = state.sensors_listed, set(state.sensors_seen)
            return listed is None or all(s in seen for s in listed) or \
                time.monotonic() - rates_ready[0] > 3 * period

        try:
            while not enough() and (left := deadline - time.monotonic()) > 0:
                # Look again after the next periodic message (at most one period from now).
                self.traffic.wait_for(lambda e: e.subtopic in PERIODIC, min(left, period),
                                      after=self.traffic.mark(),
                                      what=f"{need} intervals of every declared rate")
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
            if self.client is not None and self.client.is_connected and not self.settings.dry_run:
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
        if self.client is not None:
            self.client.close()
        if self.reference is not None:
            self.reference.stop()
            self.reference = None

    # --- what the header shows -----------------------------------------------------------------
    def header(self) -> list[str]:
        s = self.settings
        hb = self.context.heartbeat()
        levels = ", ".join(self.context.levels()) or "none declared"
        broker = str(s.broker) if not s.embedded else \
            f"embedded {self.broker_url} with the bundled reference unit" + (
                f" (faults: {', '.join(s.sim_faults)})" if s.sim_faults else "")
        safety = [f"role {self.unit.role}"]
        if self.unit.is_real:
            safety.append("motion tasks: " + (", ".join(self.profile.motion_tasks) or "none")
                          if s.allow_motion else "no task that moves the unit (no --allow-motion)")
        if s.dry_run:
            safety.append("DRY RUN: nothing is published")
        if "tst execution" in self.context.levels():
            safety.append(f"TST commands to {s.tst_topic}")
        return [
            f"waraps-conformance {__version__}: certifying {self.unit}",
            f"  broker:   {broker}",
            f"  profile:  {self.profile.name} ({self.profile.source}), timing scale "
            f"{s.timing_scale:g}",
            f"  unit:     agent-uuid {hb.get('agent-uuid', '?')}, agent-type "
            f"{hb.get('agent-type', '?')}, levels: {levels}",
            f"  reboot:   {self._reboot_how() if self.context.reboot else 'none (REBOOT-* could not test)'}",
            f"  safety:   {'; '.join(safety)}",
            f"  reports:  {self.settings.reports_dir / self.stem}.json / .html",
            f"  Using --seed={s.seed} (repeat this run: {self.rerun_command()})",
        ]


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t % 1 * 1000):03d}"


def _is_address(text: str) -> bool:
    try:
        UnitAddress.parse(text)
    except ValueError:
        return False
    return not text.startswith("/")


class _Probe:
    """A read-only look at ``<prefix>/#`` while waiting for the unit: which topics exist (with
    the first payload of each), for the error message when the unit is not there. Never
    publishes; keeps at most 500 topics and 64 KiB of each payload."""

    def __init__(self, broker: BrokerURL, unit: UnitAddress) -> None:
        self._topics: dict[str, bytes] = {}
        self._client: MqttClient | None = None
        self._broker, self._unit = broker, unit

    def start(self) -> None:
        def seen(m: Message) -> None:
            if m.topic not in self._topics and len(self._topics) < MAX_PROBE_TOPICS:
                self._topics[m.topic] = m.payload[:65536]
        try:
            self._client = MqttClient(self._broker, on_message=seen).connect()
            self._client.subscribe(f"{self._unit.prefix}/#")
            self._client.subscribe(f"/{self._unit.prefix}/#")  # TOPIC-001: a leading '/'
        except BrokerError:
            self._client = None

    def topics(self) -> dict[str, bytes]:
        return dict(self._topics)

    def close(self) -> None:
        if self._client is not None:
            self._client.close()


__all__ = ["CERTIFICATION", "COMMANDER_RULES", "Certification", "NotAlive"]

"""The pytest11 entry point: ``pytest --unit waraps/unit/air/simulation/dji0`` certifies a unit.

Importing this module is cheap and changes nothing unless ``--unit`` is given: the options
are declared, and that is all (every pytest run on the machine loads this entry point, so the
suite's modules are imported inside the hooks that need them). With ``--unit``, a
``Certification`` (``conformance.suite``) is registered for the run; with ``--unit`` and no
test paths, pytest runs exactly the conformance suite packaged in ``conformance.suite``, from
any working directory.
"""

from __future__ import annotations

import importlib.util
from typing import TYPE_CHECKING, Any

import pytest

from conformance.cli.options import BROKER_ENV, CREDENTIALS, TLS_FILES, TLS_INSECURE, parse_rate
from conformance.display import printable
from conformance.exits import EXIT_NOT_CERTIFIED, EXIT_UNTESTED
from conformance.masking import mask_password

if TYPE_CHECKING:
    from conformance.suite.session import Certification

SUITE_PACKAGE = "conformance.suite"
PLUGIN_NAME = "waraps-conformance-certification"
# Exit statuses: pytest's own (ExitCode 0-5) keep their meaning; one is added.
# The verdict model (conformance.conclusion) decides which; README 'Exit status' lists them.
CERTIFIED_EXIT = pytest.ExitCode.OK
"""0: a complete run certified every level the unit claims; or a partial run of selected rules
in which none failed (verdict 'partial', no level certified)."""
FAILED_EXIT = pytest.ExitCode.TESTS_FAILED
"""1: a rule failed."""
INTERRUPTED_EXIT = pytest.ExitCode.INTERRUPTED
"""2: interrupted (Ctrl-C, or --max-duration reached): not every rule ran."""
NOT_CERTIFIED_EXIT = EXIT_NOT_CERTIFIED  # README "Exit status"
"""6: not certified: the broker or the unit could not be reached, or the broker was lost for
good during the run."""
UNTESTED_EXIT = EXIT_UNTESTED
"""7: not certified: a complete run in which no rule failed, but a level the unit claims could
not be certified (a rule it needs could not be tested: no --reboot-cmd, no opt-in)."""
EXIT_HELP = ("exit status: 0 certified (every claimed level; with -k/--rule: no selected rule "
             "failed), 1 a rule failed, 2 interrupted (Ctrl-C or --max-duration), 4 usage "
             "error, 6 not certified (broker or unit unreachable, or the broker lost for good), "
             "7 not certified (no rule failed, but a rule a claimed level needs could not be "
             "tested); the last line says why")


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("waraps-conformance",
                            f"WARA-PS conformance (certify one unit; {EXIT_HELP})")
    _unit_options(group)
    _safety_options(group)
    _run_options(group)
    _reference_unit_options(group)
    _ini_options(parser)


def _unit_options(group: pytest.OptionGroup) -> None:
    """The unit, where it is, how it is reached (TLS: the same options as every subcommand
    that connects, ``conformance.cli.options``), what it claims and how it is rebooted."""
    group.addoption("--unit", dest="waraps_unit", default=None, metavar="ADDRESS",
                    help="certify this unit, e.g. waraps/unit/air/simulation/dji0 (switches the "
                         "plugin on; without test paths, runs the packaged conformance suite)")
    group.addoption("--broker", dest="waraps_broker", default=None, metavar="URL",
                    help=f"mqtt://HOST:PORT, mqtts://HOST:PORT or embedded (the embedded broker "
                         f"with the bundled reference unit). Default: {BROKER_ENV}; "
                         f"{CREDENTIALS}")
    # The same TLS options as every subcommand that connects (conformance.cli.options).
    for option, help_ in TLS_FILES:
        group.addoption(option, dest="waraps_" + option[2:].replace("-", "_"), default=None,
                        metavar="PEM", help=help_)
    group.addoption(TLS_INSECURE[0], dest="waraps_tls_insecure", action="store_true",
                    default=False, help=TLS_INSECURE[1])
    group.addoption("--profile", dest="waraps_profile", default=None, metavar="NAME|FILE",
                    help="what the unit claims and how to test it: a built-in profile "
                         "(default, strict, ...) or a YAML file")
    group.addoption("--timing-scale", dest="waraps_timing_scale", default=None, metavar="X",
                    help="multiply every deadline by X (slow links); default 1")
    group.addoption("--reboot-cmd", dest="waraps_reboot_cmd", default=None, metavar="CMD",
                    help="shell command that reboots the unit (REBOOT-*; without it they are "
                         "could-not-test)")


def _safety_options(group: pytest.OptionGroup) -> None:
    """What the suite may send to a real unit (docs/ARCHITECTURE.md 'Safety'), and how strict it
    judges."""
    group.addoption("--allow-motion", dest="waraps_allow_motion", action="store_true",
                    default=False, help="let the suite start the profile's motion-tasks on a "
                                        "real unit (every role but 'simulation' and the "
                                        "profile's simulated-roles)")
    group.addoption("--allow-hostile", dest="waraps_allow_hostile", action="store_true",
                    default=False, help="let the suite send hostile and malformed payloads "
                                        "(the robustness probes) to a real unit; the profile's "
                                        "robustness: true does the same")
    group.addoption("--dry-run", dest="waraps_dry_run", action="store_true", default=False,
                    help="publish nothing; print what would be published")
    group.addoption("--strict-rules", dest="waraps_strict_rules", action="store_true",
                    default=False, help="adopt the suite's decisions as conventions: a rule "
                                        "whose basis is 'decided' (the spec is silent) fails "
                                        "instead of warning (as 'strict: true' in the profile)")


def _run_options(group: pytest.OptionGroup) -> None:
    """The run: its reports, seed, length, observation, exploration and rules selected."""
    group.addoption("--reports-dir", dest="waraps_reports_dir", default=None, metavar="DIR",
                    help="where the JSON and HTML certification reports go (default reports/)")
    group.addoption("--seed", dest="waraps_seed", default=None, metavar="N",
                    help="seed for generated task parameters (the header shows each run's)")
    group.addoption("--max-duration", dest="waraps_max_duration", default=None,
                    metavar="DURATION", help="stop the run cleanly after this long (600, 90s, "
                    "10m, 1h; default 10m): the test waiting fails saying for what, started "
                    "tasks are aborted, reports are written, exit status 2")
    group.addoption("--observe", dest="waraps_observe", default=None, metavar="DURATION",
                    help="observe the unit at least this long before judging the passive "
                         "rules (a rerun line adds it when the evidence came late)")
    group.addoption("--explore", dest="waraps_explore", default=None, metavar="DURATION",
                    help="after the scripted scenarios, explore command orders this long "
                         "(hypothesis; 90s, 2m; default: 50 heartbeat periods of the unit, "
                         "at least 20 s and at most 50 s; 0: off)")
    group.addoption("--explore-order", dest="waraps_explore_order", default="model",
                    choices=("model", "random"), help="how exploration orders what it may "
                    "send next: 'model' (default) the most telling first in the protocol "
                    "model's view; 'random' a random order (to measure what the model's "
                    "guidance adds: bench/bench_explore.py --order random)")
    group.addoption("--explore-replay", dest="waraps_explore_replay", default=None,
                    metavar="FILE", help="replay the story a failing exploration stored "
                    "(reports/*-explore.json) instead of exploring")
    group.addoption("--rule", dest="waraps_rules", action="append", default=None,
                    metavar="ID", help="judge only this rule (repeatable), running the "
                    "scenarios that produce its evidence; like -k ID, but exact")


def _reference_unit_options(group: pytest.OptionGroup) -> None:
    """The bundled reference unit's switches (--broker embedded), and where TST commands go."""
    group.addoption("--sim-fault", dest="waraps_sim_faults", action="append", default=None,
                    metavar="FAULT", help="with --broker embedded: switch on a fault of the "
                                          "bundled reference unit (repeatable)")
    group.addoption("--sim-variant", dest="waraps_sim_variants", action="append", default=None,
                    metavar="VARIANT", help="with --broker embedded: switch on a conformant "
                    "variant of the bundled reference unit (repeatable; waraps-conformance sim "
                    "--list-variants lists them)")
    group.addoption("--sim-rate", dest="waraps_sim_rate", type=parse_rate, default=None,
                    metavar="HZ", help="with --broker embedded: the reference unit's rate")
    group.addoption("--sim-tst", dest="waraps_sim_tst", action="store_true", default=False,
                    help="with --broker embedded: the reference unit declares 'tst execution' "
                         "and runs TST trees (14)")
    group.addoption("--tst-command-topic", dest="waraps_tst_command_topic", default=None,
                    metavar="own|ADDRESS", help="where TST commands go (14.1): 'own' (the "
                    "unit's tst/command, the default) or an operator's address or tst/command "
                    "topic, e.g. waraps/unit/ground/real/op0; the suite publishes there and "
                    "to the unit's exec/command, nowhere else")


def _ini_options(parser: pytest.Parser) -> None:
    """The ini twin of every option a project would set once (every option has one, so a project's
    ini says what its command lines would)."""
    for name, help_ in (
            ("waraps_broker", "default for --broker"), ("waraps_profile", "default for --profile"),
            ("waraps_timing_scale", "default for --timing-scale"),
            ("waraps_reboot_cmd", "default for --reboot-cmd"),
            ("waraps_reports_dir", "default for --reports-dir"),
            ("waraps_ca_file", "default for --ca-file"),
            ("waraps_cert_file", "default for --cert-file"),
            ("waraps_key_file", "default for --key-file"),
            ("waraps_tst_command_topic", "default for --tst-command-topic"),
            ("waraps_max_duration", "default for --max-duration (10m)"),
            ("waraps_explore", "default for --explore (0: off)")):
        parser.addini(name, help_, default="")
    for name, help_ in (("waraps_allow_motion", "default for --allow-motion"),
                        ("waraps_allow_hostile", "default for --allow-hostile"),
                        ("waraps_dry_run", "default for --dry-run"),
                        ("waraps_strict_rules", "default for --strict-rules"),
                        ("waraps_tls_insecure", "default for --tls-insecure")):
        parser.addini(name, help_, type="bool", default=False)


def pytest_addhooks(pluginmanager: pytest.PytestPluginManager) -> None:
    from conformance.suite import hooks

    pluginmanager.add_hookspecs(hooks)


def suite_path() -> str:
    """The folder of the packaged conformance suite (found without importing it)."""
    spec = importlib.util.find_spec(SUITE_PACKAGE)
    assert spec is not None and spec.submodule_search_locations
    return list(spec.submodule_search_locations)[0]


@pytest.hookimpl(tryfirst=True)
def pytest_load_initial_conftests(early_config: pytest.Config, parser: pytest.Parser,
                                  args: list[str]) -> None:
    """``--unit`` without test paths: collect the packaged suite, not the project's testpaths
    (pytest would otherwise take ``testpaths`` or the current directory: ArgsSource)."""
    ns = early_config.known_args_namespace
    if getattr(ns, "waraps_unit", None) and not ns.file_or_dir:
        path = suite_path()
        args.append(path)
        ns.file_or_dir = [path]


def pytest_configure(config: pytest.Config) -> None:
    if not config.getoption("waraps_unit", None):
        return
    if config.getoption("numprocesses", None) or config.getoption("dist", "no") != "no":
        raise pytest.UsageError("the certification suite drives one unit from one process: "
                                "leave out -n/--dist (pytest-xdist)")
    from conformance.suite.session import CERTIFICATION, Certification
    from conformance.suite.settings import read

    config.addinivalue_line("markers", "waraps_rule(rule_id): the rule this test judges")
    config.addinivalue_line("markers", "waraps_explore: the exploration (runs after the "
                                       "scripted scenarios)")
    try:
        settings = read(config)
    except pytest.UsageError as e:  # it repeats what was typed: escaped, never a password
        raise pytest.UsageError(printable(mask_password(str(e)))) from None
    certification = Certification(config, settings)
    config.stash[CERTIFICATION] = certification
    config.pluginmanager.register(_CertificationPlugin(certification), PLUGIN_NAME)


class _CertificationPlugin:
    """The hooks of one certification run (registered only with ``--unit``)."""

    def __init__(self, certification: Certification) -> None:
        self.certification = certification
        self.finished = False
        self.status: int | None = None
        """The run's exit status, once the session finished."""
        self.session: pytest.Session | None = None
        self.explore_outcome = ""
        """test_explore's outcome in the suite's words (it judges no rule of its own)."""

    @pytest.hookimpl(tryfirst=True)
    def pytest_sessionstart(self, session: pytest.Session) -> None:
        """Before anything else: the broker is reachable and the unit alive. Otherwise ONE
        clear error (in the summary), no test runs, and the run is not certified."""
        from conformance.client import BrokerError
        from conformance.suite.session import NotAlive

        self.session = session
        c = self.certification
        if session.config.getoption("collectonly", False):
            c.collect_only = True  # listing the tests needs no broker and no unit
            return
        try:
            c.start()
        except (BrokerError, NotAlive) as e:
            c.error = str(e)

    def pytest_report_header(self, config: pytest.Config) -> list[str]:
        return self.certification.header()

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, config: pytest.Config,
                                      items: list[pytest.Item]) -> None:
        """``--rule``: only those rules. Active scenarios first, in the order of
        ``SCENARIOS`` (reboot last: it wipes the unit's history); the passive rules at the
        end, over the whole observation."""
        from conformance.rules import CATALOGUE
        from conformance.scenarios import RULE_SCENARIO, SCENARIOS

        def rule_of(item: pytest.Item) -> str | None:
            marker = item.get_closest_marker("waraps_rule")
            return marker.args[0] if marker is not None else None

        wanted = self.certification.settings.rules
        if wanted:
            dropped = [i for i in items if rule_of(i) not in wanted]
            if dropped:
                items[:] = [i for i in items if rule_of(i) in wanted]
                config.hook.pytest_deselected(items=dropped)
        order = {name: i for i, name in enumerate(SCENARIOS)}

        def key(item: pytest.Item) -> tuple[int, int]:
            rule = rule_of(item)
            if item.get_closest_marker("waraps_explore") is not None:
                return (1, len(order))  # after the scripted scenarios
            if rule is None:
                return (0, 0)
            if rule in RULE_SCENARIO:
                return (1, order[RULE_SCENARIO[rule]])
            return (2, 0)

        items.sort(key=key)  # stable: the file order within each group stays
        c = self.certification
        c.evidence.selected = [r for r in map(rule_of, items) if r]
        if set(c.evidence.selected) != set(CATALOGUE):  # -k, -m, --rule or test ids: a partial run
            c.selection = c.settings.selection_words() or "not every rule's test was selected"

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtestloop(self, session: pytest.Session) -> bool | None:
        """No broker or no unit: no test runs (the summary says why, once)."""
        return True if self.certification.error else None

    @pytest.hookimpl(wrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item,
                                  call: pytest.CallInfo[None]) -> Any:
        from conformance.suite.verdict import locate_skip

        report = yield
        locate_skip(item, report)
        return report

    @pytest.hookimpl(tryfirst=True)  # before pytest writes the result: our line goes first
    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        c = self.certification
        c.progress.clear()
        if report.nodeid.endswith("::test_explore") and (
                report.when == "call" or report.outcome != "passed"):
            from conformance.suite.summary import explore_outcome

            self.explore_outcome = explore_outcome(report, c.explored)
        marker = report.keywords.get("waraps_rule") if report.when == "call" or (
            report.when == "setup" and report.outcome != "passed") else None
        if marker is not None:
            rule = report.nodeid.rsplit("[", 1)[-1].rstrip("]")
            c.evidence.ran.add(rule)
        if c.out_of_time and self.session is not None:
            self.session.shouldstop = c.out_of_time
        if c.broker_lost is not None and self.session is not None:
            self.session.shouldstop = c.facts().not_run_reason()

    @pytest.hookimpl(tryfirst=True)
    def pytest_sessionfinish(self, session: pytest.Session, exitstatus: int) -> None:
        """Abort every task the suite started (also after a failure or Ctrl-C), write the
        final reports, and say in the exit status whether the unit could be certified."""
        self.finished = True
        c = self.certification
        # The run stopped for a lost broker is not a Ctrl-C (its verdict says why).
        interrupted = (exitstatus == pytest.ExitCode.INTERRUPTED and c.broker_lost is None
                       ) or bool(c.out_of_time)
        session.exitstatus = c.finish(interrupted=interrupted, exitstatus=int(exitstatus))
        self.status = int(session.exitstatus)

    def pytest_unconfigure(self, config: pytest.Config) -> None:
        if not self.finished:  # a usage error or an internal error before the session
            self.finished = True
            self.certification.finish(interrupted=True, exitstatus=-1)
        elif self.status is not None and not self.certification.collect_only:
            self._say_exit(config, self.status)

    def _say_exit(self, config: pytest.Config, status: int) -> None:
        """The last line the terminal prints, after pytest's own counts (README 'Exit
        status')."""
        from conformance.suite.summary import exit_line

        tr = config.pluginmanager.get_plugin("terminalreporter")
        if tr is not None:
            tr.write_line(exit_line(self.certification, status),
                          green=status == 0, red=status != 0)

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        from conformance.suite.summary import write_summary

        if not self.certification.collect_only:
            write_summary(self.certification, terminalreporter, self.explore_outcome)

"""The certification run's settings, read from pytest's options and ini file.

Every value is checked here, once: a bad one is a ``pytest.UsageError`` that says what is
wrong and lists the valid values ("did you mean ..."). Passwords come only from the
environment (``WARAPS_PASSWORD``), never from an option.
"""

from __future__ import annotations

import dataclasses
import difflib
import os
import secrets
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from conformance.cli.options import parse_duration, reports_dir_problem
from conformance.client import BrokerURL, mask_password
from conformance.profile import Profile, ProfileError, builtin_names, load
from conformance.rules import CATALOGUE
from conformance.scenarios import story
from conformance.topics import TopicError, UnitAddress

# option dest -> ini name (the ini twin of every option but --unit and --seed)
INI = {
    "waraps_broker": "waraps_broker",
    "waraps_profile": "waraps_profile",
    "waraps_timing_scale": "waraps_timing_scale",
    "waraps_reboot_cmd": "waraps_reboot_cmd",
    "waraps_allow_motion": "waraps_allow_motion",
    "waraps_allow_hostile": "waraps_allow_hostile",
    "waraps_dry_run": "waraps_dry_run",
    "waraps_strict_rules": "waraps_strict_rules",
    "waraps_reports_dir": "waraps_reports_dir",
    "waraps_ca_file": "waraps_ca_file",
    "waraps_cert_file": "waraps_cert_file",
    "waraps_key_file": "waraps_key_file",
    "waraps_tls_insecure": "waraps_tls_insecure",
    "waraps_tst_command_topic": "waraps_tst_command_topic",
    "waraps_max_duration": "waraps_max_duration",
    "waraps_explore": "waraps_explore",
}
MAX_DURATION = 600.0
"""Seconds a certification may last by default (--max-duration): then it stops cleanly."""
TRUE = ("1", "true", "yes", "on")
FALSE = ("", "0", "false", "no", "off")


@dataclass(frozen=True)
class Settings:
    """What one certification run needs to know. Times in seconds, rates in Hz."""

    unit: UnitAddress
    broker: BrokerURL
    profile: Profile
    timing_scale: float = 1.0
    reboot_cmd: str | None = None
    allow_motion: bool = False
    allow_hostile: bool = False
    """--allow-hostile: hostile and malformed payloads may go to a real unit
    (docs/ARCHITECTURE.md 'Safety')."""
    dry_run: bool = False
    strict_rules: bool = False
    """--strict-rules: decided rules fail (the profile is made strict)."""
    reports_dir: Path = Path("reports")
    seed: int = 0
    sim_faults: tuple[str, ...] = ()
    """--broker embedded runs the bundled reference unit; these are its fault switches."""
    sim_variants: tuple[str, ...] = ()
    """--broker embedded: the reference unit's conformant variants (--sim-variant)."""
    sim_rate: float = 1.0
    sim_tst: bool = False
    """--broker embedded: the reference unit declares 'tst execution' and runs trees (14)."""
    tst_command_topic: str | None = None
    """Where start-tst and the TST signals go (14.1): an operator's tst/command such as
    ``.../op0/tst/command``; None: the unit's own."""
    max_duration: float = MAX_DURATION
    """Seconds: past it the run stops, failing the test that waits (--max-duration)."""
    observe: float = 0.0
    """--observe: seconds to observe the unit at least before the passive rules are judged."""
    rules: tuple[str, ...] = ()
    """--rule: only these rules are judged (and the scenarios that produce their evidence)."""
    keyword: str = ""
    """pytest's -k expression: a selection too (a partial run, its rerun line keeps it)."""
    markexpr: str = ""
    """pytest's -m expression."""
    explore: float | None = None
    """--explore: seconds of exploration after the scripted scenarios; None: the
    default (``suite.exploration.default_budget``), 0: off."""
    explore_order: str = "model"
    """--explore-order: 'model' (the most telling command first) or 'random'."""
    explore_replay: Path | None = None
    """--explore-replay: the stored story the exploration replays instead of exploring."""
    extra: dict[str, str] = field(default_factory=dict)

    @property
    def tst_topic(self) -> str:
        """The one tst/command topic the suite publishes TST commands to."""
        return self.tst_command_topic or self.unit.topic("tst/command")

    @property
    def tst_operator(self) -> UnitAddress | None:
        """The operator whose tst/command is used (14.1), or None (the unit's own)."""
        if self.tst_command_topic is None:
            return None
        return UnitAddress.parse(self.tst_command_topic.rsplit("/", 2)[0])

    @property
    def embedded(self) -> bool:
        """The bundled reference unit runs here: --broker embedded, or the test suite's
        --broker virtual (the same pair in virtual time, ``conformance.sim.virtual``)."""
        return self.broker.scheme in ("embedded", "virtual")

    @property
    def virtual(self) -> bool:
        return self.broker.scheme == "virtual"

    def rerun_command(self, rule: str | None = None, observe: float = 0.0) -> str:
        """The pytest command that repeats this run (``rule``: only that rule, observing at
        least ``observe`` seconds): every option that changes what is tested or how, TLS
        files included. Never a secret: the broker URL carries no password (the password
        comes only from WARAPS_PASSWORD), a reboot command's is masked."""
        b = self.broker
        # '=' for paths: a path in its own argument could be taken for a test path by pytest.
        q = shlex.quote  # every value shell-quoted: a unit name may be `x;rm -rf ~`
        parts = ["pytest", "--unit", q(str(self.unit)), "--broker", q(str(b))]
        parts += b.tls_arguments()
        parts += self._reference_unit_options()
        if self.tst_command_topic:
            parts += ["--tst-command-topic", q(self.tst_command_topic)]
        if self.profile.source.startswith("<built-in"):
            if self.profile.name != "default":
                parts += ["--profile", q(self.profile.name)]
        else:
            parts += [f"--profile={q(self.profile.source)}"]
        if self.timing_scale != 1.0:
            parts += ["--timing-scale", f"{self.timing_scale:g}"]
        if self.reboot_cmd:  # a password in it (curl https://u:pw@...) is never printed
            parts += ["--reboot-cmd", q(mask_password(self.reboot_cmd))]
        if self.allow_motion:
            parts.append("--allow-motion")
        if self.allow_hostile:
            parts.append("--allow-hostile")
        if self.dry_run:
            parts.append("--dry-run")
        if self.strict_rules:
            parts.append("--strict-rules")
        if self.max_duration != MAX_DURATION:
            parts += ["--max-duration", f"{self.max_duration:g}"]
        parts += ["--seed", str(self.seed)]
        parts += self._explore_options()
        if observe or self.observe:
            parts += ["--observe", f"{max(int(observe), int(self.observe))}"]
        if rule:
            parts += ["-k", q(rule)]
        else:
            parts += [w for w in [self.selection_words()] if w]
        return " ".join(parts)

    def _reference_unit_options(self) -> list[str]:
        """The reference unit's options of the rerun line: its faults, variants, rate, TST."""
        q = shlex.quote
        parts = [q(f"--sim-fault={f}") for f in self.sim_faults]
        parts += [q(f"--sim-variant={v}") for v in self.sim_variants]
        if self.embedded and self.sim_rate != 1.0:
            parts += ["--sim-rate", f"{self.sim_rate:g}"]
        if self.sim_tst:
            parts.append("--sim-tst")
        return parts

    def _explore_options(self) -> list[str]:
        """The exploration's options of the rerun line: its budget, order and replay."""
        parts = []
        if self.explore is not None:
            parts += ["--explore", f"{self.explore:g}"]
        if self.explore_order != "model":
            parts += ["--explore-order", self.explore_order]
        if self.explore_replay is not None:
            parts += [f"--explore-replay={shlex.quote(str(self.explore_replay))}"]
        return parts

    def selection_words(self) -> str:
        """How this run selects rules, as options of its command line (shell-quoted): ``-k
        'HB-003 or HB-012'``, ``--rule=HB-003``; '' when it selects none."""
        parts = [shlex.quote(f"--rule={r}") for r in self.rules]
        if self.keyword:
            parts.append(f"-k {shlex.quote(self.keyword)}")
        if self.markexpr:
            parts.append(f"-m {shlex.quote(self.markexpr)}")
        return " ".join(parts)


def _value(config: pytest.Config, dest: str) -> object:
    """An option's value, else its ini twin's (None when neither is set)."""
    value = config.getoption(dest, None)
    if value not in (None, False) or dest not in INI:
        return value
    ini = config.getini(INI[dest])
    return ini if ini not in ("", None, []) else value


def _flag(config: pytest.Config, dest: str) -> bool:
    value = _value(config, dest)
    if isinstance(value, bool) or value is None:
        return bool(value)
    text = str(value).strip().lower()
    if text in TRUE:
        return True
    if text in FALSE:
        return False
    raise pytest.UsageError(f"ini {INI[dest]} = {value!r}: not a boolean; valid: "
                            f"{', '.join(TRUE + FALSE[1:])}")


def _did_you_mean(value: str, valid: list[str]) -> str:
    close = difflib.get_close_matches(value, valid, n=2)
    return f" (did you mean {' or '.join(close)}?)" if close else ""


def read(config: pytest.Config) -> Settings:
    """The settings of this run, or ``pytest.UsageError`` naming the bad value."""
    text = str(config.getoption("waraps_unit"))
    try:
        unit = UnitAddress.parse(text)
    except TopicError as e:
        raise pytest.UsageError(f"--unit: {e}") from None
    broker = _broker(config)
    profile_name = str(_value(config, "waraps_profile") or "default")
    try:
        profile = load(profile_name)
    except ProfileError as e:
        raise pytest.UsageError(f"--profile: {e}") from None
    strict_rules = _flag(config, "waraps_strict_rules")
    if strict_rules:
        profile = dataclasses.replace(profile, strict=True)
    scale = _timing_scale(_value(config, "waraps_timing_scale"))
    reboot = _value(config, "waraps_reboot_cmd")
    reports = _reports_dir(config)
    seed = _seed(config.getoption("waraps_seed", None))
    faults, variants, sim_rate, sim_tst = _sim_switches(config, broker.scheme)
    tst_topic = _tst_command_topic(_value(config, "waraps_tst_command_topic"), unit)
    return Settings(unit=unit, broker=broker, profile=profile, timing_scale=scale,
                    max_duration=_duration(_value(config, "waraps_max_duration")),
                    rules=_rules(config.getoption("waraps_rules", None) or ()),
                    keyword=str(config.getoption("keyword", "") or ""),
                    markexpr=str(config.getoption("markexpr", "") or ""),
                    observe=_duration(config.getoption("waraps_observe", None), 0.0, "--observe"),
                    explore=_explore(_value(config, "waraps_explore")),
                    explore_order=str(config.getoption("waraps_explore_order", None)
                                      or "model"),
                    explore_replay=_replay(config, reports),
                    reboot_cmd=str(reboot) if reboot else None,
                    allow_motion=_flag(config, "waraps_allow_motion"),
                    allow_hostile=_flag(config, "waraps_allow_hostile"),
                    dry_run=_flag(config, "waraps_dry_run"), strict_rules=strict_rules,
                    reports_dir=reports, seed=seed,
                    sim_faults=faults, sim_variants=variants, sim_rate=sim_rate, sim_tst=sim_tst,
                    tst_command_topic=tst_topic)


def _timing_scale(scale_text: object) -> float:
    """--timing-scale: a positive factor of every deadline (1 when not given)."""
    try:
        scale = float(scale_text) if scale_text not in (None, "") else 1.0  # type: ignore[arg-type]
    except (TypeError, ValueError):
        scale = -1.0
    if not scale > 0 or scale != scale or scale == float("inf"):
        raise pytest.UsageError(f"--timing-scale {scale_text!r}: a positive number is needed "
                                f"(1 = the profile's deadlines, 3 = three times as long, for a "
                                f"slow link)")
    return scale


def _reports_dir(config: pytest.Config) -> Path:
    """--reports-dir, relative to where pytest was started, writable (made unless only
    collecting: listing writes nothing)."""
    reports = Path(str(_value(config, "waraps_reports_dir") or "reports"))
    if not reports.is_absolute():
        reports = Path(config.invocation_params.dir) / reports
    problem = reports_dir_problem(reports, create=not config.getoption("collectonly", False))
    if problem:
        raise pytest.UsageError(problem)
    return reports


def _seed(seed_text: object) -> int:
    """--seed, or a random one (the header shows it, so the run can be repeated)."""
    if seed_text is None:
        return secrets.randbelow(10**9)
    try:
        return int(seed_text)  # type: ignore[call-overload]
    except ValueError:
        raise pytest.UsageError(f"--seed {seed_text!r}: a whole number is needed "
                                f"(the header of an earlier run shows its seed)") from None


def _sim_switches(config: pytest.Config,
                  scheme: str) -> tuple[tuple[str, ...], tuple[str, ...], float, bool]:
    """The reference unit's switches (--sim-fault, --sim-variant, --sim-rate, --sim-tst):
    only with the bundled reference unit (--broker embedded, or virtual in the tests)."""
    faults = tuple(config.getoption("waraps_sim_faults", None) or ())
    if faults and scheme not in ("embedded", "virtual"):
        raise pytest.UsageError("--sim-fault switches a fault of the bundled reference unit, "
                                "which runs only with --broker embedded")
    if faults:
        from conformance.sim import FAULTS

        for name in faults:
            if name not in FAULTS:
                raise pytest.UsageError(
                    f"--sim-fault {name!r} is not a fault of the reference unit"
                    f"{_did_you_mean(name, list(FAULTS))}; valid: {', '.join(sorted(FAULTS))}")
    variants = tuple(config.getoption("waraps_sim_variants", None) or ())
    if variants and scheme not in ("embedded", "virtual"):
        raise pytest.UsageError("--sim-variant switches a variant of the bundled reference "
                                "unit, which runs only with --broker embedded")
    if variants:
        from conformance.sim.variants import VariantError, check_variants

        try:
            check_variants(variants)
        except VariantError as e:
            raise pytest.UsageError(f"--sim-variant: {e}") from None
        if scheme == "embedded" and "mqtt5-qos1" in variants:
            raise pytest.UsageError(
                "--sim-variant mqtt5-qos1: the embedded amqtt broker refuses MQTT 5; run the "
                "reference unit on a broker that speaks it (waraps-conformance sim --variant "
                "mqtt5-qos1 --broker mqtt://HOST:PORT) and certify it there")
    sim_rate = config.getoption("waraps_sim_rate", None) or 1.0
    if not sim_rate > 0:
        raise pytest.UsageError(f"--sim-rate {sim_rate!r}: a positive rate in Hz is needed")
    sim_tst = bool(config.getoption("waraps_sim_tst", False))
    if sim_tst and scheme not in ("embedded", "virtual"):
        raise pytest.UsageError("--sim-tst switches on the TST level of the bundled reference "
                                "unit, which runs only with --broker embedded")
    return faults, variants, float(sim_rate), sim_tst


def _tst_command_topic(value: object, unit: UnitAddress) -> str | None:
    """--tst-command-topic: 'own' (the unit's tst/command), an operator's address
    (``waraps/unit/ground/real/op0``) or its tst/command topic; None for the unit's own."""
    text = str(value or "").strip().rstrip("/")
    if text in ("", "own") or text == unit.topic("tst/command"):
        return None
    base = text[:-len("/tst/command")] if text.endswith("/tst/command") else text
    try:
        operator = UnitAddress.parse(base)
    except TopicError as e:
        raise pytest.UsageError(
            f"--tst-command-topic {text!r}: {e}; give 'own' (the unit's tst/command) or an "
            f"operator's address, e.g. {unit.prefix}/unit/ground/real/op0 (14.1)") from None
    if operator == unit:
        return None
    return operator.topic("tst/command")


def _duration(value: object, default: float = MAX_DURATION,
              option: str = "--max-duration") -> float:
    """A duration option in seconds, read as every subcommand reads one (``parse_duration``:
    600, 90s, 10m, 10min, 1h, 1h30m)."""
    if value in (None, ""):
        return default
    try:
        return parse_duration(str(value))
    except ValueError:
        raise pytest.UsageError(f"{option} {value!r}: a positive duration is needed, "
                                f"e.g. 600, 90s, 10m or 1h") from None


def _explore(value: object) -> float | None:
    """--explore: a duration (0 or off: no exploration); None: the default budget."""
    if value in (None, ""):
        return None
    if str(value).strip().lower() in ("0", "0s", "off", "no"):
        return 0.0
    return _duration(value, option="--explore")


def _replay(config: pytest.Config, reports: Path) -> Path | None:
    """--explore-replay FILE: a story an earlier run stored (relative to the working folder)."""
    value = config.getoption("waraps_explore_replay", None)
    if not value:
        return None
    path = Path(str(value))
    if not path.is_absolute():
        path = Path(config.invocation_params.dir) / path
    if not path.is_file():
        raise pytest.UsageError(f"--explore-replay {value}: no such file (a failing "
                                f"exploration stores its story under {reports})")
    try:  # read now: a story that is none is a usage error, before anything runs
        story.load(path)
    except story.StoryError as e:
        raise pytest.UsageError(f"--explore-replay: {e}") from None
    return path


def _rules(values: object) -> tuple[str, ...]:
    """``--rule``: rule ids of the catalogue (also comma-separated)."""
    out: list[str] = []
    for value in values:  # type: ignore[attr-defined]
        for rule in filter(None, (r.strip().upper() for r in str(value).split(","))):
            if rule not in CATALOGUE:
                raise pytest.UsageError(f"--rule {rule!r} is not a rule of the catalogue"
                                        f"{_did_you_mean(rule, list(CATALOGUE))} "
                                        f"(waraps-conformance rules lists them)")
            out.append(rule)
    return tuple(dict.fromkeys(out))


def _broker(config: pytest.Config) -> BrokerURL:
    text = _value(config, "waraps_broker")
    try:
        if text:
            broker = BrokerURL.parse(str(text))
        else:
            found = BrokerURL.from_env()
            if found is None:
                raise pytest.UsageError(
                    "no broker: pass --broker mqtt://HOST:PORT, mqtts://HOST:PORT or embedded "
                    "(or set WARAPS_BROKER, WARAPS_PORT, WARAPS_TLS_CONNECTION)")
            broker = found
    except ValueError as e:
        # Never echo a password, even the one a user wrongly put into the URL.
        raise pytest.UsageError(f"--broker: {mask_password(str(e))}") from None
    files = {k: _value(config, f"waraps_{k}") for k in ("ca_file", "cert_file", "key_file")}
    for key, path in files.items():
        if path and not os.path.isfile(str(path)):
            raise pytest.UsageError(f"--{key.replace('_', '-')} {path}: no such file")
    insecure = _flag(config, "waraps_tls_insecure")
    if any(files.values()) or insecure:
        if broker.scheme != "mqtts":
            raise pytest.UsageError("--ca-file, --cert-file, --key-file and --tls-insecure "
                                    "need an mqtts:// broker")
        ca, cert, private = (str(v) if v else None for v in files.values())
        broker = broker.with_tls_files(ca, cert, private, insecure=insecure)
    return broker


def profile_names() -> list[str]:
    return builtin_names()

"""The rerun line (``conformance.suite.header.repeat_command``): it repeats every option that
changes what the run judges, and a failure's line selects its rule alone. Run for real (a rule
failing again) in ``test_plugin_faults.py``; here the line itself, with no broker."""

from __future__ import annotations

from pathlib import Path

from conformance.client import BrokerURL
from conformance.profile import load
from conformance.suite.header import repeat_command
from conformance.suite.settings import Settings
from conformance.topics import UnitAddress

UNIT = "waraps/unit/air/simulation/dji0"
FAST = Path(__file__).parent / "profiles" / "fast.yaml"


def settings(broker: str = "mqtt://127.0.0.1:1883", profile: str | Path = "default",
             **options: object) -> Settings:
    return Settings(UnitAddress.parse(UNIT), BrokerURL.parse(broker), load(profile), seed=3,
                    **options)  # type: ignore[arg-type]


def test_the_run_is_repeated_with_its_seed() -> None:
    assert repeat_command(settings()) == \
        f"pytest --unit {UNIT} --broker mqtt://127.0.0.1:1883 --seed 3"


def test_a_rule_is_rerun_alone_observed_as_long_as_its_evidence_took() -> None:
    assert repeat_command(settings(), "HB-010", observe=42) == \
        f"pytest --unit {UNIT} --broker mqtt://127.0.0.1:1883 --seed 3 --observe 42 -k HB-010"
    # --observe of the run itself is kept when it is longer.
    assert repeat_command(settings(observe=60.0), "HB-010", observe=42).endswith(
        "--seed 3 --observe 60 -k HB-010")


def test_the_reference_unit_and_the_profile_are_repeated() -> None:
    line = repeat_command(settings("embedded", FAST, sim_faults=("abort-ignored",),
                                   sim_rate=5.0, sim_tst=True, timing_scale=2.0),
                          "EXEC-SIG-002")
    assert line == (f"pytest --unit {UNIT} --broker embedded --sim-fault=abort-ignored "
                    f"--sim-rate 5 --sim-tst --profile={FAST} --timing-scale 2 --seed 3 "
                    "-k EXEC-SIG-002")
    assert "--profile strict" in repeat_command(settings(profile="strict"))

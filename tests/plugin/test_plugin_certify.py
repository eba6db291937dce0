"""The reference unit passes the certification, end to end, on both real brokers."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from certify_helpers import FAST, UNIT, Rebooter, certify

from conformance.rules import CATALOGUE, Mode
from conformance.sim import SimUnit
from conformance.topics import UnitAddress

pytestmark = pytest.mark.slow


def test_reference_unit_passes_on_the_embedded_broker(pytester: pytest.Pytester) -> None:
    junit = pytester.path / "junit.xml"
    run = certify(pytester, "--unit", UNIT, "--broker", "embedded", "--sim-rate", "3",
                  f"--profile={FAST}", "--seed", "7", f"--junitxml={junit}")
    assert run.result.ret == 0, run.text
    assert not run.failed
    # Every rule has a test, and every active rule was really examined (not skipped).
    assert set(run.outcomes) == set(CATALOGUE)
    active = {r for r, rule in CATALOGUE.items() if rule.mode is Mode.ACTIVE}
    assert {r for r in active if run.outcomes[r] != "passed"} == set(), run.text
    rules = run.unit_rules()
    assert all(rules[r]["verdict"] == "pass" for r in active)
    # The report tells what pytest tells: a pass for every test passed, a skip for every skip.
    as_pytest = {"pass": "passed", "warn": "passed", "skip": "skipped",
                 "could-not-test": "skipped", "fail": "failed"}
    assert {r: as_pytest[v["verdict"]] for r, v in rules.items()} == run.outcomes
    # The header makes the run repeatable and says what is being certified.
    header = run.text
    for needle in ("certifying waraps/unit/air/simulation/dji0", "agent-uuid ", "levels: sensor,"
                   " direct execution", "Using --seed=7", "profile:  fast-selftest"):
        assert needle in header
    # JUnit carries the run's identity as properties.
    props = {p.get("name"): p.get("value") for p in ET.parse(junit).iter("property")}
    assert props["unit"] == UNIT and props["seed"] == "7"
    assert len(props["agent-uuid"].split()) == 2  # before and after the reboot
    assert props["profile"].startswith("fast-selftest") and props["suite-version"]
    assert len(props["schemas-hash"]) >= 16
    # The JSON and HTML reports were written.
    assert len(list(run.reports_dir.glob("dji0-*.json"))) == 1
    assert len(list(run.reports_dir.glob("dji0-*.html"))) == 1


def test_reference_unit_passes_on_mosquitto(pytester: pytest.Pytester, mosquitto: str,
                                            unit_address: UnitAddress) -> None:
    with SimUnit(unit_address, mosquitto, rate=3.0, seed=3) as sim:
        rebooter = Rebooter(sim)
        run = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                      f"--profile={FAST}", "--seed", "7", plugins=(rebooter,))
    assert run.result.ret == 0, run.text
    assert not run.failed
    assert rebooter.calls == 1
    assert run.outcomes["REBOOT-001"] == run.outcomes["REBOOT-002"] == "passed"


def test_one_rule_by_its_id(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "embedded", "--sim-rate", "3",
                  f"--profile={FAST}", "-k", "EXEC-PING-002")
    assert run.result.ret == 0, run.text
    assert run.outcomes == {"EXEC-PING-002": "passed"}


def test_warn_is_a_pass_with_a_warning_and_strict_makes_it_a_failure(
        pytester: pytest.Pytester) -> None:
    """An erratum reading (ERR-001: 'sensor.info') warns under the default profile: the test
    passes, a ConformanceWarning says why, the JUnit verdict property says 'warn'."""
    junit = pytester.path / "junit.xml"
    args = ("--unit", UNIT, "--broker", "embedded", "--sim-rate", "3",
            "--sim-fault=sensor-dot-info", "-k", "ERR-001")
    run = certify(pytester, *args, f"--junitxml={junit}")
    assert run.result.ret == 0, run.text
    assert run.outcomes == {"ERR-001": "passed"}
    assert "ConformanceWarning: ERR-001 sensor level topic is 'sensor_info'" in run.text
    verdicts = [p.get("value") for p in ET.parse(junit).iter("property")
                if p.get("name") == "verdict"]
    assert verdicts == ["warn"]
    strict = certify(pytester, *args, "--profile", "strict")
    assert strict.result.ret == pytest.ExitCode.TESTS_FAILED
    assert strict.outcomes == {"ERR-001": "failed"}

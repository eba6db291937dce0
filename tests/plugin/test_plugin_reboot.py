"""REBOOT-001 when the unit comes back from the requested reboot under another name (
2; docs/FIELD-NOTES.md 'Real agents certified live': agents that add a random suffix to their name
at every start, `cppl2_9d00`):
it fails naming the new name, instead of could-not-test; a unit of the same type and role that
was there before the reboot is not taken for it."""

from __future__ import annotations

from typing import Any

import pytest
from certify_helpers import FAST, certify, certify_selected

from conformance.sim import SimUnit

pytestmark = [pytest.mark.slow, pytest.mark.mosquitto]

RULES = "REBOOT-001 or REBOOT-002"


class Renamer:
    """A reboot hook: the unit stops, and starts again under ``<name>_9d00`` (or its own name
    when ``rename`` is false)."""

    def __init__(self, unit: str, broker: str, rename: bool) -> None:
        self.unit, self.broker, self.rename = unit, broker, rename
        self.sims: list[Any] = [SimUnit(unit, broker, rate=3.0, seed=1).start()]

    def pytest_waraps_reboot(self, config: pytest.Config, unit: str) -> bool:
        self.sims[-1].stop()
        name = unit + "_9d00" if self.rename else unit
        self.sims.append(SimUnit(name, self.broker, rate=3.0, seed=2).start())
        return True

    def stop(self) -> None:
        for sim in self.sims:
            sim.stop()


@pytest.mark.parametrize("rename", [True, False], ids=["renamed", "same-name"])
def test_a_unit_back_under_another_name_fails_reboot_001_naming_it(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, rename: bool) -> None:
    unit = f"{prefix}/unit/air/simulation/cppl2_1a2b"
    # Another unit of the same type and role, there all along: never taken for the unit.
    with SimUnit(f"{prefix}/unit/air/simulation/cppl2_77ff", mosquitto, rate=3.0, seed=3):
        renamer = Renamer(unit, mosquitto, rename)
        # The exploration comes after the reboot: renamed, it says why nothing answers.
        explore = ("--explore=2s", "-k", f"{RULES} or test_explore") if rename else ("-k", RULES)
        try:
            run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                          *explore, plugins=(renamer,))
        finally:
            renamer.stop()
    rules = run.unit_rules()
    if rename:
        # A decided condition of REBOOT-001 ('renamed'): this profile adopts every decision.
        assert rules["REBOOT-001"]["verdict"] == "fail", rules["REBOOT-001"]
        found = rules["REBOOT-001"]["violations"][0]
        assert found["condition"] == "renamed"
        assert "'cppl2_1a2b_9d00'" in found["observed"]
        assert "cppl2_77ff" not in found["observed"]
        assert run.result.ret == 1
        assert "came back under another name ('cppl2_1a2b_9d00') after the suite's reboot" \
            in run.text, run.text[-3000:]
        assert "had not come back" not in run.text
        # The failure says what its condition stands on, as every violation's does.
        from conformance.rules import CATALOGUE
        assert f"basis     {CATALOGUE['REBOOT-001'].basis_text('renamed')}"[:80] in run.text, \
            run.text[-3000:]
    else:
        assert rules["REBOOT-001"]["verdict"] == "pass", rules["REBOOT-001"]


def test_reboot_002_is_not_claimed_by_a_unit_without_direct_execution(
        pytester: pytest.Pytester, prefix: str) -> None:
    """REBOOT-002 is about the history of commands (12.1): a unit that declares only the
    sensor level (the official L1 agent, RISE) does not claim it; its reboot is still judged
    (REBOOT-001)."""
    run = certify_selected(pytester, prefix, "REBOOT", "undeclared-direct-execution")
    rules = run.unit_rules()
    assert rules["REBOOT-001"]["verdict"] == "pass", run.text
    assert rules["REBOOT-002"]["verdict"] == "skip", rules["REBOOT-002"]
    assert "not claimed" in rules["REBOOT-002"]["reason"]


def test_of_new_names_the_one_like_the_unit_s_own_is_taken_for_it() -> None:
    """Another unit of the same type and role first heard after the reboot (slower than the
    window the names known before were read in: the public agents' pyl1 beside cppl2) is not
    named for the unit when a name sharing its beginning came too (cppl2_vvhp back as
    cppl2_4b3f); with none like it, the first heard is."""
    from types import SimpleNamespace

    from conformance.clock import VirtualClock
    from conformance.message import Message
    from conformance.suite.reboot import Names

    clock = VirtualClock(1000.0)
    names = Names(SimpleNamespace(traffic=SimpleNamespace(clock=clock)),  # type: ignore[arg-type]
                  "waraps/unit/air/simulation/cppl2_vvhp")
    for t, name in ((1001.0, "pyl1"), (1002.0, "cppl2_4b3f")):
        names._seen(Message(t, f"waraps/unit/air/simulation/{name}/heartbeat", b"{}"))
    assert names.new_name(set(), 1000.5, 0.0) == "cppl2_4b3f"
    assert names.new_name({"cppl2_4b3f"}, 1000.5, 0.0) == "pyl1"

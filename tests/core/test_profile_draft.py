"""`waraps-conformance profile`: a starting profile from what a unit declares and publishes
(conformance.profile_draft), observed read-only on a real broker."""

from __future__ import annotations

from pathlib import Path

import pytest

from conformance import profile
from conformance.cli import main
from conformance.sim import SimUnit
from conformance.topics import UnitAddress


def test_the_draft_of_the_reference_unit_loads_and_says_what_it_declares(
        unit_address: UnitAddress, mosquitto: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "unit.yaml"
    with SimUnit(unit_address, mosquitto, rate=5.0, faults=["sensor-dot-info"]):
        code = main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                     "--observe", "3s", "-o", str(out)])
    assert code == 0
    drafted = profile.load(out)  # the draft is a valid profile as it is
    assert drafted.levels == ("sensor", "direct execution")
    assert drafted.sensors == ("camera_url",)  # beyond the mandatory four (5.2)
    assert "move-to" in drafted.tasks and drafted.motion_tasks == ()  # never moves by default
    text = out.read_text()
    assert "# motion-tasks: [" in text and "move-to" in text.split("# motion-tasks:")[1]
    assert "heartbeat: declares rate 5.0 Hz, measured" in text
    assert "sensor/position: published at" in text
    assert f"observing {unit_address}" in capsys.readouterr().err  # says what it waits for
    # an edited profile is never overwritten
    assert main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                 "--observe", "0.1s", "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err


def test_a_unit_never_seen_gets_a_commented_draft_and_exit_6(
        unit_address: UnitAddress, mosquitto: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                 "--observe", "0.5s"]) == 6
    text = capsys.readouterr().out
    assert "No heartbeat was seen" in text and "No direct_execution_info was seen" in text
    profile.from_dict(__import__("yaml").safe_load(text), "<draft>")  # still a valid profile


@pytest.mark.parametrize(("argv", "message"), [
    (["--unit", "not/a/unit"], "--unit: 'not/a/unit' is not a unit address"),
    (["--unit", "waraps/unit/air/real/x", "--observe", "soon"], "--observe: duration 'soon'"),
])
def test_bad_options_say_what_to_fix(argv: list[str], message: str, mosquitto: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profile", "--broker", mosquitto, *argv]) == 2
    assert message in capsys.readouterr().err

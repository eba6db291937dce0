"""`waraps-conformance profile`: a starting profile from what a unit declares and publishes
(conformance.profile_draft), observed read-only on a real broker."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from conformance import profile
from conformance.cli import main
from conformance.profile_draft import Observed, draft
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
    assert "PROBLEM" not in text  # the reference unit keeps its word
    assert '"sensor/position": published at' in text
    assert f"observing {unit_address}" in capsys.readouterr().err  # says what it waits for
    # an edited profile is never overwritten
    assert main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                 "--observe", "0.1s", "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err


def test_a_unit_never_seen_gets_a_commented_draft_and_exit_6(
        unit_address: UnitAddress, mosquitto: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                 "--observe", "0.5s"]) == 6
    said = capsys.readouterr()
    text = said.out
    assert "No heartbeat was seen" in text and "No direct_execution_info was seen" in text
    # exit 6 is said on stderr too, with what to check
    assert f"waraps-conformance profile: no heartbeat of {unit_address} within 0.5s on " \
           f"{mosquitto}" in said.err and "is the unit running" in said.err, said.err
    profile.from_dict(__import__("yaml").safe_load(text), "<draft>")  # still a valid profile


@pytest.mark.parametrize(("argv", "message"), [
    (["--unit", "not/a/unit"], "--unit: 'not/a/unit' is not a unit address"),
    (["--unit", "waraps/unit/air/real/x", "--observe", "soon"], "--observe: duration 'soon'"),
])
def test_bad_options_say_what_to_fix(argv: list[str], message: str, mosquitto: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profile", "--broker", mosquitto, *argv]) == 2
    assert message in capsys.readouterr().err


HOSTILE = ["cam\u2028severity: {'*': warning}\u2028description",
           "x\u2029severity: {'*': warning}", "y\x85severity: {'*': warning}",
           "z\nseverity: {'*': warning}", "w\rseverity: {'*': warning}",
           "v\x0bseverity: {'*': warning}\x0c", "u\u202e\x1b[2J: &a [*a]", "t' # !!python/x"]


def hostile_observation(unit: UnitAddress) -> Observed:
    """A unit whose every declared word tries to become a key of the drafted profile."""
    import time as clock

    from conformance.message import Message

    seen = Observed(unit, 3.0)
    now = clock.time()
    bodies = {"heartbeat": {"levels": ["sensor", "direct execution", *HOSTILE], "rate": 5.0,
                            "name": HOSTILE[0]},
              "sensor_info": {"sensor-data-provided": ["position", *HOSTILE]},
              "direct_execution_info": {"tasks-available": [
                  {"name": n} for n in ("look-at-bearing", "go-home", *HOSTILE)]}}
    for i in range(3):
        for sub, body in bodies.items():
            seen.feed(Message(now + i, unit.topic(sub), json.dumps(body).encode(), 0, False))
        for name in HOSTILE:
            seen.feed(Message(now + i * 5, unit.topic(f"sensor/{name}"), b"{}", 0, False))
    return seen


def test_nothing_a_unit_publishes_becomes_a_key_of_the_draft(unit_address: UnitAddress) -> None:
    """Every line-breaking code point (\\n, \\r, U+2028, U+2029, U+0085, \\v,
    \\f), YAML's specials, control and bidi characters in sensor, level and task names are
    escaped; the draft loads with exactly the keys the drafter writes, and no severity."""
    text = draft(hostile_observation(unit_address))
    assert all(ch not in text for ch in "\u2028\u2029\x85\r\x0b\x0c\x1b\u202e")
    loaded = yaml.safe_load(text)
    assert set(loaded) == {"extends", "name", "levels", "sensors", "tasks", "motion-tasks",
                           "safe-radius", "response-timeout", "feedback-timeout",
                           "reboot-timeout", "rate-tolerance"}
    drafted = profile.from_dict(loaded, "<draft>")
    assert drafted.severity == profile.load("default").severity  # none of the unit's making
    assert drafted.levels == ("sensor", "direct execution")
    # Section 9 tasks with the spec example's parameters, the others left to fill in.
    assert drafted.task_params["look-at-bearing"]["bearing"] == 45.0
    assert "go-home" not in drafted.tasks
    assert '# "go-home" is not a section 9 task: fill in the parameters' in text
    assert '#   PROBLEM: declares heartbeat rate 5.0 Hz, measured 1.00 Hz (HB-003)' in text


@pytest.mark.slow
def test_a_hostile_unit_cannot_certify_itself_through_its_drafted_profile(
        pytester: pytest.Pytester, unit_address: UnitAddress, mosquitto: str,
        tmp_path: Path) -> None:
    """The forged profile: a unit publishes on `.../sensor/cam\\u2028severity: {'*':
    warning}\\u2028description`; the profile drafted from it has no severity, and the faulty
    reference unit (topic-uppercase-sensor) certified with it still fails."""
    from conformance.client import BrokerURL, MqttClient

    out = tmp_path / "drafted.yaml"
    topic = unit_address.topic(f"sensor/{HOSTILE[0]}")
    with SimUnit(unit_address, mosquitto, rate=5.0), \
            MqttClient(BrokerURL.parse(mosquitto), may_publish=lambda t: True
                       ).connect() as forger:
        forger.publish(topic, b"{}", qos=1, retain=True)
        try:
            assert main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                         "--observe", "2s", "-o", str(out)]) == 0
        finally:
            forger.publish(topic, b"", qos=1, retain=True)  # the shared broker keeps none
    assert "cam\\u2028severity" in out.read_text()  # seen, and written escaped
    assert profile.load(out).severity == profile.load("default").severity
    run = pytester.runpytest_subprocess(
        "--unit", "waraps/unit/air/simulation/dji0", "--broker", "virtual",
        "--sim-fault", "topic-uppercase-sensor", f"--profile={out}", "--explore", "0",
        "-k", "TOPIC or HB-001", "-p", "no:cacheprovider", timeout=120)
    assert run.ret != 0, run.stdout.str()
    assert "downgrades" not in run.stdout.str()  # the header would say a forged downgrade
    run.stdout.fnmatch_lines(["*TOPIC-* *[[]fail[]]*"])


def test_a_unit_slower_than_it_declares_is_a_problem_in_the_draft_and_on_stderr(
        unit_address: UnitAddress, mosquitto: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """docs/FIELD-NOTES.md 'Real agents certified live': an agent declaring 5 Hz publishes at 0.2
    Hz; the draft says so as a
    problem, not as a neutral note."""
    out = tmp_path / "slow.yaml"
    with SimUnit(unit_address, mosquitto, rate=5.0, faults=["heartbeat-rate-drift"]):
        assert main(["profile", "--unit", str(unit_address), "--broker", mosquitto,
                     "--observe", "3s", "-o", str(out)]) == 0
    text = out.read_text()
    assert "#   PROBLEM: declares heartbeat rate 5.0 Hz, measured" in text, text
    assert "PROBLEM: declares heartbeat rate 5.0 Hz, measured" in capsys.readouterr().err
    profile.load(out)


def test_a_draft_whose_only_task_is_not_a_section_9_one_is_filled_in_as_it_says(
        unit_address: UnitAddress) -> None:
    """A public agent offering only go-home (not a section 9 task) got 'tasks: {}' and a
    commented placeholder under it: uncommented as the comment says, the file was not YAML.
    Now it loads as drafted (no task) and, filled in, with the user's parameters."""
    import time as clock

    from conformance.message import Message

    seen = Observed(unit_address, 3.0)
    body = {"tasks-available": [{"name": "go-home"}]}
    for i in range(3):
        seen.feed(Message(clock.time() + i, unit_address.topic("direct_execution_info"),
                          json.dumps(body).encode(), 0, False))
    text = draft(seen)
    assert profile.from_dict(yaml.safe_load(text), "<draft>").tasks == ()
    filled = text.replace('  # "go-home": {params: {}}', '  "go-home": {params: {speed: 5.0}}')
    assert filled != text
    drafted = profile.from_dict(yaml.safe_load(filled), "<filled>")
    assert drafted.task_params["go-home"] == {"speed": 5.0}


def test_a_draft_says_an_undeclared_level_and_an_unknown_role(tmp_path: Path) -> None:
    """The RISE agent (certified this session): direct_execution_info without the level in its
    heartbeat is a PROBLEM (HB-013), and its role 'simulated' (not 3.1's) is said to be
    treated as real, with the profile line that would make it a simulation, commented out.
    The draft still loads, and with that line uncommented the role is a simulation."""
    unit = UnitAddress.parse("waraps/unit/air/simulated/rise0")
    seen = Observed(unit, 5.0, heartbeat={"levels": ["sensor"], "rate": 1.0},
                    dei={"tasks-available": [], "tasks-executing": []})
    text = draft(seen)
    assert ("#   PROBLEM: publishes direct_execution_info but its heartbeat does not declare "
            "the direct execution level (5.1, HB-013)") in text, text
    assert "# Its role \"simulated\" is not one of 3.1's" in text, text
    assert '# simulated-roles: ["simulated"]' in text
    path = tmp_path / "rise.yaml"
    path.write_text(text)
    assert profile.load(path).simulated_roles == ()
    path.write_text(text.replace('# simulated-roles: ["simulated"]', 'simulated-roles: ["simulated"]'))
    assert profile.load(path).simulated_roles == ("simulated",)
    plain = draft(Observed(UnitAddress.parse("waraps/unit/air/real/dji0"), 5.0,
                           heartbeat={"levels": ["sensor", "direct execution"], "rate": 1.0},
                           dei={"tasks-available": []}))
    assert "HB-013" not in plain and "simulated-roles" not in plain
    # It offers no task: the draft says so and lists none (an empty 'tasks:' read as null).
    assert "# direct_execution_info offers no task (5.3)" in text and "\ntasks: []\n" in text
    assert yaml.safe_load(text)["tasks"] == []


@pytest.mark.parametrize("payload", [
    b'{"levels": ' + b"[" * 100_000 + b"]" * 100_000 + b', "rate": 1}',  # 200 KB, once a RecursionError
    b'{"levels": ["sensor"], "rate": 1' + b"0" * 400 + b"}",  # once an OverflowError
    b'{"levels": ["sensor"], "rate": 1e400}',
    b'{"levels": ["sensor"], "name": "\\ud800", "rate": 1}',
], ids=["nested-100000", "rate-1e400-digits", "rate-1e400", "lone-surrogate"])
def test_a_hostile_heartbeat_is_read_within_the_bounds(payload: bytes,
                                                       unit_address: UnitAddress) -> None:
    """The drafter reads payloads as the validator does (size, nesting, finite numbers):
    what it cannot read is not a declaration, never a traceback."""
    from conformance.message import Message
    from conformance.profile_draft import problems

    seen = Observed(unit_address, 5.0)
    for i in range(5):
        seen.feed(Message(1_763_700_000.0 + i, f"{unit_address.base}/heartbeat", payload))
    text = draft(seen)
    problems(seen)
    assert yaml.safe_load(text)["extends"]


def test_a_slow_heartbeat_gets_an_alive_timeout_of_three_of_its_periods(tmp_path: Path) -> None:
    """The public drone operator's heartbeat comes every 5 s: the suite's default wait for
    the first heartbeat (5 s) could miss it, so the draft writes three of its measured periods;
    six intervals are said to be fewer than the ten the --observe help aims for. A unit at
    1 Hz keeps the default."""
    unit = UnitAddress.parse("waraps/unit/ground/real/dop1")
    slow = Observed(unit, 30.0, heartbeat={"levels": ["sensor"], "rate": 0.2})
    slow.arrivals["heartbeat"] = [100.0 + 5.0 * i for i in range(7)]
    text = draft(slow)
    assert "\nalive-timeout: 15   # the first heartbeat, awaited 3 of its measured periods " \
           "(5.0 s)" in text, text
    assert "measured 0.20 Hz over 6 intervals (fewer than ten" in text
    path = tmp_path / "dop1.yaml"
    path.write_text(text)
    assert profile.load(path).alive_timeout == 15
    fast = Observed(unit, 30.0, heartbeat={"levels": ["sensor"], "rate": 1.0})
    fast.arrivals["heartbeat"] = [100.0 + i for i in range(30)]
    assert "alive-timeout" not in draft(fast) and "fewer than ten" not in draft(fast)

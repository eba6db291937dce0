"""The scenarios' own building blocks: task parameters (never invented: the profile's or the
spec example's; seeded, valid, safe) and the suite's own commands (valid, except the ones
broken on purpose)."""

from __future__ import annotations

import random

import pytest
from certify_helpers import FAST, Rebooter, certify

from conformance import taskspec
from conformance.profile import Profile
from conformance.scenarios.params import (
    NoParams,
    invalid_params,
    task_moves,
    task_schema,
    valid_params,
)
from conformance.scenarios.safety import Position, Safety
from conformance.topics import UnitAddress
from conformance.validator import Validator

ORIGIN = Position(58.3949, 15.5641, 2.0)
ADDRESS = UnitAddress.parse("waraps/unit/air/real/dji0")


def start_task(task: str, params: dict) -> bytes:
    import orjson

    return orjson.dumps({"com-uuid": "7300d049-176f-4dcb-b0bf-151980d5611a",
                         "command": "start-task", "execution-unit": "dji0",
                         "sender": "waraps-conformance", "task-uuid":
                         "9b4c701c-e8a2-4a92-9370-87c8f57e0dc0",
                         "task": {"name": task, "params": params}})


def points(value: object) -> list[dict]:
    if isinstance(value, dict):
        if "latitude" in value:
            return [value]
        return [p for v in value.values() for p in points(v)]
    if isinstance(value, list):
        return [p for v in value for p in points(v)]
    return []


@pytest.mark.parametrize("task", taskspec.task_names())
def test_section_9_parameters_are_the_spec_example_valid_seeded_and_near_the_unit(
        task: str) -> None:
    safety = Safety(ADDRESS, Profile(safe_radius=40.0), allow_motion=True, task_moves=task_moves)
    params = valid_params(task, ORIGIN, safety, seed=11)
    assert params == valid_params(task, ORIGIN, safety, seed=11)  # --seed repeats a run
    v = Validator(Profile()).validate(ADDRESS.topic("exec/command"), start_task(task, params))
    assert v.ok, [(x.rule, x.path, x.observed) for x in v.violations]
    for p in points(params):
        assert ORIGIN.distance(Position(p["latitude"], p["longitude"])) <= 20.0
        assert p["rostype"] == "GeoPoint" and "type" not in p  # the canonical form (ERR-010)
    for key in ("loop-flag", "hold-flag", "continue-flag", "named-position"):
        assert params.get(key) in (None, False)
    # Never invented: every key is one of the spec's own example.
    example = task_schema(task)["examples"][0]
    assert set(params) <= set(example), (params, example)


def test_parameters_come_from_the_profile_else_the_spec_example_else_nowhere() -> None:
    given = Profile(tasks=("go-home", "look-at-bearing"),
                    task_params={"go-home": {"speed": 5.0, "home": {
                        "latitude": 1.0, "longitude": 2.0, "altitude": 0.0,
                        "rostype": "GeoPoint"}}})
    safety = Safety(ADDRESS, given, allow_motion=True, task_moves=task_moves)
    params = valid_params("go-home", ORIGIN, safety, seed=3)
    assert params["speed"] == 5.0  # the profile's, as given
    assert ORIGIN.distance(Position(params["home"]["latitude"],
                                    params["home"]["longitude"])) <= 25.0  # made safe
    assert valid_params("look-at-bearing", ORIGIN, safety, seed=3) == \
        task_schema("look-at-bearing")["examples"][0]  # the spec's example
    bare = Safety(ADDRESS, Profile(), allow_motion=True, task_moves=task_moves)
    with pytest.raises(NoParams, match=r"no task to start: go-home has no parameters in the "
                       r"profile and is not a section 9 task; add tasks: \{go-home: "
                       r"\{params: \.\.\.\}\} to the profile"):
        valid_params("go-home", ORIGIN, bare, seed=3)
    ok, why = bare.may_start("go-home")
    assert not ok and why.startswith("no task to start: go-home has no parameters")
    assert safety.may_start("go-home")[0] is False  # moves (unknown) on a real unit
    only = Safety(ADDRESS, Profile(task_scenarios={"look-at-bearing": ("start",)}),
                  allow_motion=False, task_moves=task_moves)
    assert only.may_start("look-at-bearing", "start")[0]
    assert not only.may_start("look-at-bearing", "signal")[0]


@pytest.mark.parametrize("task", taskspec.task_names())
def test_invalid_parameters_are_invalid_for_the_schema(task: str) -> None:
    safety = Safety(ADDRESS, Profile(), allow_motion=True, task_moves=task_moves)
    bad = invalid_params(task, ORIGIN, safety, seed=11)
    assert bad is not None
    params, what = bad
    v = Validator(Profile()).validate(ADDRESS.topic("exec/command"), start_task(task, params))
    assert "TASK-001" in {x.rule for x in v.violations}, what


def test_safety_decides_by_role_tags_and_profile() -> None:
    real = Safety(ADDRESS, Profile(motion_tasks=("move-to",)), allow_motion=False,
                  task_moves=task_moves)
    assert real.may_start("look-at-bearing")[0]
    ok, why = real.may_start("move-to")
    assert not ok and "--allow-motion" in why
    assert not real.may_start("navigate")[0]  # moves although the spec gives it no tag
    assert not real.may_start("some-unknown-task")[0]  # unknown: assumed to move
    allowed = Safety(ADDRESS, Profile(motion_tasks=("move-to",)), allow_motion=True,
                     task_moves=task_moves)
    assert allowed.may_start("move-to")[0] and not allowed.may_start("move-path")[0]
    sim = Safety(UnitAddress.parse("waraps/unit/air/simulation/dji0"), Profile(),
                 allow_motion=False, task_moves=task_moves)
    assert sim.may_start("move-to")[0]
    only = Safety(ADDRESS, Profile(tasks=("look-at-bearing",)), allow_motion=True,
                  task_moves=task_moves)
    assert not only.may_start("look-at-position")[0]
    rng = random.Random(1)
    assert all(ORIGIN.distance(allowed.near(ORIGIN, rng)) <= 25.0 for _ in range(200))


class Commands:
    """Reads, after the run, what the suite's commander sent and what it broke on purpose."""

    def __init__(self) -> None:
        self.invalid: set[bytes] = set()

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        from conformance.suite.session import CERTIFICATION

        self.invalid = set(session.config.stash[CERTIFICATION].commander.deliberately_invalid)


def test_the_suite_sends_valid_commands_except_the_ones_broken_on_purpose(
        pytester: pytest.Pytester, mosquitto: str, unit_address: UnitAddress) -> None:
    from conformance.client import BrokerURL, MqttClient
    from conformance.sim import SimUnit

    commands = Commands()
    topic = unit_address.topic("exec/command")
    with SimUnit(unit_address, mosquitto, rate=3.0) as sim, \
            MqttClient(BrokerURL.parse(mosquitto)) as wire:
        wire.subscribe(topic)
        run = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                      f"--profile={FAST}", plugins=(Rebooter(sim), commands))
        sent = [m.payload for m in wire.messages(timeout=0.5)]
    assert run.result.ret == 0, run.text
    assert len(commands.invalid) >= 8
    validator = Validator(Profile())
    valid = [p for p in sent if p not in commands.invalid]
    assert len(valid) > 20
    for payload in valid:
        v = validator.validate(topic, payload)
        assert v.ok, (payload[:200], [(x.rule, x.path, x.observed) for x in v.violations])
    for payload in commands.invalid:
        assert not validator.validate(topic, payload).ok, payload

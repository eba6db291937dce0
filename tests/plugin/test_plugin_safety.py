"""Safety (docs/ARCHITECTURE.md 'Safety'): commands only to the unit under test; no motion on a real
unit unless --allow-motion AND the profile's motion-tasks say so, decided by the publish policy on
every payload (malformed ones too), proven from the broker's traffic; positions near the unit,
inside the profile's safe radius."""

from __future__ import annotations

import json
import re
from pathlib import Path

import orjson
import pytest
from certify_helpers import FAST, MATRIX, Rebooter, certify

from conformance import taskspec
from conformance.client import BrokerURL, Message, MqttClient
from conformance.plugin import UNTESTED_EXIT
from conformance.profile import Profile
from conformance.scenarios import robust
from conformance.scenarios.safety import MOVES_WITHOUT_TAG, MotionGate, Position, named_tasks
from conformance.sim import SimUnit
from conformance.topics import UnitAddress

pytestmark = pytest.mark.slow

MOTION = {s.name for s in taskspec.task_specs() if s.moves_unit} | MOVES_WITHOUT_TAG


def moves(task: str) -> bool:
    try:
        return taskspec.task_spec(task).moves_unit or task in MOVES_WITHOUT_TAG
    except KeyError:
        return True


def motion_named(payload: bytes) -> set[str]:
    """The motion tasks a payload names, as this test reads it (on its own, not with the
    suite's gate): any of them as a word of its own in the raw text or in the decoded JSON,
    in any case, '_' taken for '-'."""
    texts = [payload.decode("utf-8", "replace")]
    try:
        texts.append(json.dumps(json.loads(payload), ensure_ascii=False))
    except ValueError:
        pass
    text = " ".join(texts).lower().replace("_", "-")
    return {n for n in MOTION if re.search(rf"(?<![a-z0-9-]){re.escape(n)}(?![a-z0-9-])", text)}


def geopoints(value: object) -> list[dict]:
    if isinstance(value, dict):
        if "latitude" in value and "longitude" in value:
            return [value]
        return [p for v in value.values() for p in geopoints(v)]
    if isinstance(value, list):
        return [p for v in value for p in geopoints(v)]
    return []


class Wire:
    """Everything published under the prefix while certifying (a read-only observer)."""

    def __init__(self, broker: str, prefix: str) -> None:
        self.messages: list[Message] = []
        self.client = MqttClient(BrokerURL.parse(broker), on_message=self.messages.append)
        self.prefix = prefix

    def __enter__(self) -> Wire:
        self.client.connect()
        self.client.subscribe(f"{self.prefix}/#")
        return self

    def __exit__(self, *exc: object) -> None:
        self.client.close()

    def commands(self) -> list[tuple[Message, dict]]:
        out = []
        for m in self.messages:
            if m.topic.endswith(("/exec/command", "/tst/command")):
                try:
                    body = orjson.loads(m.payload)
                except orjson.JSONDecodeError:
                    body = {}
                out.append((m, body if isinstance(body, dict) else {}))
        return out

    def position_before(self, unit: str, t: float) -> Position | None:
        found = None
        for m in self.messages:
            if m.topic == f"{unit}/sensor/position" and m.time <= t:
                p = orjson.loads(m.payload)
                found = Position(p["latitude"], p["longitude"], p.get("altitude", 0.0))
        return found


def started(wire: Wire) -> list[tuple[Message, dict]]:
    return [(m, b) for m, b in wire.commands() if b.get("command") == "start-task"
            and isinstance(b.get("task"), dict)]


def test_a_real_unit_is_not_moved_without_allow_motion(pytester: pytest.Pytester,
                                                       mosquitto: str, prefix: str) -> None:
    """Every scenario, TST included, on a real unit whose profile lists motion tasks: no
    payload that reached the unit's command topics names one (the broker's traffic, read by
    an observer of its own)."""
    unit, other = f"{prefix}/unit/air/real/dji0", f"{prefix}/unit/air/real/dji1"
    with SimUnit(other, mosquitto, rate=3.0), \
            SimUnit(unit, mosquitto, rate=3.0, tst_execution=True) as sim, \
            Wire(mosquitto, prefix) as wire:
        # The matrix profile lets the suite start move-to and navigate: only the flag may.
        # --allow-hostile: the robustness probes go out too, and none of them may move it.
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={MATRIX}",
                      "--allow-hostile", "--seed", "3", plugins=(Rebooter(sim),))
    assert run.result.ret == 0, run.text
    assert "no motion (no --allow-motion), hostile payloads allowed (--allow-hostile)" \
        in run.text
    names = {b["task"].get("name") for _, b in started(wire)}
    assert names and not any(moves(n) for n in names if n != "waraps-conformance-no-such-task")
    commands = [m for m, _ in wire.commands()]
    assert any(m.topic.endswith("/tst/command") for m in commands)  # trees were sent too
    # and the robustness probes (its start-task whose task is a string names no real task)
    assert any(b'"task":"waraps-conformance-no-such-task"' in m.payload for m in commands)
    assert [(m.topic, m.payload) for m in commands if motion_named(m.payload)] == []
    # The probes were sent and judged, not refused: none names a motion task.
    assert run.outcomes["EXEC-ROBUST-002"] == "passed", run.unit_rules()["EXEC-ROBUST-002"]
    # Commands went to the unit under test only: never to its neighbour, never elsewhere.
    assert {m.topic for m in commands} == {f"{unit}/exec/command", f"{unit}/tst/command"}


@pytest.mark.slow
def test_probes_the_policy_refuses_on_a_real_unit_are_no_broker_stall(
        pytester: pytest.Pytester, mosquitto: str, prefix: str) -> None:
    """The public drone operator (role real) ended 'not certified' (exit 6, 'the broker
    delivered nothing ... the suite's own command did not come back'): the robustness probes
    the policy refused were awaited as echoes. A refused payload is never sent."""
    unit = f"{prefix}/unit/air/real/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "--seed", "3", plugins=(Rebooter(sim),))
    # No rule failed; without --allow-hostile EXEC-ROBUST-* could not be tested: no
    # certificate (exit 7), and never 6.
    assert run.result.ret == UNTESTED_EXIT, run.text
    assert "had not come back" not in run.text and "did not come back" not in run.text \
        and "delivered nothing" not in run.text
    assert "hostile payloads to a real unit need --allow-hostile" in json.dumps(
        run.unit_rules()["EXEC-ROBUST-002"])


def test_the_publish_policy_refuses_a_motion_task_whatever_the_scenario_sends(
        pytester: pytest.Pytester, mosquitto: str, prefix: str,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/ARCHITECTURE.md 'Safety': the policy, not the scenario, decides. A robustness probe made
    to name move-to (cut off, upper case, '_': as a lenient parser may still read it) is not
    published to a real unit without --allow-motion; the scenario's rules are could-not-test saying
    why, and the run goes on (no crash)."""
    probe = b'{"command": "start-task", "task": "MOVE_TO", "com-uuid": '
    monkeypatch.setattr(robust, "UNREADABLE", (*robust.UNREADABLE, ("a motion probe", probe)))
    unit = f"{prefix}/unit/air/real/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "--allow-hostile", "--seed", "3", "-k", "EXEC-ROBUST",
                      plugins=(Rebooter(sim),))
    assert run.result.ret == 0, run.text
    assert "Traceback" not in run.text and "INTERNALERROR" not in run.text
    rules = run.unit_rules()
    for rule in ("EXEC-ROBUST-001", "EXEC-ROBUST-002"):
        assert rules[rule]["verdict"] == "could-not-test", rules[rule]
        assert "names the motion task(s) move-to" in rules[rule]["reason"]
        assert "--allow-motion" in rules[rule]["reason"]
    payloads = [m.payload for m, _ in wire.commands()]
    assert payloads and probe not in payloads  # the probes before it went out; it did not
    assert [p for p in payloads if motion_named(p)] == []


@pytest.mark.parametrize(("payload", "named"), [
    (b'{"command": "start-task", "task": "move-to"}', ["move-to"]),  # the old robust probe
    (b'{"task": {"name": "take-off", "params": {}}}', ["take-off"]),
    (b'{"task": "move\\u002dto"}', ["move-to"]),  # an escape, decoded
    (b'{"command": "start-task", "task": "LAND"', ["land"]),  # malformed, upper case
    (b"\xff\xfe navigate", ["navigate"]),  # not UTF-8
    (b'{"tst": {"name": "seq", "children": [{"name": "search_area"}]}}', ["search-area"]),
    (b'{"task": {"name": "look-at-bearing"}, "sender": "island"}', []),  # not a word of its own
    (b'{"task": "waraps-conformance-no-such-task"}', []),
])
def test_a_payload_is_read_leniently_for_motion_tasks(payload: bytes, named: list[str]) -> None:
    assert named_tasks(payload, MOTION) == named
    assert sorted(motion_named(payload)) == named  # the test's own reading agrees


def test_the_motion_gate_decides_by_unit_role_flag_and_profile() -> None:
    move = b'{"command": "start-task", "task": {"name": "move-to", "params": {}}}'
    look = b'{"command": "start-task", "task": {"name": "look-at-bearing", "params": {}}}'
    fly = b'{"command": "start-task", "task": {"name": "fly-circle", "params": {}}}'
    real = UnitAddress.parse("waraps/unit/air/real/dji0")
    sim = UnitAddress.parse("waraps/unit/air/simulation/dji0")
    drone = Profile(name="drone", motion_tasks=("move-to",))

    def gate(unit: UnitAddress, profile: Profile, allow: bool) -> MotionGate:
        from conformance.scenarios.params import task_moves

        # (hostile payloads allowed: these bare commands lack com-uuid and params)
        return MotionGate(unit, profile, allow_motion=allow, allow_hostile=True,
                          listed=lambda: ["look-at-bearing", "fly-circle"], task_moves=task_moves)
    assert gate(sim, Profile(), False).refusal(move) is None  # a simulation may move
    assert "move-to" in (gate(real, Profile(), False).refusal(move) or "")
    assert "move-to" in (gate(real, drone, False).refusal(move) or "")  # the flag too
    assert "move-to" in (gate(real, Profile(), True).refusal(move) or "")  # the profile too
    assert gate(real, drone, True).refusal(move) is None
    assert gate(real, drone, True).refusal(look) is None
    # A task the unit lists that this suite does not know is taken to move (Safety.moves).
    assert "fly-circle" in (gate(real, drone, True).refusal(fly) or "")


ROLES = ("real", "simulation", "playback", "live", "xyz-unknown", "simulated")


@pytest.mark.parametrize("role", ROLES)
def test_only_simulation_and_the_profile_simulated_roles_are_simulations(role: str) -> None:
    """docs/ARCHITECTURE.md 'Safety' fails closed: every role word but 'simulation' (and a profile's
    simulated-roles) is a real unit: no motion task without --allow-motion and motion-tasks,
    no hostile payload without --allow-hostile or robustness: true."""
    from conformance.scenarios.params import task_moves

    move = b'{"command": "start-task", "task": {"name": "move-to", "params": {}}}'
    hostile = b"\xff\xfe\xfd{}"
    unit = UnitAddress.parse(f"waraps/unit/air/{role}/dji0")

    def gate(profile: Profile, *, motion: bool = False, hostile_ok: bool = False) -> MotionGate:
        return MotionGate(unit, profile, allow_motion=motion, allow_hostile=hostile_ok,
                          task_moves=task_moves)
    simulation = role == "simulation"
    for profile in (Profile(), Profile(motion_tasks=("move-to",))):
        refused = gate(profile).refusal(move)
        assert (refused is None) == simulation, refused
        assert (gate(profile).refusal(hostile) is None) == simulation
    if not simulation:
        assert "names the motion task(s) move-to" in (gate(Profile()).refusal(move) or "")
        assert "--allow-hostile" in (gate(Profile()).refusal(hostile) or "")
        assert "this payload is not UTF-8" in (gate(Profile()).refusal(hostile) or "")
        assert "--allow-motion" in (gate(Profile()).decision.sentence())
        assert f"role {role!r} is treated as real" in gate(Profile()).decision.sentence()
    # The opt-ins, one by one: motion needs both the flag and motion-tasks (this bare
    # command, without com-uuid and params, is malformed too: hostile payloads allowed).
    assert gate(Profile(motion_tasks=("move-to",)), motion=True, hostile_ok=True
                ).refusal(move) is None
    if not simulation:
        assert gate(Profile(motion_tasks=("move-to",)), motion=True).refusal(move) \
            .startswith("not sent: hostile payloads")
    assert gate(Profile(), hostile_ok=True).refusal(hostile) is None
    assert gate(Profile(robustness=True)).refusal(hostile) is None
    # A profile's simulated-roles make the role a simulation, and only that role.
    listed = Profile(simulated_roles=(role,))
    assert gate(listed).refusal(move) is None and gate(listed).refusal(hostile) is None
    other = Profile(simulated_roles=("something-else",))
    assert (gate(other).refusal(hostile) is None) == simulation


@pytest.mark.parametrize(("payload", "hostile"), [
    (b'{"command": "ping", "com-uuid": "0f8e6bb0-5b4a-4b2e-9d2b-6a1f5e0e7c11", '
     b'"sender": "s"}', None),
    (b'{"command": "start-task", "com-uuid": "0f8e6bb0-5b4a-4b2e-9d2b-6a1f5e0e7c11", '
     b'"sender": "s", "task": {"name": "no-such-task", "params": {}}}', None),
    *[(probe, "hostile") for _, probe in robust.UNREADABLE],
    *[(probe, "hostile") for _, probe in robust.malformed("0f8e6bb0-5b4a-4b2e-9d2b-6a1f5e0e7c11")],
    (b'{"command": "ping", "x": "' + b"a" * 70_000 + b'"}', "hostile"),  # huge
    (b'{"command": "ping", "x": ' + b"[" * 40 + b"]" * 40 + b"}", "hostile"),  # deep
])
def test_every_robustness_probe_is_hostile_and_the_suite_commands_are_not(
        payload: bytes, hostile: str | None) -> None:
    from conformance.scenarios.safety import hostility

    found = hostility("waraps/unit/air/real/dji0/exec/command", payload)
    assert (found is not None) == (hostile is not None), found


def _wire_hostile(wire: Wire) -> list[bytes]:
    """Commands on the wire that are not a UTF-8 JSON object naming a known command (this
    test's own reading, not the suite's gate)."""
    out = []
    for m, _ in wire.commands():
        try:
            body = json.loads(m.payload.decode("utf-8"))
        except ValueError:
            out.append(m.payload)
            continue
        if not isinstance(body, dict) or body.get("command") not in (
                "ping", "start-task", "signal-task", "query-status"):
            out.append(m.payload)
        elif body.get("command") == "start-task" and not isinstance(body.get("task"), dict):
            out.append(m.payload)
    return out


@pytest.mark.parametrize(("role", "opt_in", "sent"), [
    ("real", (), False),
    ("live", (), False),
    ("playback", ("--allow-hostile",), True),
    ("xyz-unknown", ("robustness: true",), True),
    ("simulated", (), False),  # seen in the wild: real unless the profile lists it
    ("simulated", ("simulated-roles: [simulated]",), True),
    ("simulation", (), True),
])
def test_hostile_payloads_reach_only_a_simulation_or_an_opted_in_real_unit(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, tmp_path: Path, role: str,
        opt_in: tuple[str, ...], sent: bool) -> None:
    """From the broker's traffic: the robustness probes are published only where the role
    is a simulation, or the user opted in; elsewhere their rules are could-not-test naming
    --allow-hostile, and the header says the decision."""
    profile = tmp_path / "unit.yaml"
    profile.write_text(f"extends: {FAST}\n" + "".join(
        f"{line}\n" for line in opt_in if not line.startswith("--")))
    flags = [o for o in opt_in if o.startswith("--")]
    unit = f"{prefix}/unit/air/{role}/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={profile}",
                      *flags, "--seed", "3", "-k", "EXEC-ROBUST", plugins=(Rebooter(sim),))
    assert "Traceback" not in run.text and "INTERNALERROR" not in run.text
    rules = run.unit_rules()
    if sent:
        assert run.result.ret == 0, run.text
        assert _wire_hostile(wire), "the probes were not sent"
        assert rules["EXEC-ROBUST-002"]["verdict"] == "pass", rules["EXEC-ROBUST-002"]
        return
    assert f"role {role!r} is treated as real" in run.text
    assert "no hostile payloads (no --allow-hostile)" in run.text
    assert _wire_hostile(wire) == []
    for rule in ("EXEC-ROBUST-001", "EXEC-ROBUST-002"):
        assert rules[rule]["verdict"] == "could-not-test", rules[rule]
        assert ("not sent: hostile payloads to a real unit need --allow-hostile (or "
                "robustness: true in the profile)") in rules[rule]["reason"], rules[rule]


def test_a_dry_run_shows_the_safety_decision_and_what_it_would_refuse(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, tmp_path: Path) -> None:
    """The header says the decision, and a profile's downgrade of errors (forged or not)."""
    profile = tmp_path / "downgrading.yaml"
    profile.write_text(f"extends: {MATRIX}\nseverity: {{'HB-01*': warning}}\n")
    unit = f"{prefix}/unit/air/live/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={profile}",
                      "--dry-run", "--seed", "3", "-k", "EXEC-ROBUST or EXEC-START-001",
                      plugins=(Rebooter(sim),))
    assert wire.commands() == []
    assert ("safety:   role 'live' is treated as real (only 'simulation' or a profile's "
            "simulated-roles are simulations): no motion (no --allow-motion), no hostile "
            "payloads (no --allow-hostile)") in run.text
    assert "dry run: would not publish" in run.text
    assert "the profile downgrades 'HB-01*': warning (" in run.text
    assert "would publish" in run.text and '"name":"move-to"' not in run.text
    rules = run.unit_rules()
    assert "--allow-hostile" in rules["EXEC-ROBUST-002"]["reason"], rules["EXEC-ROBUST-002"]


def test_allow_motion_starts_only_the_profile_motion_tasks_near_the_unit(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, tmp_path: Path) -> None:
    profile = tmp_path / "drone.yaml"
    profile.write_text(f"extends: {FAST}\nname: drone\nmotion_tasks: [move-to]\n"
                       f"safe_radius: 30\n")
    unit = f"{prefix}/unit/air/real/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={profile}",
                      "--allow-motion", "--allow-hostile", "--seed", "3",
                      plugins=(Rebooter(sim),))
    assert run.result.ret == 0, run.text
    assert "motion tasks: move-to" in run.text
    # (the name EXEC-START-005 sends is certainly not a task: the unit must refuse it)
    moving = {b["task"]["name"] for _, b in started(wire) if moves(b["task"]["name"])}
    assert moving - {"waraps-conformance-no-such-task"} == {"move-to"}
    # From the broker's traffic: the motion task the flag and profile allow reached the unit,
    # and no other.
    assert set().union(*(motion_named(m.payload) for m, _ in wire.commands())) == {"move-to"}
    for m, body in started(wire):
        origin = wire.position_before(unit, m.time)
        assert origin is not None
        for point in geopoints(body["task"].get("params")):
            target = Position(point["latitude"], point["longitude"])
            assert origin.distance(target) <= 30.0, (body["task"], origin)


def test_every_started_task_is_ended_by_the_suite(pytester: pytest.Pytester, mosquitto: str,
                                                  prefix: str) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    with SimUnit(unit, mosquitto, rate=3.0) as sim, Wire(mosquitto, prefix) as wire:
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={FAST}",
                      "--seed", "3", plugins=(Rebooter(sim),))
        # After the run: the unit's own list of running tasks is empty.
        info = [m for m in wire.messages if m.topic == f"{unit}/direct_execution_info"][-1]
    assert run.result.ret == 0, run.text
    assert orjson.loads(info.payload)["tasks-executing"] == []


def test_a_task_whose_abort_went_unanswered_is_not_aborted_in_every_scenario() -> None:
    """i20 6: teardown between scenarios (abort_all(stuck=False)) leaves out a task whose
    $abort went unanswered (8 aborts of 5 s each in one run before); the run's last teardown
    tries it once more; a unit that answered no signal-task gets a fifth of the deadline."""
    from conformance.scenarios.commander import Commander
    from conformance.scenarios.traffic import Traffic

    unit = UnitAddress.parse("waraps/unit/air/real/dji0")
    traffic = Traffic(unit)
    published: list[dict] = []

    def publish(topic: str, payload: bytes) -> None:
        body = orjson.loads(payload)
        published.append(body)
        if body["command"] == "start-task":  # runs; signals go unanswered
            traffic.add(Message(1000.0 + len(published), unit.topic("exec/response"),
                                orjson.dumps({"response": "running", "com-uuid": "x",
                                              "response-to": body["com-uuid"],
                                              "task-uuid": body["task-uuid"]}), 0, False))

    def aborts() -> int:
        return sum(b["command"] == "signal-task" for b in published)

    commander = Commander(unit, traffic, publish, say=lambda text: None)
    commander.start_task("look-at-bearing", {}, 1.0)
    assert commander.abort_all(0.2, stuck=False) == [] and aborts() == 1
    assert commander.abort_all(0.2, stuck=False) == [] and aborts() == 1  # not again
    assert commander.abort_all(0.2) == [] and aborts() == 2  # the last teardown: once more


def test_the_profile_own_parameters_are_the_user_word_and_a_broken_copy_is_not() -> None:
    """A profile may give a section 9 task parameters its schema refuses (an agent's own
    reading of section 9): sent to a real unit as the user wrote them (positions made safe);
    the refusal probe made from them (one parameter of the wrong type) is still hostile."""
    from conformance.scenarios.params import invalid_params, task_moves, valid_params
    from conformance.scenarios.safety import Safety
    from conformance.scenarios.sender import Sender

    unit = UnitAddress.parse("waraps/unit/air/live/dji0")
    drone = Profile(tasks=("move-to",), motion_tasks=("move-to",), task_params={"move-to": {
        "speed": 5.0, "waypoint": {"latitude": 1.0, "longitude": 2.0, "altitude": 9.0,
                                   "rostype": "GeoPoint"}}})
    safety = Safety(unit, drone, allow_motion=True, task_moves=task_moves)
    gate = MotionGate(unit, drone, allow_motion=True, task_moves=task_moves)
    origin = Position(58.39, 15.56, 2.0)

    def start(params: dict) -> bytes:
        return Sender.compose({"command": "start-task", "execution-unit": "dji0",
                               "task-uuid": "9b4c701c-e8a2-4a92-9370-87c8f57e0dc0",
                               "task": {"name": "move-to", "params": params}})[0]
    given = start(valid_params("move-to", origin, safety, 3))
    assert "TASK-001" in (MotionGate(unit, Profile(motion_tasks=("move-to",)),
                                     allow_motion=True).refusal(given) or "")  # not the user's
    assert gate.refusal(given) is None
    broken, _ = invalid_params("move-to", origin, safety, 3)
    assert "--allow-hostile" in (gate.refusal(start(broken)) or "")


def test_a_task_outside_section_9_is_started_only_with_the_profile_parameters(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, tmp_path: Path) -> None:
    """From the broker's traffic: a unit offering go-home (variant own-task)
    is never sent it with invented parameters; without parameters in the profile the rules
    that needed it say could-not-test naming them; with them it is started with exactly
    those."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    bare, given = tmp_path / "bare.yaml", tmp_path / "given.yaml"
    bare.write_text(f"extends: {FAST}\ntasks: [go-home]\n")
    given.write_text(f"extends: {FAST}\ntasks: {{go-home: {{params: {{speed: 3.0}}}}}}\n")
    runs = {}
    for path in (bare, given):
        with SimUnit(unit, mosquitto, rate=3.0, variants=["own-task"]) as sim, \
                Wire(mosquitto, prefix) as wire:
            run = certify(pytester, "--unit", unit, "--broker", mosquitto,
                          f"--profile={path}", "--seed", "3", "-k", "EXEC-START-001",
                          plugins=(Rebooter(sim),))
        runs[path] = (run, [b["task"] for _, b in started(wire)])
    run, tasks = runs[bare]
    assert tasks == [], tasks
    reason = run.unit_rules()["EXEC-START-001"]["reason"]
    assert ("no task to start: go-home has no parameters in the profile and is not a section "
            "9 task; add tasks: {go-home: {params: ...}} to the profile") in reason, reason
    run, tasks = runs[given]
    assert run.result.ret == 0, run.text
    assert tasks and all(t == {"name": "go-home", "params": {"speed": 3.0}} for t in tasks)

"""The variants that are readings of units written elsewhere from the spec alone: each changes
exactly what it names (as ``test_variants.py`` shows for the others, on the same script and
simulated time). That each is certified and linted clean: tests/plugin/test_plugin_variants.py.
"""

from __future__ import annotations

import orjson
import pytest
from test_variants import ADDRESS, T1, Run, com

from conformance.checks import Monitor
from conformance.client import BrokerURL, MqttClient
from conformance.message import Message
from conformance.profile import Profile
from conformance.sim import SimUnit
from conformance.sim.variants import PREPARING_SECONDS, REBOOT_AWAY
from conformance.topics import UnitAddress

START = (1.0, "exec", {"com-uuid": com(60), "command": "start-task", "execution-unit": "dji0",
                       "sender": "commander", "task-uuid": T1,
                       "task": {"name": "look-at-bearing", "params": {"bearing": 1.0}}})


@pytest.fixture(scope="module")
def plain() -> Run:
    return Run()


def test_both_sensor_info_sends_each_sensor_info_again_on_5_2s_spelling(plain: Run) -> None:
    run = Run("both-sensor-info")
    underscore, dotted = run.messages("/sensor_info"), run.messages("/sensor.info")
    assert len(underscore) >= 10
    assert [m for _, m in dotted] == [m for _, m in underscore]
    assert [(t, m) for t, m in run.messages() if t != "/sensor.info"] == plain.messages()


def test_preparing_status_says_preparing_for_its_seconds_then_running(plain: Run) -> None:
    script = [START]
    base, run = (Run(script=script, seconds=4.0),
                 Run("preparing-status", script=script, seconds=4.0))

    def statuses(r: Run) -> list[tuple[float, str]]:
        return [(when, orjson.loads(p)["status"]) for when, t, p in r.sent
                if t == "/exec/feedback"]

    assert [s for _, s in statuses(base)][:1] == ["running"]
    (prepared, first), (ready, second) = statuses(run)[:2]
    assert (first, second) == ("preparing", "running")
    assert prepared == START[0] and ready - prepared == pytest.approx(PREPARING_SECONDS, abs=0.1)
    assert [s for _, s in statuses(run)[2:]] == [s for _, s in statuses(base)[1:]]
    assert [(t, m) for t, m in run.messages() if t != "/exec/feedback"] == [
        (t, m) for t, m in base.messages() if t != "/exec/feedback"]
    # Ended while preparing ($enough 0.8 s after the start): no 'running' after its end.
    ended = [m["status"] for _, m in Run("preparing-status").messages("/exec/feedback")
             if m["task-uuid"] == T1]
    assert ended == ["preparing", "finished"]
    assert [m["status"] for _, m in plain.messages("/exec/feedback")
            if m["task-uuid"] == T1] == ["running", "finished"]


def test_paused_not_executing_lists_a_task_only_while_it_is_not_paused() -> None:
    script = [START,
              (2.0, "exec", {"com-uuid": com(61), "command": "signal-task",
                             "sender": "commander", "signal": "$pause", "task-uuid": T1}),
              (3.5, "exec", {"com-uuid": com(62), "command": "signal-task",
                             "sender": "commander", "signal": "$continue", "task-uuid": T1})]
    plain, run = Run(script=script, seconds=4.5), Run("paused-not-executing", script=script,
                                                      seconds=4.5)

    def listed(r: Run) -> list[tuple[float, bool]]:
        return [(when, any(e["task-uuid"] == T1 for e in orjson.loads(p)["tasks-executing"]))
                for when, t, p in r.sent if t == "/direct_execution_info"]

    def paused(when: float) -> bool:
        return 2.0 <= when < 3.5  # the signals come before that moment's info

    assert all(shown for when, shown in listed(plain) if 1.0 < when < 4.5)
    assert [shown for when, shown in listed(run) if 1.0 < when < 4.5] == [
        not paused(when) for when, _ in listed(run) if 1.0 < when < 4.5]
    assert any(paused(when) for when, _ in listed(run))
    assert [(t, m) for t, m in run.messages() if t != "/direct_execution_info"] == [
        (t, m) for t, m in plain.messages() if t != "/direct_execution_info"]


def judged(run: Run, script: list) -> dict[str, str]:
    """Every rule's verdict by a Monitor (the default profile) on ``run``'s traffic and the
    script's exec commands, as lint would judge their recording: rule -> verdict."""
    at = 1.7e9  # Run's clock: stamps are 1.7e9 + its time
    messages = [Message(at + when, ADDRESS.base + sub, payload, 0, False)
                for when, sub, payload in run.sent]
    messages += [Message(at + when - 0.001, f"{ADDRESS.base}/exec/command", orjson.dumps(body),
                         0, False) for when, _, body in script]
    monitor = Monitor(Profile())
    for m in sorted(messages, key=lambda m: m.time):
        monitor.feed(m)
    monitor.finish(at + run.now)
    rules = monitor.report().units[str(ADDRESS)].rules
    return {r: res.verdict.value for r, res in rules.items()}


def accused(verdicts: dict[str, str]) -> dict[str, str]:
    """The rules failed or warned."""
    return {r: v for r, v in verdicts.items() if v in ("fail", "warn")}


def test_a_long_pause_of_a_task_left_out_of_tasks_executing_is_no_end() -> None:
    """Paused for 10 s (past every deadline of the default profile) while left out of
    tasks-executing, then continued and aborted: judged clean, as the plain unit's run."""
    script = [START, *[(when, "exec", {"com-uuid": com(i), "command": "signal-task",
                                       "sender": "commander", "signal": signal,
                                       "task-uuid": T1})
                       for i, (when, signal) in enumerate(
                           [(2.0, "$pause"), (12.0, "$continue"), (14.0, "$abort")], 70)]]
    assert accused(judged(Run(script=script, seconds=16.0), script)) == {}
    assert accused(judged(Run("paused-not-executing", script=script, seconds=16.0),
                          script)) == {}


@pytest.mark.parametrize("variant,warns", [
    ("both-sensor-info", {"ERR-001": "warn"}), ("preparing-status", {"EXEC-FB-002": "warn"})])
def test_judged_on_its_traffic_a_variant_warns_only_on_its_reading(variant: str,
                                                                  warns: dict[str, str]) -> None:
    """Each stream of SensorInfo at its rate (SI-002 judged, and passed); 'preparing' a
    task-specific status the unit did not declare (EXEC-FB-002, decided)."""
    script = [START]
    verdicts = judged(Run(variant, script=script, seconds=12.0), script)
    assert accused(verdicts) == warns
    assert verdicts["SI-002"] == "pass"
    assert accused(judged(Run(script=script, seconds=12.0), script)) == {}


def test_reboot_away_is_silent_for_its_seconds_then_back_with_a_new_agent_uuid() -> None:
    script = [(1.0, "reboot", b"")]
    plain, run = (Run(script=script, seconds=7.0),
                  Run("reboot-away", script=script, seconds=7.0))

    def silence(r: Run) -> float:
        beats = [when for when, t, _ in r.sent if t == "/heartbeat"]
        return max(b - a for a, b in zip(beats, beats[1:], strict=False))

    assert silence(plain) < 2.0
    assert REBOOT_AWAY <= silence(run) < REBOOT_AWAY + 1.0 / 2.0 + 0.1
    assert len({m["agent-uuid"] for _, m in run.messages("/heartbeat")}) == 2


def test_mqtt5_qos1_connects_with_mqtt_5_and_publishes_at_qos_1(mosquitto: str,
                                                                 unit_address: UnitAddress
                                                                 ) -> None:
    """On a real broker (amqtt refuses MQTT 5): a subscriber at QoS 1 gets every message of
    the variant at QoS 1 and the plain unit's at QoS 0."""
    seen: dict[str, set[int]] = {}
    with MqttClient(BrokerURL.parse(mosquitto)) as listener:
        listener.subscribe(f"{unit_address.prefix}/#", qos=1)
        plain = unit_address.with_name("dji1")
        with SimUnit(unit_address, mosquitto, variants=["mqtt5-qos1"], rate=4.0) as unit, \
                SimUnit(plain, mosquitto, rate=4.0):
            assert unit.runtime.client is not None and unit.runtime.client.mqtt5
            for m in listener.messages(1.0):
                seen.setdefault(m.topic.split("/")[4], set()).add(m.qos)
    assert seen == {"dji0": {1}, "dji1": {0}}


"""The variants that are readings of units written elsewhere from the spec alone: each changes
exactly what it names (as ``test_variants.py`` shows for the others, on the same script and
simulated time). That each is certified and linted clean: tests/plugin/test_plugin_variants.py.
"""

from __future__ import annotations

import orjson
import pytest
from test_variants import T1, Run, com

from conformance.client import BrokerURL, MqttClient
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


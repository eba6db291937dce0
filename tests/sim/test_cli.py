"""``waraps-conformance sim``: ready line, reboot by SIGHUP and by stdin, stop by SIGTERM,
fleets with per-unit faults, and usage errors that say how to fix them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import orjson
import pytest

from conformance.topics import UnitAddress


def launch(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "conformance.cli", "sim", *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def ready(proc: subprocess.Popen[str]) -> dict[str, str]:
    """The fields of the ready line (after the broker's URL line, if any)."""
    assert proc.stdout is not None
    for _ in range(3):
        line = proc.stdout.readline()
        if line.startswith("ready "):
            return dict(w.split("=", 1) for w in line.split()[1:])
    raise AssertionError(f"no ready line; stderr: {proc.stderr.read() if proc.stderr else ''}")


def uuids(obs, base: str) -> list[str]:
    return list(dict.fromkeys(orjson.loads(m.payload)["agent-uuid"]
                              for m in obs.on(f"{base}/heartbeat")))


def test_reboots_on_sighup_and_on_stdin_and_stops_on_sigterm(observe, mosquitto: str,
                                                             unit_address: UnitAddress) -> None:
    obs = observe(mosquitto, f"{unit_address.base}/#")
    proc = launch("--unit", str(unit_address), "--broker", mosquitto, "--rate", "5")
    try:
        fields = ready(proc)
        assert fields["pid"] == str(proc.pid) and fields["unit"] == str(unit_address)
        first = fields["agent-uuid"]
        obs.wait_for(lambda _: uuids(obs, unit_address.base) == [first], timeout=10,
                     what="heartbeats of the first life")
        os.kill(proc.pid, signal.SIGHUP)  # what --reboot-cmd "kill -HUP <pid>" does
        obs.wait_for(lambda _: len(uuids(obs, unit_address.base)) == 2, timeout=10,
                     what="a new agent-uuid after SIGHUP")
        assert proc.stdin is not None
        proc.stdin.write("reboot\n")
        proc.stdin.flush()
        obs.wait_for(lambda _: len(uuids(obs, unit_address.base)) == 3, timeout=10,
                     what="a new agent-uuid after 'reboot' on stdin")
        proc.terminate()
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


def test_fleet_with_a_fault_on_one_unit_on_its_own_embedded_broker(observe) -> None:
    proc = launch("--broker", "embedded", "--unit", "fl/unit/surface/simulation/usv0",
                  "--count", "3", "--rate", "5", "--fault", "heading-signed@1", "--seed", "1")
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        assert url.startswith("mqtt://127.0.0.1:")
        fields = ready(proc)
        assert fields["count"] == "3" and fields["broker"] == url
        obs = observe(url, "fl/#")
        obs.wait_for(lambda _: all(obs.on(f"usv{i}/sensor/heading") for i in range(3)),
                     timeout=10, what="headings of usv0..usv2")
        headings = {i: float(obs.on(f"usv{i}/sensor/heading")[-1].payload) for i in range(3)}
        assert headings[1] < 0 <= headings[0] and headings[2] >= 0  # only usv1 is faulty
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


@pytest.mark.parametrize("args, message", [
    (["--fault", "heartbeat-rate-drfit"], "did you mean heartbeat-rate-drift"),
    (["--fault", "dropouts@7", "--count", "2"], "not a unit index from 0 to 1"),
    (["--variant", "strikt"], "did you mean strict"),
    (["--variant", "terse", "--variant", "verbose"], "cannot be combined"),
    (["--variant", "mqtt5-qos1", "--broker", "embedded"], "amqtt broker refuses it"),
    (["--unit", "waraps/unit/boat/real/x"], "agent type 'boat'"),
    (["--rate", "0"], "positive number of Hz"),
    (["--broker", "http://example"], "scheme 'http'"),
    (["--tst-operator", "waraps/unit/ground/real/op0"], "--tst-operator needs --tst"),
    (["--tst", "--tst-operator", "op0"], "PREFIX1/unit/TYPE/ROLE/UNIT"),
])
def test_usage_errors_say_how_to_fix(args: list[str], message: str) -> None:
    out = subprocess.run([sys.executable, "-m", "conformance.cli", "sim", *args],
                         capture_output=True, text=True, timeout=30)
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_unreachable_broker_is_one_clear_error() -> None:
    from conformance.broker import free_port

    out = subprocess.run([sys.executable, "-m", "conformance.cli", "sim", "--broker",
                          f"mqtt://127.0.0.1:{free_port()}"], capture_output=True, text=True,
                         timeout=30)
    # 3, as lint, record and profile say an unreachable broker
    assert out.returncode == 3 and "cannot reach the broker" in out.stderr


def test_tst_unit_takes_trees_from_the_operators_topic(observe, mosquitto: str,
                                                       unit_address: UnitAddress) -> None:
    operator = unit_address.with_name("op0")
    obs = observe(mosquitto, f"{unit_address.prefix}/#", (operator.topic("tst/command"),))
    proc = launch("--unit", str(unit_address), "--broker", mosquitto, "--rate", "5", "--tst",
                  "--tst-operator", str(operator), "--task-seconds", "1")
    try:
        fields = ready(proc)
        assert fields["tst"] == "on" and fields["operator"] == str(operator)
        root = "5184d315-15c4-42d4-a647-fa74f794c03b"
        com = obs.send({"command": "start-tst", "tst": {
            "name": "look-at-bearing", "params": {"bearing": 90.0}, "children": [],
            "common_params": {"execunit": f"/{unit_address.name}", "node-uuid": root}}},
            topic=operator.topic("tst/command"))
        answer = obs.wait_for(lambda _: next((r for r in obs.json_on(operator.topic(
            "tst/response")) if r.get("response-to") == com), None), 10, "the start-tst answer")
        assert (answer["response"], answer["root-uuid"]) == ("started", root)
        info = obs.wait_for(lambda _: [i for i in obs.json_on(unit_address.topic(
            "tst_execution_info")) if i["nodes-executing"]], 10, "the tree in tst_execution_info")
        assert info[0]["nodes-executing"][0]["node-uuid"] == root
        proc.terminate()
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)

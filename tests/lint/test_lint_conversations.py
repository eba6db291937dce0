"""Lint judges conversations from recorded traffic, and blames the right party: the reference
unit on Mosquitto, a commander that sends it good, resent, malformed and unknown commands, and
``waraps-conformance lint`` of the recording."""

from __future__ import annotations

import threading
import time
import uuid
from pathlib import Path

import orjson
import pytest
from lint_helpers import run_lint, write_recording

from conformance.client import BrokerURL, Message, MqttClient
from conformance.sim import SimUnit

pytestmark = pytest.mark.mosquitto


class Recorder:
    """Everything under a topic filter, kept in arrival order."""

    def __init__(self, broker: str, topic_filter: str) -> None:
        self.messages: list[Message] = []
        self._new = threading.Condition()
        self.client = MqttClient(BrokerURL.parse(broker), on_message=self._keep)
        self.client.connect()
        self.client.subscribe(topic_filter, qos=1)

    def _keep(self, m: Message) -> None:
        with self._new:
            self.messages.append(m)
            self._new.notify_all()

    def wait_for(self, found, timeout: float, what: str):  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        with self._new:
            while not (got := found(self.messages)):
                left = deadline - time.monotonic()
                assert left > 0, f"no {what} within {timeout} s"
                self._new.wait(min(left, 0.2))
            return got

    def answered(self, com_uuid: str) -> bool:
        return any(m.topic.endswith("/exec/response") and com_uuid.encode() in m.payload
                   for m in self.messages)


def test_a_commanders_faults_are_on_its_row_and_the_unit_has_none(mosquitto: str, tmp_path: Path,
                                                                  prefix: str) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    command_topic = f"{unit}/exec/command"
    with SimUnit(unit, mosquitto, rate=2.0, seed=1, task_seconds=1.0) as sim:
        rec = Recorder(mosquitto, f"{prefix}/#")
        op0 = MqttClient(BrokerURL.parse(mosquitto), may_publish=lambda t: t == command_topic)
        op0.connect()
        try:
            rec.wait_for(lambda ms: sum(m.topic.endswith("/heartbeat") for m in ms) >= 2, 10,
                         "two heartbeats")

            def send(body: dict | bytes) -> str:
                payload = body if isinstance(body, bytes) else orjson.dumps(body)
                op0.publish(command_topic, payload, qos=1)
                return str(body.get("com-uuid", "")) if isinstance(body, dict) else ""

            def cmd(command: str, **extra) -> dict:  # type: ignore[no-untyped-def]
                return {"com-uuid": str(uuid.uuid4()), "command": command, "sender": "op0",
                        **extra}

            ping = cmd("ping")
            task = str(uuid.uuid4())
            start = cmd("start-task", **{"task-uuid": task, "task": {
                "name": "look-at-bearing", "params": {"bearing": 45.0}}})
            reused = cmd("ping")
            last = cmd("query-status", **{"task-uuid": task})
            for body in (ping, ping, start, start):  # each sent twice: resends (12.1)
                send(body)
            bad = str(uuid.uuid4())
            send(b'{"com-uuid": "' + bad.encode() + b'", "command": "signal-task", '
                 b'"sender": "op0", signal: $abort}')  # 12.2.2's example: not JSON
            send(cmd("fly-to-the-moon"))  # not one of the four commands
            send(cmd("signal-task", **{"task-uuid": task, "signal": {"name": "$enough"}}))
            send({"command": "ping", "sender": "op0"})  # no com-uuid
            send(reused)
            send({**reused, "command": "query-status", "task-uuid": task})  # its com-uuid again
            send(cmd("signal-task", **{"task-uuid": task, "signal": "$abort"}))
            send(last)
            rec.wait_for(lambda ms: rec.answered(last["com-uuid"]), 10, "an answer to the last")
            n = sum(m.topic.endswith("/heartbeat") for m in rec.messages)
            rec.wait_for(lambda ms: sum(m.topic.endswith("/heartbeat") for m in ms) >= n + 4,
                         10, "four more heartbeats")  # the answers' deadlines pass
        finally:
            op0.close()
            rec.client.close()
        assert sim.core.commands >= 12
    recording = write_recording(tmp_path / "op0.jsonl", rec.messages)
    run = run_lint(["--from", str(recording)], tmp_path / "reports")
    assert run.report is not None
    rows = run.report["units"]
    commander = rows["commander op0"]
    failed = {r for r, res in commander["rules"].items() if res["verdict"] == "fail"}
    assert commander["party"] == "commander"
    assert failed == {"MSG-002", "EXEC-001", "EXEC-008"}, run.out
    me = rows[unit]
    assert {r: res["reason"] for r, res in me["rules"].items()
            if res["verdict"] in ("fail", "warn")} == {}, run.out
    # The unit's side of every conversation was judged, and passed.
    for rule in ("EXEC-PING-001", "EXEC-PING-002", "EXEC-START-001", "EXEC-START-002",
                 "EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-ROBUST-002", "EXEC-SIG-001",
                 "EXEC-SIG-002", "EXEC-QUERY-001", "EXEC-006", "EXEC-009"):
        assert me["rules"][rule]["verdict"] == "pass", (rule, me["rules"][rule])
    assert run.code == 1  # the commander failed
    assert "FAIL: commander op0" in run.out
    gated = run_lint(["--from", str(recording), "--gate", "units"], tmp_path / "gated")
    assert gated.code == 0 and ": no unit fails a rule of severity error" in gated.out, gated.out

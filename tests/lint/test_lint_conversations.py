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
    # Every start-task named its task-uuid: 12.1's generated one was never asked for
    assert me["rules"]["EXEC-START-002"]["verdict"] == "skip", me["rules"]["EXEC-START-002"]
    for rule in ("EXEC-PING-001", "EXEC-PING-002", "EXEC-START-001",
                 "EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-ROBUST-002", "EXEC-SIG-001",
                 "EXEC-SIG-002", "EXEC-QUERY-001", "EXEC-006", "EXEC-009"):
        assert me["rules"][rule]["verdict"] == "pass", (rule, me["rules"][rule])
    assert run.code == 1  # the commander failed
    assert "FAIL: commander op0" in run.out
    gated = run_lint(["--from", str(recording), "--gate", "units"], tmp_path / "gated")
    assert gated.code == 0 and ": no unit fails a rule of severity error" in gated.out, gated.out


def _converse(mosquitto: str, prefix: str, faults: tuple[str, ...], script) -> list[Message]:  # type: ignore[no-untyped-def]
    """The reference unit with ``faults``, commanded by ``script(send, rec)``; everything
    recorded, until four heartbeats after the script (the answers' deadlines pass) or, for a
    unit that died, until the script returns."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    command_topic = f"{unit}/exec/command"
    with SimUnit(unit, mosquitto, rate=2.0, seed=3, faults=faults):
        rec = Recorder(mosquitto, f"{prefix}/#")
        op = MqttClient(BrokerURL.parse(mosquitto), may_publish=lambda t: t == command_topic)
        op.connect()
        try:
            rec.wait_for(lambda ms: sum(m.topic.endswith("/heartbeat") for m in ms) >= 2, 10,
                         "two heartbeats")

            def send(body: dict | bytes) -> str:
                payload = body if isinstance(body, bytes) else orjson.dumps(body)
                op.publish(command_topic, payload, qos=1)
                return str(body.get("com-uuid", "")) if isinstance(body, dict) else ""

            script(send, rec)
        finally:
            op.close()
            rec.client.close()
    return rec.messages


def _cmd(command: str, **extra) -> dict:  # type: ignore[no-untyped-def]
    return {"com-uuid": str(uuid.uuid4()), "command": command, "sender": "op0", **extra}


def _beats(rec: Recorder, n: int) -> None:
    have = sum(m.topic.endswith("/heartbeat") for m in rec.messages)
    rec.wait_for(lambda ms: sum(m.topic.endswith("/heartbeat") for m in ms) >= have + n, 20,
                 f"{n} more heartbeats")


def test_answers_in_flight_are_no_unit_that_stopped_answering(mosquitto: str, tmp_path: Path,
                                                             prefix: str) -> None:
    """docs/FIELD-NOTES.md 'Precision': a unit that ignores a malformed command and, inside its
    timeout, answers a ping has not stopped answering; the query-status it ignores later is
    that command's own finding. Recorded from the reference unit, linted."""
    def script(send, rec) -> None:  # type: ignore[no-untyped-def]
        send(b'{"com-uuid": "' + str(uuid.uuid4()).encode() + b'", signal: $abort}')
        ping = _cmd("ping")
        send(ping)
        rec.wait_for(lambda ms: rec.answered(ping["com-uuid"]), 10, "the pong")
        _beats(rec, 2)
        send(_cmd("query-status", **{"task-uuid": str(uuid.uuid4())}))
        _beats(rec, 14)  # 7 s: past every deadline (the profile's response timeout, 5 s)

    messages = _converse(mosquitto, prefix, ("malformed-unanswered", "query-unanswered"), script)
    run = run_lint(["--from", str(write_recording(tmp_path / "r.jsonl", messages))],
                   tmp_path / "reports")
    assert run.report is not None
    me = run.report["units"][f"{prefix}/unit/air/simulation/dji0"]["rules"]
    assert me["EXEC-ROBUST-001"]["verdict"] != "fail", run.out
    assert me["EXEC-PING-001"]["verdict"] == "pass"
    assert me["EXEC-ROBUST-002"]["verdict"] == "warn", me["EXEC-ROBUST-002"]
    assert me["EXEC-QUERY-001"]["verdict"] == "fail"


def test_a_unit_that_dies_after_answering_is_its_death_not_deafness(mosquitto: str,
                                                                   tmp_path: Path,
                                                                   prefix: str) -> None:
    """It answers a ping, then dies on a start-task without task-uuid: HB-012 names that
    command; no 'stopped answering', and the ping before stays answered."""
    def script(send, rec) -> None:  # type: ignore[no-untyped-def]
        ping = _cmd("ping")
        send(ping)
        rec.wait_for(lambda ms: rec.answered(ping["com-uuid"]), 10, "the pong")
        send(_cmd("start-task", task={"name": "look-at-bearing", "params": {"bearing": 9.0}}))
        rec.wait_for(lambda ms: sum(m.topic.endswith("/exec/command") for m in ms) >= 2, 10,
                     "the commands' echoes")

    messages = _converse(mosquitto, prefix, ("dies-on-missing-task-uuid",), script)
    # Another unit heard 10 s later: the observation went on past the death (HB-012).
    later = messages[-1].time + 10.0
    other = Message(later, f"{prefix}/unit/air/simulation/other/heartbeat", orjson.dumps({
        "agent-type": "air", "agent-uuid": str(uuid.uuid4()), "levels": ["sensor"],
        "name": "other", "rate": 1.0, "stamp": later, "type": "HeartBeat"}))
    run = run_lint(["--from", str(write_recording(tmp_path / "r.jsonl", [*messages, other]))],
                   tmp_path / "reports")
    assert run.report is not None
    me = run.report["units"][f"{prefix}/unit/air/simulation/dji0"]["rules"]
    assert me["HB-012"]["verdict"] == "fail", run.out
    assert "start-task 'look-at-bearing'" in me["HB-012"]["violations"][0]["observed"]
    assert me["EXEC-ROBUST-001"]["verdict"] != "fail", run.out
    assert me["EXEC-PING-001"]["verdict"] == "pass"
    assert me["EXEC-START-001"]["verdict"] != "fail"

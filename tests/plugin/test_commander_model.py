"""The commander asks the Monitor's model whether a task it started has ended (
one task state): its raw feedback is read only where the model holds nothing of the task."""

from __future__ import annotations

import orjson

from conformance.client import Message
from conformance.protocol import State
from conformance.scenarios.commander import Commander
from conformance.scenarios.traffic import Traffic
from conformance.topics import UnitAddress

UNIT = UnitAddress.parse("waraps/unit/air/real/dji0")


def _commander(held: dict[str, State], feedback: str | None = None
               ) -> tuple[Commander, list[dict]]:
    """A commander whose unit answers every command at once ('running', 'ok'), with
    ``feedback`` for a started task, and whose model holds ``held``."""
    traffic = Traffic(UNIT)
    published: list[dict] = []

    def publish(topic: str, payload: bytes) -> None:
        body = orjson.loads(payload)
        published.append(body)
        t = 1000.0 + len(published)
        answer = "running" if body["command"] == "start-task" else "ok"
        traffic.add(Message(t, UNIT.topic("exec/response"), orjson.dumps(
            {"response": answer, "com-uuid": "x", "response-to": body["com-uuid"],
             "task-uuid": body["task-uuid"]}), 0, False))
        if body["command"] == "start-task" and feedback:
            traffic.add(Message(t + 0.1, UNIT.topic("exec/feedback"), orjson.dumps(
                {"status": feedback, "com-uuid": "y", "task-uuid": body["task-uuid"]}), 0,
                False))

    commander = Commander(UNIT, traffic, publish, say=lambda text: None,
                          task_state=lambda task_uuid: held.get(task_uuid))
    return commander, published


def _aborts(published: list[dict]) -> int:
    return sum(b["command"] == "signal-task" for b in published)


def test_a_task_the_model_holds_ended_is_not_aborted() -> None:
    held: dict[str, State] = {}
    commander, published = _commander(held)
    sent, _ = commander.start_task("look-at-bearing", {}, 1.0)
    held[sent.body["task-uuid"]] = State.FINISHED  # no feedback in the traffic: the model's
    assert commander.is_final(sent.body["task-uuid"])
    assert commander.abort_all(0.2) == [] and _aborts(published) == 0


def test_a_task_the_model_holds_running_is_aborted_and_one_it_does_not_hold_by_feedback(
        ) -> None:
    held: dict[str, State] = {}
    commander, published = _commander(held, feedback="finished")
    running, _ = commander.start_task("look-at-bearing", {}, 1.0)
    unknown, _ = commander.start_task("look-at-bearing", {}, 1.0)
    held[running.body["task-uuid"]] = State.RUNNING
    assert not commander.is_final(running.body["task-uuid"])
    assert commander.is_final(unknown.body["task-uuid"])  # its 'finished' feedback
    assert commander.abort_all(0.2) == [running.body["task-uuid"]] and _aborts(published) == 1

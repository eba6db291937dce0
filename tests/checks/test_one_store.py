"""One task state: the unit's protocol.Model keeps every task, and the exec
conversations read and annotate its records; no second store of TaskRecords exists."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from test_sequence import TIMEOUTS, new, signal, start

from conformance.checks import Monitor
from conformance.checks.conversation import CONVERSATIONS, Conversations, conversations
from conformance.checks.exec_sequence import model_of
from conformance.protocol import Command, Model, State
from conformance.taskrecord import TaskRecord

T0 = 1_700_000_000.0  # the stream's epoch (tests/checks/conftest.py)


def _containers(x: Any, depth: int = 3) -> Iterator[Any]:
    """Every dict, list, set and tuple reachable from ``x``'s attributes (a few levels)."""
    attrs = getattr(x, "__dict__", None)
    values = list(attrs.values()) if attrs is not None else []
    for v in values:
        if isinstance(v, dict | list | set | tuple):
            yield v
        if depth and hasattr(v, "__dict__") and not isinstance(v, TaskRecord):
            yield from _containers(v, depth - 1)


def _holds_tasks(container: Any) -> bool:
    items = container.values() if isinstance(container, dict) else container
    return any(isinstance(v, TaskRecord) for v in items)


def test_the_conversations_task_is_the_models_and_there_is_one_store(stream):
    m = Monitor(TIMEOUTS)
    a, b = new(), new()
    stream.feed(m, stream.alive(6.0) + start(stream, 2.0, a) + start(stream, 3.0, b)
                + signal(stream, 4.0, a, "$pause", (4.2, a, "paused")))
    unit = m.state(stream.address)
    c = unit.stash[CONVERSATIONS]
    model = model_of(m.ctx, unit)
    assert c.model is model and c.tasks is model.tasks
    for task_uuid in (a, b):
        assert c.followed(task_uuid) is model.tasks[task_uuid]
    assert model.tasks[a].state is State.PAUSED and model.tasks[a].command is not None
    assert list(c.running) == [a, b] and [t.task_uuid for t in c.open()] == [a, b]
    stores = [x for x in _containers(c) if _holds_tasks(x)]
    assert len(stores) == 1 and stores[0] is model.tasks, "a second store of TaskRecords"
    others = [v for k, v in unit.stash._items.items() if k is not CONVERSATIONS]
    assert not any(_holds_tasks(x) for v in others for x in _containers(v))


def test_the_model_exists_whenever_the_conversations_do(stream):
    """Feedback before any command (lint joining mid-stream) makes both; the task it shows is
    the model's record, followed by the conversations."""
    m = Monitor(TIMEOUTS)
    a = new()
    stream.feed(m, stream.alive(2.0) + [stream.feedback(1.5, a, "running")])
    unit = m.state(stream.address)
    c = unit.stash[CONVERSATIONS]
    assert isinstance(c, Conversations) and c.followed(a) is c.model.tasks[a]
    assert model_of(m.ctx, unit) is c.model and c.model.state(a) is State.RUNNING


@pytest.mark.parametrize("by", ["model_of", "conversations"])
def test_either_way_in_makes_both(stream, by):
    m = Monitor(TIMEOUTS)
    unit = m.state(stream.address)
    made = model_of(m.ctx, unit) if by == "model_of" else conversations(unit, m.ctx).model
    assert unit.stash[CONVERSATIONS].model is made
    assert made.response_timeout == TIMEOUTS.response_timeout


def test_a_new_life_is_one_the_model_knows_none_of_the_tasks_of(stream):
    """12.1: after a new agent-uuid the model knows no task of the life before; their records
    stay (lost), for the conversations, which judge them by their own life."""
    m = Monitor(TIMEOUTS)
    a = new()
    stream.feed(m, stream.alive(4.0) + start(stream, 2.0, a))
    unit = m.state(stream.address)
    c = unit.stash[CONVERSATIONS]
    record = c.tasks[a]
    stream.feed(m, [stream.heartbeat(4.5, agent_uuid="another-life")])
    assert c.model.life == "another-life" and not c.running
    assert c.model.state(a) is State.UNKNOWN and c.model.live() == [] and record.lost
    assert c.followed(a) is record and record.life != c.life
    stream.feed(m, [stream.feedback(5.0, a, "running")])  # the new life names it: a new task
    assert c.tasks[a] is record and not record.lost and c.model.state(a) is State.RUNNING
    model = Model()  # a model alone forgets the records too
    model.heartbeat({"agent-uuid": "one"}, 0.0)
    model.feedback({"task-uuid": "t1", "status": "running"}, 1.0)
    model.heartbeat({"agent-uuid": "two"}, 2.0)
    assert model.tasks == {}


def _start(model, t: float, com: str, task: str | None) -> None:
    body = {"com-uuid": com, "command": "start-task", "task": {"name": "move-to"}}
    if task is not None:
        body["task-uuid"] = task
    model.command(Command.read(body), t)


def test_feedback_before_the_answer_is_that_start_tasks_task_even_once_ended():
    """12 orders no topics: a task first seen in feedback after its start-task was sent is
    that start-task's, its final status too (it was held running before: a second record)."""
    model = Model()
    _start(model, 1.0, "c1", None)
    model.feedback({"task-uuid": "t1", "status": "finished"}, 1.1)
    record = model.tasks["t1"]
    model.response({"response-to": "c1", "response": "running", "task-uuid": "t1"}, 1.2)
    assert model.tasks["t1"] is record and record.started_by == "c1"
    assert model.state("t1") is State.FINISHED


def test_a_new_task_under_an_ended_uuid_begins_in_its_record(stream):
    m = Monitor(TIMEOUTS)
    a = new()
    stream.feed(m, stream.alive(8.0) + start(stream, 2.0, a)
                + [stream.feedback(3.0, a, "finished")] + start(stream, 5.0, a))
    c = m.state(stream.address).stash[CONVERSATIONS]
    record = c.tasks[a]
    assert c.followed(a) is record and record.final is None and record.followed == pytest.approx(T0 + 5.1)
    assert record.state is State.RUNNING and list(c.running) == [a]
    assert [s for _, s in record.statuses] == ["running", "finished", "running"]

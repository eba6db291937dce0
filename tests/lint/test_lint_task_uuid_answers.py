"""Answers told by what they carry, from a capture alone (12.1, 12.3): a resent start-task
answered under its task-uuid without its com-uuid in response-to, and a second query-status
(a new com-uuid) of the same task, each a conversation of its own."""

from __future__ import annotations

from pathlib import Path

import orjson
import pytest
from lint_helpers import T0, run_lint, unit_traffic, verdicts, write_recording

from conformance.client import Message

TASK = "5c0ed702-2f6a-46b4-a1a4-ea2e86e04282"
START = "29c24bbf-88f0-4de2-97e9-4bd0d5f6bf23"


def _exec(unit: str, t: float, sub: str, body: dict) -> Message:
    return Message(T0 + t, f"{unit}/exec/{sub}", orjson.dumps(body))


def _started(unit: str, agent: str) -> list[Message]:
    """A start-task at 10 s answered 'running' (its feedback too), resent at 12 s."""
    start = {"com-uuid": START, "command": "start-task", "execution-unit": "dji0",
             "sender": "op0", "task-uuid": TASK,
             "task": {"name": "move-to", "params": {"waypoint": {
                 "latitude": 58.3946, "longitude": 15.5645, "altitude": 100.0,
                 "rostype": "GeoPoint"}}}}
    return [_exec(unit, 10.0, "command", start),
            _exec(unit, 10.1, "response", {"agent-uuid": agent, "com-uuid": f"{START[:-2]}01",
                                           "fail-reason": "", "response": "running",
                                           "response-to": START, "task-uuid": TASK}),
            _exec(unit, 10.2, "feedback", {"agent-uuid": agent, "com-uuid": f"{START[:-2]}02",
                                           "status": "running", "task-uuid": TASK}),
            _exec(unit, 12.0, "command", start)]


@pytest.mark.parametrize(("response_to", "fault"), [
    (None, "EXEC-002"),  # the schema's: response-to is missing
    ("7300d049-176f-4dcb-b0bf-151980d5611a", "EXEC-006"),  # it names no command seen
])
def test_a_resend_answered_under_its_task_uuid_alone_is_answered(
        tmp_path: Path, reports_dir: Path, prefix: str, response_to: str | None,
        fault: str) -> None:
    """The answer to a resent start-task names its task-uuid but not (or not as) its
    com-uuid: the task-uuid, which the start-task response carries (12.3.3), tells which
    command it answers, so the resend was answered (EXEC-RESEND-002 holds); the response-to
    is a fault of its own. The same traffic without that answer fails EXEC-RESEND-002."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    agent = "3887ced0-4e2d-4be4-aeff-6ba7242853a1"
    msgs = unit_traffic(prefix, "dji0", seconds=30, agent_uuid=agent) + _started(unit, agent)
    answer = {"agent-uuid": agent, "com-uuid": f"{START[:-2]}03", "fail-reason": "",
              "response": "running", "task-uuid": TASK}
    if response_to is not None:
        answer["response-to"] = response_to
    told = run_lint(["--from", str(write_recording(tmp_path / "told.jsonl", [
        *msgs, _exec(unit, 12.1, "response", answer)]))], reports_dir / "told")
    silent = run_lint(["--from", str(write_recording(tmp_path / "silent.jsonl", msgs))],
                      reports_dir / "silent")
    assert verdicts(silent.report, unit)["EXEC-RESEND-002"] in ("fail", "warn"), silent.out
    got = verdicts(told.report, unit)
    assert got["EXEC-RESEND-002"] == "pass", told.out
    assert {r for r, v in got.items() if v in ("fail", "warn")} == {fault}, told.out


QUERIES = ("638a433d-07fb-4bcf-af97-228114638907", "a1587d98-b253-4e8a-bb8c-c937693881c0")


@pytest.mark.parametrize("wrong", [0, 1])
def test_each_query_status_of_a_task_is_judged_on_its_own(
        tmp_path: Path, reports_dir: Path, prefix: str, wrong: int) -> None:
    """Two query-status of one running task, each with its own com-uuid (12.1): each is a
    conversation of its own, so an answer that contradicts the task's feedback fails
    EXEC-QUERY-001 whether it is the first or the second ('finished' while it runs)."""
    unit = f"{prefix}/unit/air/simulation/dji0"
    agent = "3887ced0-4e2d-4be4-aeff-6ba7242853a1"
    msgs = unit_traffic(prefix, "dji0", seconds=30, agent_uuid=agent) + _started(unit, agent)
    msgs = [m for m in msgs if not (m.time == T0 + 12.0 and m.topic.endswith("command"))]
    for i, (com_uuid, t) in enumerate(zip(QUERIES, (14.0, 16.0), strict=True)):
        msgs += [_exec(unit, t, "command", {"com-uuid": com_uuid, "command": "query-status",
                                             "sender": "op0", "task-uuid": TASK}),
                 _exec(unit, t + 0.1, "response", {
                     "agent-uuid": agent, "com-uuid": f"{com_uuid[:-2]}99", "fail-reason": "",
                     "response": "finished" if i == wrong else "running",
                     "response-to": com_uuid, "task-uuid": TASK})]
    run = run_lint(["--from", str(write_recording(tmp_path / "queries.jsonl", msgs))],
                   reports_dir)
    rules = run.report["units"][unit]["rules"]
    assert rules["EXEC-QUERY-001"]["verdict"] == "fail", run.out
    (found,) = rules["EXEC-QUERY-001"]["violations"]
    assert found["time"] == pytest.approx(T0 + (14.1 if wrong == 0 else 16.1)), found

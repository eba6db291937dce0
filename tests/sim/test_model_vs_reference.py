"""The model of direct execution (conformance/protocol.py) agrees with the conformant reference
unit in every order of commands: hypothesis drives the thread-free ``UnitCore`` in process
(starts, every builtin signal to running, paused, ended and unknown tasks, queries, resends,
pings, time passing) and after each command checks that its answer is one the model allowed,
that the model holds each task in the state the unit holds it, and that the sequence rules find
nothing. The same machine against a sequence fault finds it (the model's rules can fail)."""

from __future__ import annotations

import uuid

import orjson
import pytest
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.errors import Flaky
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from conformance.message import Message
from conformance.protocol import BUILTIN_SIGNALS, Command, Model, State
from conformance.sim.unit import UnitCore
from conformance.topics import UnitAddress

ADDRESS = UnitAddress("model", "air", "simulation", "dji0")
TASKS = {"look-at-bearing": {"bearing": 45.0}, "image-object-detection": {}}
"""Tasks that run until they are ended, of two kinds (camera, detector): both may run."""


class Conversation(RuleBasedStateMachine):
    faults: tuple[str, ...] = ()

    def __init__(self) -> None:
        super().__init__()
        self.now = 1000.0
        self.out: list[Message] = []
        self.core = UnitCore(ADDRESS, self._emit, faults=self.faults, rng=_rng(),
                             task_seconds=1.0, clock=lambda: self.now)
        self.core.start(self.now)
        self.model = Model(whole_life=True, response_timeout=5.0, feedback_timeout=10.0)
        self.sent: list[dict] = []
        self.findings: list = []
        self._feed()

    def _emit(self, topic: str, payload: bytes, retain: bool) -> None:
        self.out.append(Message(self.now, topic, payload))

    def _feed(self) -> None:
        for m in self.out:
            self.findings += self.model.observe(m)
        self.out.clear()

    def _send(self, body: dict) -> None:
        cmd = Command.read(body)
        assert cmd is not None
        allowed = self.model.expect(cmd).responses
        self.now += 0.05
        msg = Message(self.now, ADDRESS.topic("exec/command"), orjson.dumps(body))
        self.findings += self.model.observe(msg)
        self.core.command(msg.payload, self.now)
        answers = [orjson.loads(m.payload)["response"] for m in self.out
                   if m.topic.endswith("/exec/response")]
        self._feed()
        assert len(answers) == 1, (body, answers)
        assert answers[0] in allowed, (body, answers[0], allowed)
        self.sent.append(body)

    def _cmd(self, command: str, **extra: object) -> dict:
        return {"com-uuid": str(uuid.uuid4()), "command": command, "sender": "model", **extra}

    def _tasks(self) -> list[str]:
        return list(self.model.tasks)

    @rule(name=st.sampled_from(sorted(TASKS)), with_uuid=st.booleans())
    def start(self, name: str, with_uuid: bool) -> None:
        extra: dict = {"task": {"name": name, "params": TASKS[name]}}
        if with_uuid:
            extra["task-uuid"] = str(uuid.uuid4())
        self._send(self._cmd("start-task", **extra))

    @precondition(lambda self: self.model.tasks)
    @rule(data=st.data(), signal=st.sampled_from(BUILTIN_SIGNALS))
    def signal(self, data: st.DataObject, signal: str) -> None:
        task = data.draw(st.sampled_from(self._tasks()))
        self._send(self._cmd("signal-task", signal=signal, **{"task-uuid": task}))

    @precondition(lambda self: self.model.live())
    @rule(data=st.data(), signal=st.sampled_from(BUILTIN_SIGNALS))
    def signal_live(self, data: st.DataObject, signal: str) -> None:
        """Most signals go to a live task: pause, then abort, is where bugs live."""
        task = data.draw(st.sampled_from(self.model.live()))
        self._send(self._cmd("signal-task", signal=signal, **{"task-uuid": task}))

    @precondition(lambda self: self.model.running())
    @rule(data=st.data(), then=st.sampled_from(BUILTIN_SIGNALS))
    def pause_then(self, data: st.DataObject, then: str) -> None:
        """$pause, then another signal to the paused task (which signals a paused task takes
        is the model's decision, docs/MODEL.md)."""
        task = data.draw(st.sampled_from(self.model.running()))
        self._send(self._cmd("signal-task", signal="$pause", **{"task-uuid": task}))
        self._send(self._cmd("signal-task", signal=then, **{"task-uuid": task}))

    @rule(signal=st.sampled_from(BUILTIN_SIGNALS))
    def signal_unknown(self, signal: str) -> None:
        self._send(self._cmd("signal-task", signal=signal, **{"task-uuid": str(uuid.uuid4())}))

    @precondition(lambda self: self.model.tasks)
    @rule(data=st.data())
    def query(self, data: st.DataObject) -> None:
        task = data.draw(st.sampled_from(self._tasks()))
        self._send(self._cmd("query-status", **{"task-uuid": task}))

    @precondition(lambda self: self.sent)
    @rule(data=st.data())
    def resend(self, data: st.DataObject) -> None:
        self._send(data.draw(st.sampled_from(self.sent)))

    @rule()
    def ping(self) -> None:
        self._send(self._cmd("ping"))

    @rule(seconds=st.sampled_from((0.5, 2.0)))
    def wait(self, seconds: float) -> None:
        end = self.now + seconds
        while self.now < end:
            self.now = min(end, max(self.core.due, self.now + 0.05))
            self.core.run(self.now)
        self._feed()

    @invariant()
    def the_model_holds_what_the_unit_holds(self) -> None:
        for task_uuid, state in self.model.states().items():
            task = self.core.tasks.get(task_uuid)
            if task is not None and not self.model.tasks[task_uuid].refused:
                assert state is State(task.status), (task_uuid, state, task.status)

    @invariant()
    def nothing_found(self) -> None:
        assert not self.findings, self.findings


def _rng():  # noqa: ANN202
    import random

    return random.Random(1)


SETTINGS = settings(settings.default, stateful_step_count=25,
                    suppress_health_check=[HealthCheck.too_slow], database=None)
"""The active profile's examples (ci: 60), each up to 25 commands or waits, in process."""


def test_the_model_agrees_with_the_reference_unit_in_every_order() -> None:
    Conversation.TestCase.settings = SETTINGS
    Conversation.TestCase().runTest()


@pytest.mark.parametrize("fault", ["abort-paused-resumes", "pause-pauses-all"])
def test_the_same_machine_finds_a_sequence_fault(fault: str) -> None:
    faulty = type(f"Faulty{fault}", (Conversation,), {"faults": (fault,)})
    # Found is what is asserted, not the shortest order: no shrinking (it took most of the
    # test's time, 5-110 s on a loaded machine); derandomized, as 60 random examples missed
    # the fault about once in 15 runs (DID NOT RAISE).
    faulty.TestCase.settings = settings(SETTINGS, phases=[Phase.explicit, Phase.generate],
                                        derandomize=True)
    with pytest.raises((AssertionError, Flaky)) as found:
        faulty.TestCase().runTest()
    assert "EXEC-SEQ-00" in str(found.value), str(found.value)[:2000]

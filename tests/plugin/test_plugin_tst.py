"""The TST level of a certification (14): the reference unit passes on both levels, TST commands
go to the one tst/command topic chosen (the unit's own or an operator's, 14.1) and nowhere else,
--dry-run prints trees and publishes nothing, and every tree started is aborted at teardown."""

from __future__ import annotations

import orjson
import pytest
from certify_helpers import FAST, MATRIX, UNIT, Rebooter, certify, certify_stalling
from test_plugin_safety import Wire

from conformance.rules import CATALOGUE, Side
from conformance.scenarios import robust
from conformance.scenarios.traffic import Traffic
from conformance.scenarios.tst_commander import TstCommander, node
from conformance.sim import SimUnit
from conformance.topics import UnitAddress

TST_RULES = sorted(r for r, rule in CATALOGUE.items()
                   if r.startswith("TST-") and rule.side is Side.UNIT)

# The fields of each command as the spec's examples write it (10, 11, 12.2, 14.3); query-status
# has no example: its schema's fields, with 'sender' as every other example has it.
FORMS: dict[str, set[str]] = {
    "ping": {"com-uuid", "command", "sender"},  # 12.2.1
    "signal-task": {"com-uuid", "command", "signal", "sender", "task-uuid"},  # 12.2.2
    "start-task": {"com-uuid", "command", "execution-unit", "sender", "task", "task-uuid"},  # 10
    "query-status": {"com-uuid", "command", "sender", "task-uuid"},  # 12.1
    "start-tst": {"com-uuid", "command", "receiver", "sender", "tst"},  # 11
    "signal-tst-node": {"com-uuid", "command", "node-uuid", "sender", "signal"},  # 14.3.1
    "signal-tst-tree": {"com-uuid", "command", "node-uuid", "sender", "signal"},  # 14.3.2
    "signal-unit": {"com-uuid", "command", "unit", "sender", "signal"},  # 14.3.3
}
NODE = {"children", "common_params", "name", "params"}  # every node of 11's examples
COMMON = {"execunit", "node-uuid"}


def deliberately_broken(payload: bytes) -> bool:
    """A robustness probe (12.1: malformed on purpose), whatever its com-uuid."""
    try:
        body = orjson.loads(payload)
    except orjson.JSONDecodeError:
        return True  # not JSON at all
    if not isinstance(body, dict):
        return True
    readable = []
    for _, probe in robust.malformed("X"):
        try:
            readable.append(orjson.loads(probe))
        except orjson.JSONDecodeError:
            continue
    return {**body, "com-uuid": "X"} in readable


def form_problems(body: dict) -> list[str]:
    """How a command differs from its example form (empty: exactly that form)."""
    command = body.get("command")
    wanted = FORMS.get(command)
    if wanted is None:
        return [f"a command the spec has no example of: {command!r}"]
    fields = set(body)
    # 12.1: task-uuid may be left out of start-task (the unit generates one).
    if fields != wanted and not (command == "start-task" and fields == wanted - {"task-uuid"}):
        return [f"{command}: fields {sorted(fields)}, the example's {sorted(wanted)}"]
    problems = []
    if command == "start-task" and set(body["task"]) != {"name", "params"}:
        problems.append(f"start-task's task {sorted(body['task'])}")
    if command == "start-tst":
        stack = [("$.tst", body["tst"])]
        while stack:
            path, node = stack.pop()
            if set(node) != NODE or set(node["common_params"]) != COMMON:
                problems.append(f"{path}: {sorted(node)} "
                                f"{sorted(node.get('common_params') or {})}")
            stack += [(f"{path}.children[{i}]", c) for i, c in enumerate(node.get("children", []))]
    return problems


@pytest.mark.slow
@pytest.mark.parametrize("where", ["own", "operator"])
def test_tst_commands_go_to_the_chosen_topic_only_and_the_unit_passes(
        pytester: pytest.Pytester, mosquitto: str, prefix: str, where: str) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    op0 = f"{prefix}/unit/ground/real/op0"
    topic = f"{unit}/tst/command" if where == "own" else f"{op0}/tst/command"
    args = ["--tst-command-topic", op0] if where == "operator" else []
    with SimUnit(unit, mosquitto, rate=3.0, seed=5, tst_execution=True,
                 tst_operator=op0 if where == "operator" else None) as sim, \
            Wire(mosquitto, prefix) as wire:
        # The matrix profile (three tasks, for trees and direct execution alike): every task
        # of the reference unit runs, on both levels, with fast.yaml in test_plugin_certify.py.
        run = certify(pytester, "--unit", unit, "--broker", mosquitto, f"--profile={MATRIX}",
                      "--seed", "5", *args, plugins=(Rebooter(sim),))
        info = [m for m in wire.messages if m.topic == f"{unit}/tst_execution_info"][-1]
    assert run.result.ret == 0, run.text
    assert {r: run.outcomes[r] for r in TST_RULES} == dict.fromkeys(TST_RULES, "passed")
    assert f"TST commands to {topic}" in run.text
    # docs/ARCHITECTURE.md 'Safety': the unit's exec/command and the one TST topic chosen, nothing
    # else.
    sent = {m.topic for m, _ in wire.commands()}
    assert sent == {f"{unit}/exec/command", topic}
    starts = [b for m, b in wire.commands() if b.get("command") == "start-tst"]
    assert starts and all(b["tst"]["common_params"]["execunit"] == "/dji0" for b in starts
                          if b["tst"]["name"] != "waraps-conformance-no-such-task")
    # 11: 'receiver' names where the command goes: the operator, or the unit itself.
    assert {b["receiver"] for b in starts} == {"op0" if where == "operator" else "dji0"}
    # Every command the suite sent has exactly the fields of the spec's example form, every
    # TST node its common_params with execunit and node-uuid (a strict unit refuses less).
    sent_forms = [(m.payload, form_problems(b)) for m, b in wire.commands()
                  if not deliberately_broken(m.payload)]
    assert {b.get("command") for m, b in wire.commands()} >= set(FORMS)  # every kind sent
    assert [(p, problems) for p, problems in sent_forms if problems] == []
    children = [c for b in starts for c in b["tst"]["children"]]
    assert children and all(set(c["common_params"]) == COMMON for c in children)
    # nothing the suite started still runs
    assert orjson.loads(info.payload)["nodes-executing"] == []


def test_dry_run_prints_the_trees_and_publishes_nothing(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "embedded", "--sim-rate", "2",
                  "--sim-tst", f"--profile={FAST}", "--dry-run", "-k", "test_tst")
    assert run.result.ret == 0, run.text
    assert f"dry run: would publish to {UNIT}/tst/command: " in run.text
    assert '"command":"start-tst"' in run.text
    assert set(run.outcomes.values()) == {"skipped"}
    assert run.unit_rules()["TST-004"]["verdict"] == "could-not-test"
    assert run.report["meta"]["commands_sent"] == "0"


@pytest.mark.parametrize(("args", "message"), [
    (["--broker", "mqtt://127.0.0.1:1883", "--sim-tst"], "runs only with --broker embedded"),
    (["--broker", "embedded", "--tst-command-topic", "op0"], "an operator's address"),
])
def test_bad_tst_options_are_usage_errors(pytester: pytest.Pytester, args: list[str],
                                          message: str) -> None:
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "--unit", UNIT, *args)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert message in "\n".join(result.errlines + result.outlines)


def test_teardown_aborts_every_tree_that_has_not_ended() -> None:
    """abort_all: signal-tst-tree $abort to the root of each tree started and not ended,
    under every name the unit gave it; refused and ended trees are left alone."""
    from conformance.client import Message

    unit = UnitAddress.parse(UNIT)
    traffic = Traffic(unit)
    published: list[dict] = []
    t = [1000.0]

    def reply(sub: str, body: dict) -> None:
        t[0] += 0.01
        traffic.add(Message(t[0], unit.topic(sub), orjson.dumps(body), 0, False))

    def publish(topic: str, payload: bytes) -> None:
        body = orjson.loads(payload)
        published.append(body)
        com = body["com-uuid"]
        if body["command"] == "start-tst":
            root = body["tst"]["common_params"]["node-uuid"]
            answer = "failed" if root == "refused" else "started"
            reply("tst/response", {"response": answer, "response-to": com, "root-uuid": root,
                                   "com-uuid": "x", "fail-reason": ""})
            if root == "ended":
                reply("tst/feedback", {"node-uuid": root, "status": "succeeded"})
        else:
            reply("tst/response", {"response": "ok", "response-to": com, "com-uuid": "y"})

    tc = TstCommander(unit, unit.topic("tst/command"), traffic, publish)
    for root in ("runs", "refused", "ended"):
        tc.start(node("look-at-bearing", {}, root, execunit="/dji0"), 1.0)
    assert tc.abort_all(1.0) == ["runs"]
    aborts = [b for b in published if b["command"] == "signal-tst-tree"]
    assert [(b["node-uuid"], b["signal"]) for b in aborts] == [("runs", "$abort")]
    assert tc.abort_all(1.0) == [] and tc.open_trees == {}


@pytest.mark.slow
@pytest.mark.parametrize(("fault", "adapted"), [
    ("tst-abort-ignored", "TST-012"),  # $abort answered 'ok', not done: noted once
    ("tst-no-final-feedback", None),  # seq and conc: awaited until their task nodes ended
    ("tst-root-uuid-wrong", "TST-004"),  # trees followed under the node-uuid feedback uses
])
def test_a_stalling_tst_fault_ends_within_the_deadline(pytester: pytest.Pytester,
                                                       prefix: str, fault: str,
                                                       adapted: str | None) -> None:
    # In virtual time (the deadline is the unit's time): test_plugin_trust keeps one
    # stalling fault end to end on Mosquitto.
    run = certify_stalling(pytester, None, prefix, fault)
    if adapted:
        assert run.text.count(f"adapted to {adapted}:") == 1, run.text[-3000:]


def test_a_stuck_tree_is_aborted_again_only_by_the_last_teardown() -> None:
    """i20 6: a tree whose $abort went unanswered is not aborted again between scenarios
    (abort_all(stuck=False)); the run's last teardown (stuck=True) tries it once more."""
    from conformance.client import Message

    unit = UnitAddress.parse(UNIT)
    traffic = Traffic(unit)
    published: list[dict] = []

    def publish(topic: str, payload: bytes) -> None:
        body = orjson.loads(payload)
        published.append(body)
        if body["command"] == "start-tst":  # started; every signal then goes unanswered
            traffic.add(Message(1000.0 + len(published), unit.topic("tst/response"),
                                orjson.dumps({"response": "started", "com-uuid": "x",
                                              "response-to": body["com-uuid"],
                                              "root-uuid": "stuck", "fail-reason": ""}), 0,
                                False))

    def aborts() -> int:
        return sum(b["command"] == "signal-tst-tree" for b in published)

    tc = TstCommander(unit, unit.topic("tst/command"), traffic, publish)
    tc.start(node("look-at-bearing", {}, "stuck", execunit="/dji0"), 1.0)
    assert tc.abort_all(0.2, stuck=False) == [] and aborts() == 1
    assert tc.abort_all(0.2, stuck=False) == [] and aborts() == 1  # not again
    assert tc.abort_all(0.2) == [] and aborts() == 2  # the last teardown: once more

"""The model of direct execution (conformance/protocol.py) and the sequence rules the Monitor
judges with it (checks/exec_sequence.py): each rule passing on conformant traffic and failing
on the faulty one, with no other rule of direct execution failing."""

from __future__ import annotations

import uuid

import orjson

from conformance.checks import Monitor
from conformance.profile import Profile
from conformance.protocol import BUILTIN_SIGNALS, NEW_TASK, SIGNAL_RULE, Command, Model, State
from conformance.violation import Verdict

TIMEOUTS = Profile(response_timeout=1.0, feedback_timeout=3.0)
SEQ = ("EXEC-SEQ-001", "EXEC-SEQ-002")


def new() -> str:
    return str(uuid.uuid4())


def judge(stream, extra, seconds: float = 20.0):
    m = Monitor(TIMEOUTS)
    stream.feed(m, stream.alive(seconds) + extra)
    m.finish()
    return m.report().units[str(stream.address)].rules


def failing(rules) -> set[str]:
    return {r for r, x in rules.items() if x.verdict is Verdict.FAIL}


WAYPOINT = {"latitude": 58.4, "longitude": 15.6, "altitude": 10.0, "rostype": "GeoPoint"}


def start(stream, t: float, task: str) -> list:
    """A move-to (the one task the stream's unit offers) answered 'running'."""
    cmd = stream.command(t, "start-task", **{"task-uuid": task, "task": {
        "name": "move-to", "params": {"waypoint": WAYPOINT, "speed": "slow"}}})
    com = orjson.loads(cmd.payload)["com-uuid"]
    return [cmd, stream.response(t + 0.1, com, "running", **{"task-uuid": task,
                                                             "fail-reason": ""}),
            stream.feedback(t + 0.2, task, "running")]


def signal(stream, t: float, task: str, sig: str, *then: tuple[float, str, str],
           answer: str = "ok") -> list:
    """A signal answered ``answer`` at t + 0.1, then feedback (time, task, status)."""
    cmd = stream.command(t, "signal-task", signal=sig, **{"task-uuid": task})
    com = orjson.loads(cmd.payload)["com-uuid"]
    out = [cmd, stream.response(t + 0.1, com, answer, **{"task-uuid": task,
                                                        "fail-reason": ""})]
    return out + [stream.feedback(tt, task_uuid, status) for tt, task_uuid, status in then]


# --- EXEC-SEQ-001: a task stops once $abort or $enough is answered 'ok' -----------------------

def test_a_paused_task_aborted_passes_and_one_that_resumes_on_abort_fails(stream):
    a = new()
    before = start(stream, 2.0, a) + signal(stream, 3.0, a, "$pause", (3.2, a, "paused"))
    ok = judge(stream, before + signal(stream, 5.0, a, "$abort", (5.2, a, "aborted")))
    assert ok["EXEC-SEQ-001"].verdict is Verdict.PASS
    assert not failing(ok)
    bad = judge(stream, before + signal(stream, 5.0, a, "$abort", (5.2, a, "running"),
                                        (5.9, a, "aborted")))
    assert failing(bad) == {"EXEC-SEQ-001"}
    v = bad["EXEC-SEQ-001"].violations[0]
    assert "resumed from 'paused'" in v.observed and a in v.expected


def test_running_long_after_abort_fails_but_in_flight_or_winding_down_on_enough_does_not(
        stream):
    a = new()
    before = start(stream, 2.0, a)
    in_flight = judge(stream, before + signal(stream, 5.0, a, "$abort", (5.15, a, "running"),
                                              (5.5, a, "aborted")))
    assert in_flight["EXEC-SEQ-001"].verdict is Verdict.PASS and not failing(in_flight)
    on = judge(stream, before + signal(stream, 5.0, a, "$abort", (6.5, a, "running"),
                                       (7.0, a, "aborted")))
    assert failing(on) == {"EXEC-SEQ-001"}
    assert "still 'running'" in on["EXEC-SEQ-001"].violations[0].observed
    # 12.2.2's $enough: the task ends its own way, and may say 'running' until 'finished'
    wind_down = judge(stream, before + signal(stream, 5.0, a, "$enough", (6.5, a, "running"),
                                              (7.0, a, "finished")))
    assert not failing(wind_down) and wind_down["EXEC-SIG-004"].verdict is Verdict.PASS


def test_abort_accepted_in_12_1s_words_is_judged_as_an_ok(stream):
    """12.3.2 is empty and 12.1 gives 'running, failed, finished': a signal answered
    'running' (or 'finished') is accepted, and what an accepted $abort does applies."""
    a = new()
    before = start(stream, 2.0, a)
    for word in ("running", "finished"):
        ok = judge(stream, before + signal(stream, 5.0, a, "$abort", (5.2, a, "aborted"),
                                           answer=word))
        assert {r: ok[r].verdict for r in SEQ + ("EXEC-SIG-002",)} == dict.fromkeys(
            SEQ + ("EXEC-SIG-002",), Verdict.PASS), word
        assert not failing(ok)
    goes_on = judge(stream, before + signal(stream, 5.0, a, "$abort", (6.5, a, "running"),
                                            answer="running"))
    assert failing(goes_on) == {"EXEC-SEQ-001", "EXEC-SIG-002"}
    v = goes_on["EXEC-SEQ-001"].violations[0]
    assert "answered 'running'" in v.expected and "still 'running'" in v.observed
    # A refusal accepts nothing: no feedback is owed, and the task runs on.
    refused = judge(stream, before + signal(stream, 5.0, a, "$abort", (6.5, a, "running"),
                                            answer="failed"))
    assert not failing(refused) and refused["EXEC-SEQ-001"].verdict is Verdict.SKIP


def test_a_pause_accepted_with_running_that_pauses_another_task_fails(stream):
    a, b = new(), new()
    both = start(stream, 2.0, a) + start(stream, 3.0, b)
    bad = judge(stream, both + signal(stream, 5.0, b, "$pause", (5.2, b, "paused"),
                                      (5.25, a, "paused"), answer="running"))
    assert failing(bad) == {"EXEC-SEQ-002"}


# --- EXEC-SEQ-002: a signal changes only the task it names -----------------------------------

def test_pause_of_one_task_passes_and_a_pause_that_pauses_another_fails(stream):
    a, b = new(), new()
    both = start(stream, 2.0, a) + start(stream, 3.0, b)
    ok = judge(stream, both + signal(stream, 5.0, b, "$pause", (5.2, b, "paused")))
    assert ok["EXEC-SEQ-002"].verdict is Verdict.PASS and not failing(ok)
    bad = judge(stream, both + signal(stream, 5.0, b, "$pause", (5.2, b, "paused"),
                                      (5.25, a, "paused")))
    assert failing(bad) == {"EXEC-SEQ-002"}
    v = bad["EXEC-SEQ-002"].violations[0]
    assert a in v.observed and b in v.expected


# --- EXEC-RESEND-001: a resent signal is answered as the first, not applied again ------------

def _paused_then_continued(stream, a: str) -> tuple[list, dict]:
    """start a; $pause (paused); $continue (running again): the $pause's body for a resend."""
    pause = signal(stream, 3.0, a, "$pause", (3.2, a, "paused"))
    body = orjson.loads(pause[0].payload)
    return (start(stream, 2.0, a) + pause
            + signal(stream, 4.0, a, "$continue", (4.2, a, "running"))), body


def resend(stream, t: float, body: dict, answer: str = "ok") -> list:
    """``body`` sent again (its com-uuid), answered ``answer`` as the first was."""
    extra = {k: v for k, v in body.items() if k not in ("com-uuid", "command", "sender")}
    return [stream.command(t, body["command"], com_uuid=body["com-uuid"], **extra),
            stream.response(t + 0.1, body["com-uuid"], answer, **{
                "task-uuid": body["task-uuid"], "fail-reason": ""})]


def test_a_resent_pause_answered_again_passes_and_one_applied_again_fails(stream):
    a = new()
    before, pause = _paused_then_continued(stream, a)
    ok = judge(stream, before + resend(stream, 5.0, pause))
    assert not failing(ok)
    bad = judge(stream, before + resend(stream, 5.0, pause)
                + [stream.feedback(5.2, a, "paused")])
    assert failing(bad) == {"EXEC-RESEND-001"}
    v = bad["EXEC-RESEND-001"].violations[0]
    assert pause["com-uuid"] in v.expected and a in v.observed and "again" in v.observed
    # A new $pause (its own com-uuid) pauses it again: no resend.
    fresh = judge(stream, before + signal(stream, 5.0, a, "$pause", (5.2, a, "paused")))
    assert not failing(fresh)


def test_a_pause_resent_before_its_effect_showed_is_not_applied_twice(stream):
    """The resend came before the first's 'paused' (its answer was lost): the 'paused' that
    follows is the first's own effect."""
    a = new()
    cmd = stream.command(3.0, "signal-task", signal="$pause", **{"task-uuid": a})
    body = orjson.loads(cmd.payload)
    rules = judge(stream, start(stream, 2.0, a) + [cmd] + resend(stream, 3.3, body)
                  + [stream.feedback(3.5, a, "paused")])
    assert not failing(rules)


def test_a_task_paused_before_its_own_pause_is_answered_is_not_touched_by_another(stream):
    a, b = new(), new()
    both = start(stream, 2.0, a) + start(stream, 3.0, b)
    pause_a = stream.command(5.5, "signal-task", signal="$pause", **{"task-uuid": a})
    rules = judge(stream, both + signal(stream, 5.0, b, "$pause", (5.2, b, "paused")) + [
        pause_a, stream.feedback(5.6, a, "paused"),  # its feedback before its answer
        stream.response(5.7, orjson.loads(pause_a.payload)["com-uuid"], "ok",
                        **{"task-uuid": a, "fail-reason": ""})])
    # (EXEC-SIG-003's own judgement of feedback sent before the 'ok' is exec_feedback's.)
    assert rules["EXEC-SEQ-002"].verdict is Verdict.PASS


def test_a_task_pre_empted_by_a_new_start_is_no_other_tasks_abort(stream):
    a, b, c = new(), new(), new()
    traffic = (start(stream, 2.0, a) + start(stream, 3.0, b)
               + signal(stream, 5.0, b, "$abort", (5.2, b, "aborted"))
               + start(stream, 5.5, c) + [stream.feedback(5.8, a, "aborted")])
    rules = judge(stream, traffic)
    assert rules["EXEC-SEQ-002"].verdict is Verdict.PASS and not failing(rules)


def test_an_abort_that_also_ends_a_dependent_task_warns(stream):
    """The spec says nothing of tasks that depend on each other: another task 'aborted'
    right after an $abort answered 'ok' is EXEC-SEQ-002's decided condition 'also-aborted'
    (warns by default, fails strict); pausing another stays the rule's own words."""
    a, b = new(), new()
    traffic = (start(stream, 2.0, a) + start(stream, 3.0, b)
               + signal(stream, 5.0, b, "$abort", (5.2, b, "aborted"), (5.25, a, "aborted")))
    rule = judge(stream, traffic)["EXEC-SEQ-002"]
    assert rule.verdict is Verdict.WARN, rule
    assert [v.condition for v in rule.violations] == ["also-aborted"]
    m = Monitor(Profile(response_timeout=1.0, feedback_timeout=3.0, strict=True))
    stream.feed(m, stream.alive(20.0) + traffic)
    m.finish()
    assert m.report().units[str(stream.address)].rules["EXEC-SEQ-002"].verdict is Verdict.FAIL


# --- the model itself ---------------------------------------------------------------------------

def _cmd(**m) -> Command:
    c = Command.read({"com-uuid": new(), **m})
    assert c is not None
    return c


def test_the_model_says_what_each_command_may_get_in_each_state():
    model = Model(whole_life=True)
    start_new = _cmd(command="start-task", task={"name": "move-to"})
    e = model.expect(start_new)
    assert e.responses == {"running", "failed", "finished"} and e.outcome("running").states == {
        NEW_TASK: State.RUNNING}
    assert model.expect(_cmd(command="ping")).responses == {"pong"}
    ghost = _cmd(command="signal-task", signal="$abort", **{"task-uuid": new()})
    assert model.expect(ghost).responses == {"failed"} and model.expect(ghost).rule == \
        "EXEC-SIG-005"
    assert model.expect(_cmd(command="query-status", **{"task-uuid": new()})).responses == {
        "unknown"}
    assert model.expect(_cmd(command="take-off")).responses == {"failed"}
    # a running task, paused, then ended
    t = new()
    model.command(s := _cmd(command="start-task", task={"name": "move-to"}, **{"task-uuid": t}),
                  1.0)
    model.response({"response-to": s.com_uuid, "response": "running", "task-uuid": t}, 1.1)
    assert model.running() == [t] and model.executing() == {t}
    assert model.states() == {t: State.RUNNING}
    pause = model.expect(_cmd(command="signal-task", signal="$pause", **{"task-uuid": t}))
    assert pause.outcome("ok").implies == {t: {"paused"}} and pause.responses == {"ok", "failed"}
    model.feedback({"task-uuid": t, "status": "paused"}, 2.0)
    assert model.paused() == [t] and model.query_answers(t) == {"running", "paused"}
    again = model.expect(_cmd(command="signal-task", signal="$pause", **{"task-uuid": t}))
    assert again.outcome("ok").states == {}  # a paused task stays paused
    abort = model.expect(_cmd(command="signal-task", signal="$abort", **{"task-uuid": t}))
    assert abort.outcome("ok").states == {t: State.ABORTED} and abort.may_end == {t}
    other = model.expect(_cmd(command="start-task", task={"name": "move-to"}))
    assert other.may_end == {t}  # a second task may end the first (with a final status)
    model.feedback({"task-uuid": t, "status": "aborted"}, 3.0)
    assert model.ended() == [t] and model.query_answers(t) == {"failed", "aborted"}
    late = model.expect(_cmd(command="signal-task", signal="$continue", **{"task-uuid": t}))
    assert late.responses == {"failed", "ok"} and late.outcome("ok").states == {}
    # a resend is answered as before and executes nothing
    resend = model.expect(s)
    assert resend.resend and resend.responses == {"running"} and resend.untouched == {t}


def test_a_new_life_forgets_the_tasks():
    model = Model(whole_life=True)
    model.heartbeat({"agent-uuid": "one"}, 0.0)
    model.feedback({"task-uuid": "t1", "status": "running"}, 1.0)
    assert model.live() == ["t1"]
    model.heartbeat({"agent-uuid": "two"}, 2.0)
    assert model.tasks == {} and model.query_answers("t1") == {"unknown"}


REACHED = {State.RUNNING: (), State.PAUSED: ("paused",), State.FINISHED: ("finished",),
           State.FAILED: ("failed",), State.ABORTED: ("aborted",)}
"""Feedback after a start's 'running' that brings a task to each state the traffic shows."""


def _reached(stream, task: str, state: State) -> tuple[list, Model]:
    """The traffic that brings ``task`` to ``state``, and the model that saw it."""
    history = start(stream, 2.0, task) + [stream.feedback(2.5, task, s) for s in REACHED[state]]
    model = Model(whole_life=True)
    for m in history:
        model.observe(m)
    assert model.state(task) is state
    return history, model


def test_query_status_is_judged_by_the_models_answers(stream):
    """12.1: EXEC-QUERY-001 (the conversation check) fails an answer exactly where the model
    does not allow it, for a task in each state and every word query-status might say."""
    for state in REACHED:
        a = new()
        history, model = _reached(stream, a, state)
        for answer in ("running", "paused", "finished", "success", "failed", "aborted",
                       "unknown"):
            q = stream.command(4.0, "query-status", **{"task-uuid": a})
            com = orjson.loads(q.payload)["com-uuid"]
            rules = judge(stream, [*history, q, stream.response(4.1, com, answer)])
            fails = rules["EXEC-QUERY-001"].verdict is Verdict.FAIL
            assert fails == (answer not in model.query_answers(a)), (state, answer)


def test_feedback_is_owed_after_a_signal_where_the_model_implies_it(stream):
    """12.2.2: after an 'ok' to a built-in signal and no feedback, the conversation checks fail
    the signal's rule exactly where the model's outcome implies feedback (UNCHANGED: none)."""
    for state in (State.RUNNING, State.PAUSED):
        for sig in BUILTIN_SIGNALS:
            a = new()
            history, model = _reached(stream, a, state)
            sent = signal(stream, 3.0, a, sig)
            implied = model.expect(Command.read(sent[0].payload)).outcome("ok").implies
            owed = failing(judge(stream, history + sent)) & set(SIGNAL_RULE.values())
            assert owed == ({SIGNAL_RULE[sig]} if implied else set()), (state, sig)

"""Conversations judged from traffic alone (checks/conversation.py): every judgement shown
passing on a conformant exchange and failing on the matching fault, with the blame on the root
cause (a dead or deaf unit is one finding, not one per unanswered command)."""

from __future__ import annotations

import uuid

from conformance.checks import Monitor
from conformance.profile import Profile
from conformance.violation import Verdict

# Strict: these tests show each check finding what it finds; a decided rule (rules.toml basis)
# then fails as it did before the catalogue said what each rule stands on. That a decided rule
# only warns by default is the judge's, tested in tests/core/test_judge.py.
T0 = 1_700_000_000.0
"""When the ``stream`` fixture's time 0 is (tests/checks/conftest.py)."""
TIMEOUTS = Profile(response_timeout=1.0, feedback_timeout=3.0, strict=True)


def new() -> str:
    return str(uuid.uuid4())


def judge(stream, extra, seconds: float = 20.0, *, alive=None, profile=TIMEOUTS):
    """The unit's rule results after ``seconds`` of healthy traffic plus ``extra``."""
    m = Monitor(profile)
    stream.feed(m, (stream.alive(seconds) if alive is None else alive) + extra)
    m.finish()
    return m.report().units[str(stream.address)].rules


def verdicts(rules, *ids):
    return {r: rules[r].verdict.value for r in ids}


def start(stream, t, task_uuid=None, com=None, name="move-to", **extra):
    body = {"task": {"name": name, "params": {}}, **extra}
    if task_uuid is not None:
        body["task-uuid"] = task_uuid
    return stream.command(t, "start-task", com_uuid=com, **body)


def com_of(msg) -> str:
    import orjson

    return orjson.loads(msg.payload)["com-uuid"]


def test_answered_ping_passes_and_an_unanswered_one_fails_naming_it(stream):
    ping = stream.command(2.1, "ping")
    ok = judge(stream, [ping, stream.response(2.3, com_of(ping))])
    assert verdicts(ok, "EXEC-PING-001", "EXEC-PING-002", "EXEC-006", "EXEC-009",
                    "EXEC-010") == dict.fromkeys(
        ("EXEC-PING-001", "EXEC-PING-002", "EXEC-006", "EXEC-009", "EXEC-010"), "pass")
    lost = stream.command(2.1, "ping")
    later = stream.command(5.1, "ping")
    bad = judge(stream, [lost, later, stream.response(5.2, com_of(later))])
    r = bad["EXEC-PING-001"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 1
    assert com_of(lost) in r.violations[0].expected and r.violations[0].observed == "no answer"


def test_the_excerpt_of_a_long_command_says_it_is_cut(stream):
    # The Monitor keeps a command's head only (bounded memory): shown, it ends with '…',
    # never mid-token as if it were the whole command.
    lost = stream.command(2.1, "ping", sender="commander-" + "x" * 300)
    later = stream.command(5.1, "ping")
    bad = judge(stream, [lost, later, stream.response(5.2, com_of(later))])
    shown = bad["EXEC-PING-001"].violations[0].excerpt
    assert shown.endswith("…") and len(shown) < 200, shown
    short = judge(stream, [stream.command(2.1, "ping"), stream.command(5.1, "ping")])
    assert not any(v.excerpt.endswith("…") for v in short["EXEC-PING-001"].violations)


def test_a_pong_to_another_com_uuid_fails_ping_002_not_ping_001(stream):
    ping = stream.command(2.1, "ping")
    other = stream.command(6.1, "ping")
    rules = judge(stream, [ping, stream.response(2.2, com_of(ping).upper()), other,
                           stream.response(6.2, com_of(other))])
    assert verdicts(rules, "EXEC-PING-001", "EXEC-PING-002", "EXEC-006") == {
        "EXEC-PING-001": "pass", "EXEC-PING-002": "fail", "EXEC-006": "fail"}


def test_start_task_running_with_feedback_to_the_end_passes(stream):
    task = new()
    cmd = start(stream, 2.1, task)
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"),
        stream.feedback(6.5, task, "finished")])
    assert set(verdicts(rules, "EXEC-START-001", "EXEC-START-003",
                        "EXEC-FB-004").values()) == {"pass"}
    # 12.1's words are about a start-task sent without a task-uuid: none was
    assert rules["EXEC-START-002"].verdict is Verdict.SKIP
    assert "no start-task without a task-uuid" in rules["EXEC-START-002"].reason
    generated = new()
    bare = start(stream, 7.1)
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), bare, stream.response(7.2, com_of(bare), "running", **{
            "task-uuid": generated})])
    assert rules["EXEC-START-002"].verdict is Verdict.PASS


def test_start_task_answers_that_do_not_fit(stream):
    third = new()
    cmd1 = start(stream, 2.1, new())
    cmd2 = start(stream, 4.1)  # no task-uuid: the unit must generate one
    cmd3 = start(stream, 6.1, third)
    rules = judge(stream, [
        cmd1, stream.response(2.2, com_of(cmd1), "running"),  # task-uuid left out
        cmd2, stream.response(4.2, com_of(cmd2), "running"),  # none generated
        cmd3, stream.response(6.2, com_of(cmd3), "started", **{  # 14.4.4's word
            "task-uuid": third})])
    assert rules["EXEC-START-002"].verdict is Verdict.FAIL
    assert len(rules["EXEC-START-002"].violations) == 2
    assert rules["EXEC-START-001"].verdict is Verdict.FAIL
    assert "'started'" in rules["EXEC-START-001"].violations[0].observed


def test_a_start_task_without_task_uuid_answered_ok_and_no_task_uuid_fails_start_002(stream):
    """Seen in the field: a start-task sent without a task-uuid answered 'ok' and none. 12.1:
    'if not sent a generated task-uuid will be returned in the response message', whatever
    word accepted it ('ok' itself is EXEC-START-001's); a refusal names no task."""
    bare = start(stream, 4.1)
    rules = judge(stream, [bare, stream.response(4.2, com_of(bare), "ok")])
    assert rules["EXEC-START-001"].verdict is Verdict.FAIL
    r = rules["EXEC-START-002"]
    assert r.verdict is Verdict.FAIL and "a generated task-uuid" in r.violations[0].expected
    refused = judge(stream, [bare, stream.response(4.2, com_of(bare), "failed", **{
        "fail-reason": "no"})])
    assert refused["EXEC-START-002"].verdict is Verdict.SKIP


def test_a_task_listed_twice_or_after_its_refusal_fails_dei_004_once(stream):
    """5.3 'List of tasks currently executing.' Seen in the field: a task listed twice (no
    resend), and a task whose start-task (an unknown task: 'no-such-task') was refused
    ('failed') kept in tasks-executing for good. Each is named once, not per message; a
    task listed before its start-task was refused (the task-uuid of a running task) is no
    evidence."""
    task, phantom = new(), new()
    cmd = start(stream, 2.1, task)
    bogus = start(stream, 3.1, phantom, name="no-such-task")
    twice = [{"task-name": "move-to", "task-uuid": task}] * 2
    ghost = [{"task-name": "no-such-task", "task-uuid": phantom}]
    rules = judge(stream, [
        cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
        stream.feedback(2.3, task, "running"),
        stream.direct_execution_info(2.5, executing=twice),
        bogus, stream.response(3.2, com_of(bogus), "failed", **{
            "task-uuid": phantom, "fail-reason": "no such task"}),
        *[stream.direct_execution_info(t, executing=ghost) for t in (3.5, 6.5, 9.5, 12.5)]])
    r = rules["DEI-004"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 2, r
    assert "listed 2 times" in r.violations[0].observed
    assert "refused ('failed'): it never ran" in r.violations[1].observed
    listed = [{"task-name": "move-to", "task-uuid": task}]
    again = start(stream, 3.1, task)  # its uuid again: refused, the task runs on
    rules = judge(stream, [
        cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
        stream.feedback(2.3, task, "running"), stream.direct_execution_info(2.5, executing=listed),
        again, stream.response(3.2, com_of(again), "failed", **{
            "task-uuid": task, "fail-reason": "task-uuid in use"}),
        *[stream.direct_execution_info(t, executing=listed) for t in (6.5, 9.5)]])
    assert rules["DEI-004"].verdict is not Verdict.FAIL, rules["DEI-004"]


def test_a_dropped_start_task_fails_when_the_unit_answers_the_next_command(stream):
    dropped, ping = start(stream, 2.1, new()), stream.command(5.1, "ping")
    rules = judge(stream, [dropped, ping, stream.response(5.2, com_of(ping))])
    assert rules["EXEC-START-001"].verdict is Verdict.FAIL
    assert "start-task 'move-to'" in rules["EXEC-START-001"].violations[0].expected
    assert rules["EXEC-PING-001"].verdict is Verdict.PASS


def test_a_task_that_leaves_tasks_executing_without_final_feedback_fails(stream):
    quiet = stream.alive(20.0, info=False)  # its direct_execution_info is this test's
    task = new()
    cmd = start(stream, 2.1, task)
    listed = [stream.direct_execution_info(t + 0.5, executing=[
        {"task-uuid": task, "task-name": "move-to"}]) for t in (3, 4, 5)]
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"), *listed,
        *[stream.direct_execution_info(t + 0.5) for t in range(6, 20)]], alive=quiet)
    r = rules["EXEC-START-003"]
    assert r.verdict is Verdict.FAIL and "left tasks-executing" in r.violations[0].observed
    # Still listed (running) when the observation ends: not judged.
    still = [stream.direct_execution_info(t + 0.5, executing=[
        {"task-uuid": task, "task-name": "move-to"}]) for t in range(3, 20)]
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"), *still], alive=quiet)
    assert rules["EXEC-START-003"].verdict is Verdict.SKIP
    assert "still running" in rules["EXEC-START-003"].reason


def test_a_paused_task_left_out_of_tasks_executing_has_not_ended(stream):
    """5.3 lists the tasks 'currently executing': a unit may leave a paused task out while it
    is paused (it is not executing) and list it again once continued. Its leaving is then no
    end awaiting a final feedback (EXEC-START-003); continued and never listed again, it is."""
    quiet = stream.alive(30.0, info=False)  # its direct_execution_info is this test's
    task = new()
    entry = [{"task-uuid": task, "task-name": "move-to"}]
    cmd, pause = start(stream, 2.1, task), stream.command(5.1, "signal-task", **{
        "signal": "$pause", "task-uuid": task})
    resume = stream.command(15.1, "signal-task", **{"signal": "$continue", "task-uuid": task})
    began = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
             stream.feedback(2.3, task, "running"),
             *[stream.direct_execution_info(t + 0.5, executing=entry) for t in (3, 4)],
             pause, stream.response(5.2, com_of(pause), "ok", **{"task-uuid": task}),
             stream.feedback(5.3, task, "paused"),
             *[stream.direct_execution_info(t + 0.5) for t in range(5, 15)],
             resume, stream.response(15.2, com_of(resume), "ok", **{"task-uuid": task}),
             stream.feedback(15.3, task, "running")]
    relisted = [stream.direct_execution_info(t + 0.5, executing=entry) for t in range(15, 30)]
    rules = judge(stream, [*began, *relisted], 30.0, alive=quiet)
    assert rules["EXEC-START-003"].verdict is Verdict.SKIP, rules["EXEC-START-003"]
    assert "still running" in rules["EXEC-START-003"].reason
    never = [stream.direct_execution_info(t + 0.5) for t in range(15, 30)]
    rules = judge(stream, [*began, *never], 30.0, alive=quiet)
    r = rules["EXEC-START-003"]
    assert r.verdict is Verdict.FAIL and "left tasks-executing" in r.violations[0].observed
    # A unit that lists its paused task, then drops it while still paused, ended it unsaid
    # (the fault preempt-paused-silently).
    dropped = [*began[:8], *[stream.direct_execution_info(t + 0.5, executing=entry)
                             for t in (5, 6, 7)],
               *[stream.direct_execution_info(t + 0.5) for t in range(8, 30)]]
    rules = judge(stream, dropped, 30.0, alive=quiet)
    r = rules["EXEC-START-003"]
    assert r.verdict is Verdict.FAIL and "left tasks-executing" in r.violations[0].observed


def _resent(stream, task, *, second, feedback):
    cmd = start(stream, 2.1, task)
    again = start(stream, 3.1, task, com=com_of(cmd))
    return [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
            stream.feedback(2.3, task, "running"), again, *second(com_of(cmd)), *feedback,
            stream.feedback(8.5, task, "finished")]


def test_a_resend_answered_again_and_not_executed_again_passes(stream):
    task = new()
    rules = judge(stream, _resent(stream, task, second=lambda c: [stream.response(
        3.2, c, "running", **{"task-uuid": task})], feedback=[]))
    assert verdicts(rules, "EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-009",
                    "EXEC-FB-004") == dict.fromkeys(
        ("EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-009", "EXEC-FB-004"), "pass")


def test_a_resend_left_unanswered_warns(stream):
    task = new()
    rules = judge(stream, _resent(stream, task, second=lambda c: [], feedback=[]))
    assert rules["EXEC-RESEND-002"].verdict is Verdict.WARN
    assert rules["EXEC-START-001"].verdict is Verdict.PASS  # the first send was answered


def test_a_resend_of_a_command_never_answered_is_answered_once_in_all(stream):
    """2, 12.1: the commander resends 'until ... a response has arrived'. A ping the unit never
    heard (it subscribed late), resent and answered once, is a complete conversation; a ping
    answered, resent and not answered again still warns."""
    ping = stream.command(2.1, "ping")
    again = stream.command(3.5, "ping", com_uuid=com_of(ping))
    rules = judge(stream, [ping, again, stream.response(3.6, com_of(ping))])
    assert verdicts(rules, "EXEC-PING-001", "EXEC-RESEND-002", "EXEC-009", "EXEC-010") == \
        dict.fromkeys(("EXEC-PING-001", "EXEC-RESEND-002", "EXEC-009", "EXEC-010"), "pass")
    ping = stream.command(2.1, "ping")
    again = stream.command(3.5, "ping", com_uuid=com_of(ping))
    rules = judge(stream, [ping, stream.response(2.2, com_of(ping)), again])
    assert rules["EXEC-RESEND-002"].verdict is Verdict.WARN


def test_a_resend_executed_again_fails_resend_001(stream):
    task = new()
    rules = judge(stream, _resent(stream, task, second=lambda c: [stream.response(
        3.2, c, "running", **{"task-uuid": task})], feedback=[stream.feedback(3.3, task,
                                                                              "running")]))
    assert rules["EXEC-RESEND-001"].verdict is Verdict.FAIL
    assert "new 'running'" in rules["EXEC-RESEND-001"].violations[0].observed


def test_a_unit_that_repeats_running_is_not_accused_of_a_second_start_by_it(stream):
    """12.4's 'Update of the status' read as a periodic report (an independent
    unit): every running task's status each second. Once the unit has shown that, a 'running'
    after a resend is its period, not the task started again."""
    other, task = new(), new()
    first = start(stream, 1.0, other)
    periodic = [stream.feedback(t, other, "running") for t in (1.2, 2.2)]
    rules = judge(stream, [first, stream.response(1.1, com_of(first), "running", **{
        "task-uuid": other}), *periodic, stream.feedback(2.25, other, "finished"),
        *_resent(stream, task, second=lambda c: [stream.response(
            3.2, c, "running", **{"task-uuid": task})], feedback=[
            stream.feedback(t, task, "running") for t in (3.3, 4.3, 5.3)])])
    assert verdicts(rules, "EXEC-RESEND-001", "EXEC-FB-004") == {
        "EXEC-RESEND-001": "pass", "EXEC-FB-004": "pass"}


def test_a_resend_refused_with_failed_feedback_is_not_executed_twice(stream):
    """Seen in the field (the official Python L2 agent): the resend is answered 'failed' ('A
    task is already running') with a 'failed' feedback for the task, which runs on. Nothing
    ran twice (12.1): EXEC-RESEND-001 holds. Both 'failed' messages contradict the first
    answer while the task runs on: EXEC-RESEND-003 (decided) names them, once each, and not
    the task's later, true 'finished' (no EXEC-FB-004)."""
    task = new()
    refused = lambda c: [stream.response(3.2, c, "failed", **{  # noqa: E731
        "task-uuid": task, "fail-reason": "A task is already running"})]
    rules = judge(stream, _resent(stream, task, second=refused,
                                  feedback=[stream.feedback(3.3, task, "failed")]))
    assert verdicts(rules, "EXEC-RESEND-001", "EXEC-RESEND-002", "EXEC-FB-004") == {
        "EXEC-RESEND-001": "pass", "EXEC-RESEND-002": "pass", "EXEC-FB-004": "pass"}
    r = rules["EXEC-RESEND-003"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 2, r  # strict here
    answer, feedback = r.violations
    assert answer.topic.endswith("exec/response") and answer.time == T0 + 3.2
    assert feedback.topic.endswith("exec/feedback") and feedback.time == T0 + 3.3
    assert "then 'finished'" in answer.observed and "ran on" in answer.observed
    lenient = judge(stream, _resent(stream, task, second=refused, feedback=[
        stream.feedback(3.3, task, "failed")]), profile=Profile(
        response_timeout=1.0, feedback_timeout=3.0))
    assert lenient["EXEC-RESEND-003"].verdict is Verdict.WARN  # decided: an interop risk


def test_a_task_that_said_failed_and_runs_on_is_blamed_on_its_failed(stream):
    """EXEC-FB-004's note: a 'failed' feedback (here for a refused signal naming the task)
    after which the task says 'running' and 'finished' was the false one: the finding is the
    'failed', once, and the true end is no feedback after a final status."""
    task = new()
    cmd = start(stream, 2.1, task)
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"),
        stream.feedback(3.3, task, "failed"), stream.feedback(4.3, task, "running"),
        stream.feedback(6.3, task, "finished"), stream.feedback(7.3, task, "running")])
    r = rules["EXEC-FB-004"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 2, r  # strict here
    false, after_end = r.violations
    assert false.time == T0 + 3.3 and "then 'running'" in false.observed
    assert after_end.time == T0 + 7.3 and "final status 'finished'" in after_end.expected
    assert rules["EXEC-RESEND-003"].verdict is Verdict.SKIP  # nothing was resent
    ended = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"),
        stream.feedback(3.3, task, "failed")])
    assert ended["EXEC-FB-004"].verdict is Verdict.PASS  # a 'failed' that stays is true
    anew = start(stream, 5.1, task)  # its uuid started anew: a new task, not the old running on
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"),
        stream.feedback(3.3, task, "failed"), anew, stream.response(5.2, com_of(anew),
                                                                      "running", **{
            "task-uuid": task}), stream.feedback(5.3, task, "running"),
        stream.feedback(7.3, task, "finished")])
    assert rules["EXEC-FB-004"].verdict is Verdict.PASS, rules["EXEC-FB-004"]
    again = start(stream, 4.1, task, com=com_of(cmd))  # resent after a true 'failed': run again
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running"),
        stream.feedback(3.3, task, "failed"), again, stream.feedback(4.3, task, "running"),
        stream.feedback(6.3, task, "finished")])
    assert rules["EXEC-RESEND-001"].verdict is Verdict.FAIL
    assert rules["EXEC-FB-004"].verdict is Verdict.PASS, rules["EXEC-FB-004"]


def test_failed_feedback_after_a_resend_that_ran_the_ended_task_again(stream):
    """Seen in the field: a start-task resent after its task was aborted runs it again
    ('running': EXEC-RESEND-001, executed again); a signal-task $abort for another task then
    gets a 'failed' feedback naming the task that runs again. That 'failed' is the new run's
    status, not a second 'executed again'."""
    task, other = new(), new()
    cmd = start(stream, 2.1, task)
    abort = stream.command(3.1, "signal-task", signal="$abort", **{"task-uuid": task})
    again = start(stream, 4.1, task, com=com_of(cmd))
    wrong = stream.command(5.1, "signal-task", signal="$abort", **{"task-uuid": other})
    rules = judge(stream, [
        cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
        stream.feedback(2.3, task, "running"),
        abort, stream.response(3.2, com_of(abort), "ok", **{"task-uuid": task}),
        stream.feedback(3.3, task, "aborted"),
        again, stream.response(4.2, com_of(cmd), "running", **{"task-uuid": task}),
        stream.feedback(4.3, task, "running"),
        wrong, stream.response(5.2, com_of(wrong), "failed", **{
            "task-uuid": task, "fail-reason": "Invalid task-uuid"}),
        stream.feedback(5.3, task, "failed")])
    r = rules["EXEC-RESEND-001"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 1, r.violations
    assert "status 'running'" in r.violations[0].observed
    assert "executed again" in r.violations[0].observed
    assert rules["EXEC-FB-004"].verdict is Verdict.PASS


def test_query_status_agrees_with_the_history(stream):
    task = new()
    cmd = start(stream, 2.1, task)
    run = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
           stream.feedback(2.3, task, "running"), stream.feedback(4.3, task, "finished")]
    q = stream.command(5.1, "query-status", **{"task-uuid": task})
    ok = judge(stream, [*run, q, stream.response(5.2, com_of(q), "finished")])
    assert ok["EXEC-QUERY-001"].verdict is Verdict.PASS
    forgot = judge(stream, [*run, q, stream.response(5.2, com_of(q), "unknown")])
    assert forgot["EXEC-QUERY-001"].verdict is Verdict.FAIL
    assert "'finished'" in forgot["EXEC-QUERY-001"].violations[0].expected
    ping = stream.command(7.1, "ping")
    unanswered = judge(stream, [*run, q, ping, stream.response(7.2, com_of(ping))])
    assert unanswered["EXEC-QUERY-001"].verdict is Verdict.FAIL


def test_a_late_answer_says_how_late_and_is_not_also_a_missing_one(stream):
    ping = stream.command(2.1, "ping")
    rules = judge(stream, [ping, stream.response(4.5, com_of(ping))])
    assert rules["EXEC-010"].verdict is Verdict.WARN
    assert "2.40 s after ping" in rules["EXEC-010"].violations[0].observed
    r = rules["EXEC-PING-001"]  # not within the deadline, once: late, not 'no answer'
    assert r.verdict is Verdict.FAIL and len(r.violations) == 1  # strict: adopts 'late'
    assert "answered only after 2.40 s" in r.violations[0].observed
    assert r.violations[0].condition == "late"


def test_a_late_answer_is_a_decided_condition_and_no_answer_the_rule_s_words(stream):
    """The spec gives no deadline: a pong or a start answered after the response timeout
    warns (the 'late' condition, decided), also when its deadline had already passed;
    under strict it fails. A command never answered within the observation fails."""
    default = Profile(response_timeout=1.0, feedback_timeout=3.0)
    ping = stream.command(2.1, "ping")
    task = new()
    go = start(stream, 3.1, task)
    late = [ping, go, stream.response(8.5, com_of(ping)),  # 6.4 s: its deadline had passed
            stream.response(8.6, com_of(go), "running", **{"task-uuid": task}),
            stream.feedback(8.7, task, "finished")]
    rules = judge(stream, late, profile=default)
    assert verdicts(rules, "EXEC-PING-001", "EXEC-START-001", "EXEC-010") == {
        "EXEC-PING-001": "warn", "EXEC-START-001": "warn", "EXEC-010": "warn"}
    for rule in ("EXEC-PING-001", "EXEC-START-001"):
        assert [v.condition for v in rules[rule].violations] == ["late"], rules[rule]
        assert "interop risk" in rules[rule].reason
    strict = judge(stream, late)
    assert verdicts(strict, "EXEC-PING-001", "EXEC-START-001") == {
        "EXEC-PING-001": "fail", "EXEC-START-001": "fail"}
    never = judge(stream, [stream.command(2.1, "ping")], profile=default)
    assert never["EXEC-PING-001"].verdict is Verdict.FAIL
    assert never["EXEC-PING-001"].violations[0].condition == ""


def test_a_start_answered_finished_is_one_of_12_1_s_values(stream):
    """12.1: 'Possible values: running, failed, finished': a take-off answered 'finished'
    by a unit already airborne fits; an empty fail-reason is EXEC-007's alone (decided)."""
    default = Profile(response_timeout=1.0, feedback_timeout=3.0)
    done, refused = start(stream, 2.1, new(), name="take-off"), start(stream, 4.1, new())
    rules = judge(stream, [done, stream.response(2.2, com_of(done), "finished"),
                           refused, stream.response(4.2, com_of(refused), "failed",
                                                    **{"fail-reason": ""})], profile=default)
    assert rules["EXEC-START-001"].verdict is Verdict.PASS, rules["EXEC-START-001"]
    assert rules["EXEC-007"].verdict is Verdict.WARN


def test_an_answer_too_many_fails_exec_009(stream):
    ping = stream.command(2.1, "ping")
    rules = judge(stream, [ping, stream.response(2.2, com_of(ping)),
                           stream.response(2.3, com_of(ping))])
    assert rules["EXEC-009"].verdict is Verdict.FAIL


def test_a_unit_deaf_after_a_malformed_command_fails_robust_001_and_each_command(stream):
    """It stopped answering after the malformed command (EXEC-ROBUST-001): kinds of command it
    answered before went unanswered. That never hides each unanswered command's own finding."""
    ping0 = stream.command(2.1, "ping")
    query0 = stream.command(2.3, "query-status", **{"task-uuid": new()})
    bad = stream.msg("exec/command", b'{"com-uuid": "' + new().encode() + b'", signal: $abort}',
                     3.1)
    later = [stream.command(4.1, "ping"), stream.command(5.1, "query-status",
                                                         **{"task-uuid": new()})]
    rules = judge(stream, [ping0, stream.response(2.2, com_of(ping0)), query0,
                           stream.response(2.4, com_of(query0), "unknown"), bad, *later])
    r = rules["EXEC-ROBUST-001"]
    assert r.verdict is Verdict.FAIL and "a malformed command" in r.violations[0].detail
    assert rules["EXEC-PING-001"].verdict is Verdict.FAIL
    assert com_of(later[0]) in rules["EXEC-PING-001"].violations[0].expected
    assert rules["EXEC-QUERY-001"].verdict is Verdict.FAIL
    assert rules["EXEC-ROBUST-002"].verdict is Verdict.WARN  # the malformed one, unanswered


def test_kinds_never_answered_do_not_say_the_unit_stopped_answering(stream):
    """docs/FIELD-NOTES.md 'Real agents certified live' (kinds never answered): a unit that answers
    start-task and
    signal-task but never ping or query-status, from the first second, did not stop answering
    after a malformed command; each unanswered kind fails its own rule."""
    task = new()
    cmd = start(stream, 2.0, task)
    sig = stream.command(2.5, "signal-task", **{"task-uuid": task, "signal": "$abort"})
    bad = stream.msg("exec/command", b'{"com-uuid": "' + new().encode() + b'", signal: $abort}',
                     3.0)
    later = [stream.command(4.0 + i, kind, **({"task-uuid": new()} if kind != "ping" else {}))
             for i, kind in enumerate(("ping", "query-status") * 6)]
    rules = judge(stream, [cmd, stream.response(2.1, com_of(cmd), "running",
                                                **{"task-uuid": task}),
                           stream.feedback(2.2, task, "running"), sig,
                           stream.response(2.6, com_of(sig), "ok"),
                           stream.feedback(2.7, task, "aborted"), bad, *later])
    assert rules["EXEC-ROBUST-001"].verdict is not Verdict.FAIL
    assert rules["EXEC-PING-001"].verdict is Verdict.FAIL
    assert rules["EXEC-QUERY-001"].verdict is Verdict.FAIL


def test_answers_in_flight_are_credited_not_taken_for_deafness(stream):
    """docs/FIELD-NOTES.md 'Precision': a unit that ignored a malformed command and then, inside
    that
    command's timeout, answered another has not stopped answering; a query-status it ignores
    later is one kind of command unanswered, its own finding only."""
    bad = stream.msg("exec/command", b'{"com-uuid": "' + new().encode() + b'", signal: $abort}',
                     3.0)
    ping = stream.command(3.4, "ping")
    query = stream.command(6.0, "query-status", **{"task-uuid": new()})
    rules = judge(stream, [bad, ping, stream.response(3.5, com_of(ping)), query])
    assert rules["EXEC-ROBUST-001"].verdict is not Verdict.FAIL
    assert rules["EXEC-PING-001"].verdict is Verdict.PASS
    assert rules["EXEC-ROBUST-002"].verdict is Verdict.WARN
    assert rules["EXEC-QUERY-001"].verdict is Verdict.FAIL


def test_one_kind_unanswered_never_implies_the_others_are(stream):
    ping = stream.command(2.0, "ping")
    queries = [stream.command(3.0 + i, "query-status", **{"task-uuid": new()})
               for i in range(3)]
    rules = judge(stream, [ping, stream.response(2.1, com_of(ping)), *queries])
    assert rules["EXEC-ROBUST-001"].verdict is not Verdict.FAIL
    assert rules["EXEC-PING-001"].verdict is Verdict.PASS
    r = rules["EXEC-QUERY-001"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 3


def test_a_late_answer_is_credited(stream):
    """An answer after the deadline is late (EXEC-010), not a sign of deafness: commands sent
    before it say nothing about whether the unit still answers."""
    start1 = start(stream, 3.0, new())
    ping = stream.command(3.2, "ping")
    late_answer = stream.response(6.0, com_of(start1), "failed")
    query = stream.command(8.0, "query-status", **{"task-uuid": new()})
    rules = judge(stream, [start1, ping, late_answer, query])
    assert rules["EXEC-ROBUST-001"].verdict is not Verdict.FAIL
    assert rules["EXEC-010"].verdict is Verdict.WARN
    assert rules["EXEC-PING-001"].verdict is Verdict.FAIL
    assert rules["EXEC-QUERY-001"].verdict is Verdict.FAIL


def test_a_unit_that_dies_on_a_command_is_one_death_naming_it(stream):
    """Seen in the field: the MQTT thread dies on a start-task without task-uuid; its heartbeat
    stops for good while the process lives on."""
    cmd = start(stream, 9.5)  # no task-uuid
    ping = stream.command(12.0, "ping")
    rules = judge(stream, [cmd, ping, stream.heartbeat(30.0, agent_uuid=new())][:-1],
                  alive=stream.alive(10.0) + [stream.sensor("speed", 1.0, 30.0)])
    r = rules["HB-012"]
    assert r.verdict is Verdict.FAIL
    assert f"start-task 'move-to' without task-uuid (com-uuid {com_of(cmd)})" in r.violations[0].observed
    assert rules["EXEC-START-001"].verdict is not Verdict.FAIL
    assert rules["EXEC-PING-001"].verdict is not Verdict.FAIL
    assert rules["HB-010"].verdict is not Verdict.WARN


def test_dying_after_commands_excuses_only_the_last_one(stream):
    """docs/FIELD-NOTES.md 'Precision': commands a unit received before the one it died on were left
    unanswered by a live unit: each fails its rule; HB-012 names the last one they received while alive."""
    ping0 = stream.command(5.0, "ping")
    ping = stream.command(9.2, "ping")
    query = stream.command(9.4, "query-status", **{"task-uuid": new()})
    cmd = start(stream, 9.6)  # no task-uuid: it dies on it
    rules = judge(stream, [ping0, stream.response(5.1, com_of(ping0)), ping, query, cmd],
                  alive=stream.alive(10.0) + [stream.sensor("speed", 1.0, 30.0)])
    r = rules["HB-012"]
    assert r.verdict is Verdict.FAIL and com_of(cmd) in r.violations[0].observed
    assert rules["EXEC-PING-001"].verdict is Verdict.FAIL
    assert com_of(ping) in rules["EXEC-PING-001"].violations[0].expected
    assert rules["EXEC-QUERY-001"].verdict is Verdict.FAIL
    assert rules["EXEC-START-001"].verdict is not Verdict.FAIL
    assert rules["EXEC-ROBUST-001"].verdict is not Verdict.FAIL  # dead by their deadline


def test_levels_acted_on_but_not_declared_fail_once(stream):
    stream.levels = ["sensor"]
    ping = stream.command(2.1, "ping")
    rules = judge(stream, [ping, stream.response(2.2, com_of(ping))])
    r = rules["HB-013"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 1
    assert "'direct execution'" in r.violations[0].expected
    stream.levels = ["sensor", "direct execution"]
    assert judge(stream, [])["HB-013"].verdict is Verdict.PASS


def test_a_signal_answered_ok_implies_its_feedback(stream):
    task = new()
    cmd = start(stream, 2.1, task)
    run = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
           stream.feedback(2.3, task, "running")]
    sig = stream.command(3.1, "signal-task", **{"task-uuid": task, "signal": "$abort"})
    answered = stream.response(3.2, com_of(sig), "ok", **{"task-uuid": task})
    ok = judge(stream, [*run, sig, answered, stream.feedback(3.3, task, "aborted")])
    assert verdicts(ok, "EXEC-SIG-001", "EXEC-SIG-002") == {"EXEC-SIG-001": "pass",
                                                            "EXEC-SIG-002": "pass"}
    ignored = judge(stream, [*run, sig, answered])
    assert ignored["EXEC-SIG-002"].verdict is Verdict.FAIL
    enough = stream.command(3.1, "signal-task", **{"task-uuid": task, "signal": "$enough"})
    wrong = judge(stream, [*run, enough, stream.response(3.2, com_of(enough), "ok"),
                           stream.feedback(3.3, task, "aborted")])
    assert wrong["EXEC-SIG-004"].verdict is Verdict.FAIL


def test_a_signal_gets_the_feedback_deadline_of_its_task_where_the_profile_gives_one(stream):
    """A move-to that takes 6 s to stop ('aborted' 6 s after its $abort): late for the
    profile's feedback_timeout (3 s), in time for move-to's own (tasks: move-to:
    feedback-timeout: 8), which the finding then names."""
    import dataclasses

    task = new()
    cmd = start(stream, 2.1, task)
    sig = stream.command(3.1, "signal-task", **{"task-uuid": task, "signal": "$abort"})
    run = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
           stream.feedback(2.3, task, "running"), sig,
           stream.response(3.2, com_of(sig), "ok", **{"task-uuid": task})]
    slow = dataclasses.replace(TIMEOUTS, task_feedback_timeouts={"move-to": 8.0})
    assert judge(stream, [*run, stream.feedback(9.2, task, "aborted")],
                 profile=slow)["EXEC-SIG-002"].verdict is Verdict.PASS
    late = judge(stream, [*run, stream.feedback(9.2, task, "aborted")])["EXEC-SIG-002"]
    assert late.verdict is Verdict.FAIL and "within 3.0 s" in late.violations[0].expected
    never = judge(stream, run, profile=slow)["EXEC-SIG-002"]
    assert never.verdict is Verdict.FAIL and "within 8.0 s" in never.violations[0].expected


def test_a_signal_whose_feedback_comes_before_its_ok_is_credited(stream):
    """12 orders nothing between exec/feedback and exec/response: 'paused' published before
    the $pause's 'ok' (the reference unit's variant feedback-first) proves EXEC-SIG-003; it
    was failed when the task later ended ('finished' instead of 'paused')."""
    task = new()
    cmd = start(stream, 2.1, task)
    run = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
           stream.feedback(2.3, task, "running")]
    pause = stream.command(3.1, "signal-task", **{"task-uuid": task, "signal": "$pause"})
    resume = stream.command(4.1, "signal-task", **{"task-uuid": task, "signal": "$continue"})
    first = judge(stream, [*run, pause, stream.feedback(3.2, task, "paused"),
                           stream.response(3.3, com_of(pause), "ok", **{"task-uuid": task}),
                           resume, stream.feedback(4.2, task, "running"),
                           stream.response(4.3, com_of(resume), "ok", **{"task-uuid": task}),
                           stream.feedback(5.0, task, "finished")])
    assert verdicts(first, "EXEC-SIG-003") == {"EXEC-SIG-003": "pass"}
    # A 'paused' from before the signal is no evidence of it (the task was running again
    # when the $pause came; a task already paused owes nothing: docs/MODEL.md, EXEC-SEQ-001).
    stale = judge(stream, [*run, stream.feedback(3.0, task, "paused"),
                           stream.feedback(3.05, task, "running"), pause,
                           stream.response(3.3, com_of(pause), "ok", **{"task-uuid": task}),
                           stream.feedback(5.0, task, "finished")])
    assert stale["EXEC-SIG-003"].verdict is Verdict.FAIL  # 'paused' before the signal


def test_commands_to_a_unit_that_claims_no_execution_are_not_judged(stream):
    stream.levels = ["sensor"]
    ping = stream.command(2.1, "ping")
    rules = judge(stream, [ping, stream.command(5.1, "ping")])
    assert rules["EXEC-PING-001"].verdict is Verdict.SKIP


def test_a_gross_rate_mismatch_fails_early_and_is_not_a_string_of_silences(stream):
    stream.rate = 5.0  # declared 5 Hz, sent every 5 s (seen in the field)
    beats = [stream.heartbeat(t) for t in range(0, 20, 5)]
    rules = judge(stream, [], alive=beats)
    r = rules["HB-003"]
    assert r.verdict is Verdict.FAIL and "more than 3x" in r.violations[0].observed
    assert rules["HB-010"].verdict is not Verdict.WARN


def test_a_reboot_ends_what_the_old_life_left_open_unjudged(stream):
    task = new()
    cmd = start(stream, 2.1, task)
    other = new()
    after = [stream.heartbeat(t, agent_uuid=other) for t in range(8, 20)]
    before = [m for m in stream.alive(5.0)]
    rules = judge(stream, [cmd, stream.response(2.2, com_of(cmd), "running", **{
        "task-uuid": task}), stream.feedback(2.3, task, "running")], alive=before + after)
    assert rules["EXEC-START-003"].verdict is not Verdict.FAIL


def test_a_task_the_unit_lists_is_no_unknown_task_of_the_commander(stream):
    """9.12: vehicle-type specific tasks; TASK-002 is for names no one offers."""
    import orjson

    def offering(t: float):  # direct_execution_info that also lists a task beyond section 9
        info = orjson.loads(stream.direct_execution_info(t).payload)
        info["tasks-available"].append({"name": "spray-field", "signals": ["$abort"]})
        return stream.msg("direct_execution_info", info, t)

    traffic = [offering(t + 0.02) for t in range(7)] + stream.alive(6.0, info=False)
    listed = start(stream, 2.1, new(), name="spray-field")
    unknown = start(stream, 3.1, new(), name="dance")
    m = Monitor(TIMEOUTS)
    stream.feed(m, traffic + [listed, unknown])
    m.finish()
    commander = m.report().units["commander commander"].rules["TASK-002"]
    assert commander.verdict is Verdict.WARN and len(commander.violations) == 1
    assert "dance" in commander.violations[0].excerpt


def test_an_empty_task_uuid_is_a_finding_per_message_not_a_pseudo_task(stream):
    """docs/FIELD-NOTES.md 'Precision': feedback with task-uuid "" is one fault per message, not one
    task '' that received feedback after its final status."""
    rules = judge(stream, [stream.feedback(2.0, "", "running"),
                           stream.feedback(3.0, "", "finished"),
                           stream.feedback(4.0, "", "running"),
                           stream.feedback(5.0, "", "failed")])
    assert rules["EXEC-FB-004"].verdict is not Verdict.FAIL
    r = rules["EXEC-FB-001"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 4
    assert rules["ERR-014"].verdict is not Verdict.WARN  # judged as missing, not as malformed
    task = new()  # the fault with a real task-uuid is still found
    again = judge(stream, [stream.feedback(2.0, task, "finished"),
                           stream.feedback(3.0, task, "running")])
    assert again["EXEC-FB-004"].verdict is Verdict.FAIL


def test_an_empty_task_uuid_answering_a_command_that_named_no_task_is_no_fault(stream):
    """docs/FIELD-NOTES.md 'Precision' (spec words): the 'failed' answer to a malformed command that
    named no task has no task to name; ``task-uuid: ""`` there is not ERR-014's."""
    bad = stream.command(2.0, "start-task")  # no task: malformed
    ok = judge(stream, [bad, stream.response(2.1, com_of(bad), "failed", **{
        "task-uuid": "", "fail-reason": "no task given"})])
    assert ok["ERR-014"].verdict is not Verdict.WARN
    assert ok["EXEC-ROBUST-002"].verdict is not Verdict.FAIL
    task = new()  # a command that named a task: "" is no answer naming it
    named = stream.command(2.0, "query-status", **{"task-uuid": task})
    wrong = judge(stream, [named, stream.response(2.1, com_of(named), "unknown", **{
        "task-uuid": ""})])
    assert wrong["ERR-014"].verdict is Verdict.WARN


def test_a_task_named_uuid_instead_of_task_uuid_is_still_tracked(stream):
    """docs/FIELD-NOTES.md 'Precision' (other keys): some agents name the task 'uuid'. The wrong
    key is
    each message's finding; the task is tracked by what the unit sends."""
    import orjson

    task = new()
    cmd = start(stream, 2.1)  # no task-uuid: the unit generates one

    def fb(t, status):
        return stream.msg("exec/feedback", {"agent-uuid": stream.agent_uuid,
                                            "com-uuid": new(), "status": status,
                                            "uuid": task}, t)

    answer = orjson.loads(stream.response(2.2, com_of(cmd), "running").payload)
    answer["uuid"] = task
    rules = judge(stream, [cmd, stream.msg("exec/response", answer, 2.2), fb(2.3, "running"),
                           fb(4.0, "finished"), fb(5.0, "running")])
    assert rules["EXEC-START-002"].verdict is Verdict.FAIL
    assert len(rules["EXEC-FB-001"].violations) == 3
    r = rules["EXEC-FB-004"]
    assert r.verdict is Verdict.FAIL and task in r.violations[0].expected


def test_a_command_judged_unanswered_and_answered_later_fails_its_rule_once(stream):
    """Credited at any time: an answer after the command was judged unanswered (the unit
    answered a later one first) is late (EXEC-010), not a second failure of its rule."""
    ping = stream.command(2.0, "ping")
    other = stream.command(4.0, "ping")
    rules = judge(stream, [ping, other, stream.response(4.1, com_of(other)),
                           stream.response(6.0, com_of(ping))])
    assert len(rules["EXEC-PING-001"].violations) == 1
    assert rules["EXEC-010"].verdict is Verdict.WARN


def test_a_query_status_answer_failed_reports_a_status_it_refuses_nothing(stream):
    """12.1: query-status returns 'the status of the task (running, failed, success,
    unknown)'. A 'failed' with an empty fail-reason answering it is a task's status, not a
    refused command: no EXEC-007 (a refused start-task still owes its reason)."""
    task = new()
    cmd = start(stream, 2.1, task)
    run = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
           stream.feedback(2.3, task, "running"), stream.feedback(3.0, task, "failed")]
    q = stream.command(5.1, "query-status", **{"task-uuid": task})
    rules = judge(stream, [*run, q, stream.response(5.2, com_of(q), "failed", **{
        "task-uuid": task, "fail-reason": ""})])
    assert rules["EXEC-007"].verdict is Verdict.PASS
    assert rules["EXEC-QUERY-001"].verdict is Verdict.PASS
    refused = start(stream, 6.1, new())
    rules = judge(stream, [refused, stream.response(6.2, com_of(refused), "failed", **{
        "fail-reason": ""})])
    # still found (fail, or warn where the catalogue's basis makes EXEC-007 a decided rule)
    assert rules["EXEC-007"].verdict in (Verdict.WARN, Verdict.FAIL)
    assert len(rules["EXEC-007"].violations) == 1


def test_a_resend_refused_is_not_executed_again(stream):
    """Seen in the field: a resent start-task answered 'failed' ('A task is already
    running') and nothing else: refusing is not executing (EXEC-RESEND-001 holds); the task
    then finishes, so the 'failed' contradicted the first answer (EXEC-RESEND-003, decided).
    Answered again as the first time, it is clean."""
    task = new()
    rules = judge(stream, _resent(stream, task, second=lambda c: [stream.response(
        3.2, c, "failed", **{"task-uuid": task, "fail-reason": "A task is already running"})],
        feedback=[]))
    assert rules["EXEC-RESEND-001"].verdict is Verdict.PASS
    assert rules["EXEC-RESEND-002"].verdict is Verdict.PASS
    r = rules["EXEC-RESEND-003"]
    assert r.verdict is Verdict.FAIL and [v.time for v in r.violations] == [T0 + 3.2]  # strict
    again = judge(stream, _resent(stream, task, second=lambda c: [stream.response(
        3.2, c, "running", **{"task-uuid": task})], feedback=[]))
    assert again["EXEC-RESEND-003"].verdict is Verdict.PASS


def test_a_death_names_every_command_of_the_burst_the_last_first(stream):
    """docs/FIELD-NOTES.md 'Real agents certified live' (dying on bytes): a non-UTF-8 payload
    killed the unit, and an unknown
    command came in the same burst. Which one killed it the traffic cannot tell: HB-012 names
    every command it left unanswered in the period before its last heartbeat, the last
    first, and not one it answered another command after."""
    survived = stream.command(9.05, "query-status", **{"task-uuid": new()})
    ping = stream.command(9.1, "ping")
    bytes_ = stream.msg("exec/command", b'{"com-uuid": "' + new().encode() + b'", "x": "\xff"}',
                        9.3)
    unknown = stream.command(9.5, "waraps-conformance-no-such-command")
    rules = judge(stream, [survived, ping, stream.response(9.2, com_of(ping)), bytes_, unknown],
                  alive=stream.alive(10.0) + [stream.sensor("speed", 1.0, 30.0)])
    r = rules["HB-012"]
    assert r.verdict is Verdict.FAIL
    said = r.violations[0].observed
    assert "no-such-command" in said and "a malformed command" in said
    assert said.index("no-such-command") < said.index("a malformed command")  # the last first
    assert com_of(survived) not in said  # it answered the ping after it


def test_a_task_still_listed_long_after_it_finished_fails_dei_004_from_traffic(stream):
    """Tasks-executing entries that never end are on the wire; wherever the traffic
    shows the task's end ('finished', 'aborted'), a listing past two info periods fails DEI-004
    (5.3 'List of tasks currently executing.'). A listing composed before the end, or after a
    'failed' (which the public agents also send for a refused command), is no evidence."""
    def run(status: str, listed_at: float):
        task = new()
        cmd = start(stream, 2.1, task)
        entry = [{"task-name": "move-to", "task-uuid": task}]
        return judge(stream, [
            cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
            stream.feedback(2.3, task, "running"), stream.direct_execution_info(2.5, executing=entry),
            stream.feedback(4.0, task, status),
            stream.direct_execution_info(listed_at, executing=entry)])

    stale = run("finished", 9.0)
    r = stale["DEI-004"]
    assert r.verdict is Verdict.FAIL and len(r.violations) == 1, r
    assert "still listed 5.0 s after its 'finished' feedback" in r.violations[0].observed
    assert run("aborted", 9.0)["DEI-004"].verdict is Verdict.FAIL
    assert run("finished", 4.5)["DEI-004"].verdict is Verdict.SKIP  # composed before the end
    assert run("failed", 9.0)["DEI-004"].verdict is Verdict.SKIP


def test_info_without_tasks_executing_says_why_dei_004_was_not_judged(stream):
    """The public L2 agents send direct_execution_info without tasks-executing (DEI-001): lint
    of their traffic says DEI-004 could not be told for that reason, not that no command was
    seen; once a list comes, the reason goes."""
    import orjson

    task = new()
    cmd = start(stream, 2.1, task)
    traffic = [cmd, stream.response(2.2, com_of(cmd), "running", **{"task-uuid": task}),
               stream.feedback(4.0, task, "finished")]

    def info(t: float, listed: bool):
        m = orjson.loads(stream.direct_execution_info(t).payload)
        if not listed:
            del m["tasks-executing"]
        return stream.msg("direct_execution_info", m, t)

    alive = stream.alive(12.0, info=False) + [stream.sensor_info(t + 0.01) for t in range(13)]
    bare = judge(stream, traffic, alive=alive + [info(t + 0.02, False) for t in range(13)])
    assert bare["DEI-004"].verdict is Verdict.SKIP
    assert "no tasks-executing list (DEI-001)" in bare["DEI-004"].reason, bare["DEI-004"]
    listed = judge(stream, traffic, alive=alive + [info(t + 0.02, t >= 6) for t in range(13)])
    assert "DEI-001" not in listed["DEI-004"].reason, listed["DEI-004"]


def test_a_death_after_the_last_heartbeat_names_the_command_sent_after_it_too(stream):
    """docs/FIELD-NOTES.md 'Precision' (a slow heartbeat): a command left unanswered before the
    last heartbeat (the unit blocked on it, alive) and the start-task without task-uuid sent
    after it, which the unit died on: HB-012 names both, the later first, and what it lacked."""
    blocked = start(stream, 9.3, new())
    fatal = start(stream, 10.4)  # no task-uuid, after the last heartbeat (10.0)
    rules = judge(stream, [blocked, fatal],
                  alive=stream.alive(10.0) + [stream.sensor("speed", 1.0, 30.0)])
    said = rules["HB-012"].violations[0].observed
    assert "the commands it received as it fell silent, the last first" in said, said
    assert f"start-task 'move-to' without task-uuid (com-uuid {com_of(fatal)}), 0.40 s after" \
        in said, said
    assert said.index(com_of(fatal)) < said.index(com_of(blocked))

"""EXEC-SIG-003's expectation follows the model's decision (EXEC-SEQ-001, docs/MODEL.md):
$continue to a running task and $pause to a paused one change nothing, so no feedback is owed
(the exploration sends them; a conformant unit answers 'ok' and says nothing). A $pause to a
running task still owes 'paused'."""

from __future__ import annotations

from test_sequence import failing, judge, new, signal, start


def test_continue_to_a_running_task_owes_no_feedback(stream):
    a = new()
    extra = (start(stream, 2.0, a) + signal(stream, 3.0, a, "$continue")
             + signal(stream, 4.0, a, "$abort", (4.2, a, "aborted")))
    assert "EXEC-SIG-003" not in failing(judge(stream, extra))


def test_pause_to_a_paused_task_owes_no_second_paused(stream):
    a = new()
    extra = (start(stream, 2.0, a) + signal(stream, 3.0, a, "$pause", (3.2, a, "paused"))
             + signal(stream, 4.0, a, "$pause")
             + signal(stream, 5.0, a, "$abort", (5.2, a, "aborted")))
    assert "EXEC-SIG-003" not in failing(judge(stream, extra))


def test_pause_to_a_running_task_still_owes_paused(stream):
    a = new()
    extra = (start(stream, 2.0, a) + signal(stream, 3.0, a, "$pause")
             + signal(stream, 4.0, a, "$abort", (4.2, a, "aborted")))
    assert "EXEC-SIG-003" in failing(judge(stream, extra))


def test_continue_to_a_running_task_that_spoke_its_own_words_owes_no_feedback(stream):
    """A task's own status ('in-view-center', 12.4 allows task-specific statuses) leaves it
    running: $continue changes nothing (seen as a false EXEC-SIG-003 by exploration, seed 11:
    look-at-positions said 'in-view-center', then $continue 'ok', then 'aborted')."""
    a = new()
    extra = (start(stream, 2.0, a) + [stream.feedback(2.5, a, "in-view-center")]
             + signal(stream, 3.0, a, "$continue")
             + signal(stream, 4.0, a, "$abort", (4.2, a, "aborted")))
    assert "EXEC-SIG-003" not in failing(judge(stream, extra))


def test_continue_to_a_paused_task_that_spoke_its_own_words_still_owes_running(stream):
    a = new()
    extra = (start(stream, 2.0, a) + signal(stream, 3.0, a, "$pause", (3.2, a, "paused"))
             + [stream.feedback(3.5, a, "in-view-center")]
             + signal(stream, 4.0, a, "$continue")
             + signal(stream, 5.0, a, "$abort", (5.2, a, "aborted")))
    assert "EXEC-SIG-003" in failing(judge(stream, extra))

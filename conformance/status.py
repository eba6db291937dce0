"""Feedback statuses (12.4), and the words real units end tasks with instead.

One place for both readers of feedback: the passive conversation checks and the active
scenarios take a final-looking word outside the vocabulary (``done``, ``completed``, ...) as
the end it means, while EXEC-FB-002 still judges the word itself.
"""

from __future__ import annotations

# 12.4: "running - failed - aborted - paused - finished - starting - task specific strings".
STANDARD_STATUSES = frozenset({"running", "failed", "aborted", "paused", "finished", "starting"})
FINAL_STATUSES = frozenset({"finished", "failed", "aborted"})
# Words real units end tasks with instead of 12.4's
# (docs/FIELD-NOTES.md 'Faults seen in the traffic of real agents': vocabulary): the final
# status each one means. Compared in lower case, without surrounding blanks.
FINAL_LOOKING: dict[str, str] = {
    "done": "finished", "complete": "finished", "completed": "finished",
    "success": "finished", "succeeded": "finished", "successful": "finished",
    "finnished": "finished", "finish": "finished", "ended": "finished", "end": "finished",
    "enough": "finished", "stopped": "aborted", "cancelled": "aborted", "canceled": "aborted",
    "abort": "aborted", "killed": "aborted", "error": "failed", "failure": "failed",
    "fail": "failed", "rejected": "failed",
}


def meaning(status: object) -> str | None:
    """The 12.4 status a feedback status stands for: itself when standard, the standard word
    of a known other spelling (``Finished``, ``done``), else None."""
    if not isinstance(status, str):
        return None
    if status in STANDARD_STATUSES:
        return status
    word = status.strip().lower()
    if word in STANDARD_STATUSES:
        return word
    return FINAL_LOOKING.get(word)


def accepts_signal(response: object) -> bool:
    """Whether an answer to signal-task accepts the signal: any answer but 'failed'. 12.3.2
    (the signal-task response) is empty and 12.1 gives a response's values as 'running,
    failed, finished'; 'ok', which many units send, accepts it too."""
    return isinstance(response, str) and response != "failed"

"""Conformant units judged without false accusations from the observer's own timing
(docs/FIELD-NOTES.md 'Timing jitter', 'Precision'): every case shown both ways."""

from __future__ import annotations

from conformance.checks import Monitor
from conformance.profile import Profile
from conformance.violation import Verdict

PROFILE = Profile(response_timeout=1.0, feedback_timeout=3.0)
SPEED = 10.0  # m/s, reported on sensor/speed
DEG_PER_M = 1 / 111_195.0  # a metre north in degrees of latitude


def _moving(stream, arrivals, *, speed=SPEED):
    """Positions sent at 1 Hz (second i at i m/s * SPEED north), arriving at ``arrivals[i]``,
    with the unit's heartbeat, infos and speed."""
    out = [m for m in stream.alive(len(arrivals) + 2.0, sensors=False)]
    for i, arrival in enumerate(arrivals):
        out.append(stream.position(58.4 + i * speed * DEG_PER_M, 15.6, arrival))
        out.append(stream.sensor("speed", speed, i + 0.06))
    return out


def _sens005(stream, msgs):
    m = Monitor(PROFILE)
    stream.feed(m, msgs)
    m.finish()
    return m.report().units[str(stream.address)].rules["SENS-005"]


def test_positions_flushed_together_after_a_stall_are_not_a_jump(stream):
    """A stalled link delivers ten seconds of positions 38 us apart; the one after them is
    compared with the latest of the burst, not with the first (sent 9 s earlier)."""
    arrivals = [float(i) for i in range(6)] + [15.0 + k * 38e-6 for k in range(10)] + [
        16.0, 17.0, 18.0]
    assert _sens005(stream, _moving(stream, arrivals)).verdict is Verdict.PASS


def test_a_real_jump_still_warns(stream):
    arrivals = [float(i) for i in range(12)]
    msgs = _moving(stream, arrivals)
    msgs.append(stream.position(58.4 + 2_000 * DEG_PER_M, 15.6, 12.5))  # 2 km in 1.5 s
    assert _sens005(stream, msgs).verdict is Verdict.WARN


def test_success_answering_query_status_is_12_1s_own_word(stream):
    """12.1: query-status results are 'running, failed, success, unknown' (ERR-006's
    decision); out of place, in feedback, 'success' still warns and reads as finished."""
    import orjson

    from conformance.violation import Verdict as V

    task = "5b0c9d0e-1f2a-4b3c-8d4e-5f6a7b8c9d0e"
    start = stream.command(2.0, "start-task", **{"task-uuid": task,
                                                 "task": {"name": "move-to", "params": {}}})
    com = orjson.loads(start.payload)["com-uuid"]
    query = stream.command(5.0, "query-status", **{"task-uuid": task})
    run = [start, stream.response(2.1, com, "running", **{"task-uuid": task}),
           stream.feedback(2.2, task, "running"), stream.feedback(3.0, task, "finished"),
           query, stream.response(5.1, orjson.loads(query.payload)["com-uuid"], "success",
                                  **{"task-uuid": task})]
    m = Monitor(PROFILE)
    stream.feed(m, stream.alive(10.0) + run)
    m.finish()
    rules = m.report().units[str(stream.address)].rules
    assert rules["ERR-006"].verdict is V.PASS
    assert rules["EXEC-QUERY-001"].verdict is V.PASS
    said = [m for m in run if not m.payload.endswith(b'"finished"}')
            and b'"finished"' not in m.payload]
    m = Monitor(PROFILE)
    stream.feed(m, stream.alive(10.0) + said + [stream.feedback(3.0, task, "success")])
    m.finish()
    rules = m.report().units[str(stream.address)].rules
    assert rules["ERR-006"].verdict is V.WARN
    assert rules["EXEC-FB-002"].verdict is not V.FAIL
    assert rules["EXEC-QUERY-001"].verdict is V.PASS  # 'success' ended it as finished

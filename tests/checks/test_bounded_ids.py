"""What the checks keep of a message is bounded in bytes: identifiers they keep
as keys (com-uuid, task-uuid, response-to, ...) longer than ``bounds.ID_CHARS`` are kept as
stand-ins of bounded size, the same for the same identifier, so answers still match."""

from __future__ import annotations

from conformance.bounds import ID_CHARS, bound_ids
from conformance.checks import Monitor
from conformance.checks.conversation import CONVERSATIONS


def test_long_identifiers_get_distinct_bounded_stand_ins():
    a, b = "a" * 100_000, "a" * 99_999 + "b"
    m = {"com-uuid": a, "tasks-executing": [{"task-uuid": b}], "name": "n" * 5000,
         "short": "c" * 10}
    bound_ids(m)
    first, second = m["com-uuid"], m["tasks-executing"][0]["task-uuid"]
    assert len(first) < 200 and len(second) < 200 and first != second
    assert "(100000 chars" in first
    assert len(m["name"]) == 5000  # not an identifier the checks keep as a key: untouched
    again = {"response-to": a}
    bound_ids(again)
    assert again["response-to"] == first  # the same identifier, the same stand-in


def test_commands_with_1_mib_com_uuids_are_matched_and_not_kept_whole(stream):
    monitor = Monitor(kind="lint")
    messages = [stream.heartbeat(t) for t in range(12)]
    long_ids = [f"{i:04d}" + "x" * (900 << 10) for i in range(10)]
    for i, com in enumerate(long_ids):
        messages += [stream.command(1.1 + i, "ping", com_uuid=com),
                     stream.response(1.2 + i, com)]
    stream.feed(monitor, messages)
    monitor.finish(stream.heartbeat(12).time)
    unit = monitor.report().units[str(stream.address)]
    assert unit.rules["EXEC-PING-001"].verdict.value == "pass"  # every pong matched its ping
    # TODO(public): checks/conversation.py: the commands a unit keeps (their com-uuids)
    kept = monitor.state(stream.address).stash[CONVERSATIONS].commands
    assert len(kept) == 10 and all(len(k) <= ID_CHARS for k in kept)

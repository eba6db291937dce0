"""The check registry (conformance/checks/registry.py): built once, read-only, complete."""

from __future__ import annotations

from typing import Any

import pytest

from conformance.checks import CHECKS, covered_rules, registry
from conformance.topics import TopicKind


def test_the_registry_is_built_once_and_cannot_change() -> None:
    built = registry.build()
    assert built is registry.build()
    assert CHECKS is built.by_rule
    with pytest.raises(TypeError):
        built.on_message[TopicKind.HEARTBEAT] = ()  # type: ignore[index]
    with pytest.raises(RuntimeError, match="registered after the check registry was built"):
        @registry.check("HB-003", on=(TopicKind.HEARTBEAT,))
        def late(*args: Any) -> None:
            return None
    assert all(c.name != "late" for c in built.checks)


def test_every_check_runs_somewhere_and_is_found_by_its_rules() -> None:
    built = registry.build()
    running = {id(c) for table in (built.on_message, built.on_kind, built.reinterpret)
               for cs in table.values() for c in cs} | {id(c) for c in built.at_finish}
    assert [c.name for c in built.checks if id(c) not in running] == []
    for c in built.checks:
        assert all(c in built.by_rule[rule] for rule in c.rules), c.name
    assert covered_rules() == set(built.by_rule)
    # Registration order is the order checks run on a message: the model of direct
    # execution is fed before the conversations read it (checks/__init__.py).
    first = built.on_message[TopicKind.EXEC_COMMAND][0]
    assert first.fn.__module__ == "conformance.checks.exec_sequence"

"""Every check declares the unit's components it reads (``@check(..., reads=...)``):
certifications of the reference unit, direct execution and TST, in virtual time (and with
faults that reach the paths a conformant unit does not: a death after a command, responses
and feedback naming another agent-uuid or no task, silences), with every access to a ``Stash``
traced to the check whose call it happened in (itself or what it called); each check read
only what it declares."""

from __future__ import annotations

import sys
from collections.abc import Callable
from types import CodeType
from typing import Any

import pytest
from certify_helpers import certify_virtual

from conformance.checks import registry
from conformance.checks.stash import Stash, StashKey

UNIT = "waraps/unit/air/simulation/dji0"


def _declared() -> tuple[dict[CodeType, set[StashKey[Any]]], dict[CodeType, str]]:
    """The code of every registered check (and of what a wrapper wraps) -> what it declares;
    checks sharing one code (a finish check's wrapper) -> the union of theirs."""
    declared: dict[CodeType, set[StashKey[Any]]] = {}
    names: dict[CodeType, str] = {}
    for c in registry.build().checks:
        for fn in (c.fn, getattr(c.fn, "__wrapped__", c.fn)):
            declared.setdefault(fn.__code__, set()).update(c.reads)
            names.setdefault(fn.__code__, f"{fn.__module__}.{fn.__qualname__}")
    return declared, names


def _traced(method: Callable[..., Any], codes: dict[CodeType, set[StashKey[Any]]],
            read: dict[CodeType, set[StashKey[Any]]]) -> Callable[..., Any]:
    def traced(self: Stash, key: StashKey[Any], *args: Any, **kwargs: Any) -> Any:
        frame = sys._getframe(1)
        while frame is not None:
            if frame.f_code in codes:  # the innermost check this access happened in
                read.setdefault(frame.f_code, set()).add(key)
                break
            frame = frame.f_back
        return method(self, key, *args, **kwargs)

    return traced


@pytest.mark.parametrize("faults", [(), ("dies-on-missing-task-uuid",),
                                    ("response-stale-agent-uuid", "feedback-no-task-uuid"),
                                    ("dropouts", "sensor-unlisted")])
def test_every_check_reads_only_what_it_declares(pytester: pytest.Pytester,
                                                 monkeypatch: pytest.MonkeyPatch,
                                                 faults: tuple[str, ...]) -> None:
    declared, names = _declared()
    read: dict[CodeType, set[StashKey[Any]]] = {}
    for name in ("get", "setdefault", "with_item", "__getitem__", "__setitem__",
                 "__contains__", "__delitem__"):
        monkeypatch.setattr(Stash, name, _traced(getattr(Stash, name), declared, read))
    run = certify_virtual(pytester, UNIT, "--sim-tst", faults=faults)
    assert run.report is not None, run.text
    assert len(read) >= 20, "the run reached too few checks to tell"
    undeclared = {names[code]: sorted(k.name for k in keys - declared[code])
                  for code, keys in read.items() if keys - declared[code]}
    assert not undeclared, "reads not declared:\n" + "\n".join(
        f"  {check}: {', '.join(keys)}" for check, keys in sorted(undeclared.items()))

"""The check registry: every passive check, by the rule it implements and by when it runs.

A check is a small function registered for the rule ids it implements, one implementation per
rule. Message checks run on every message of the topic kinds they listen to, *before* the unit
state is updated with that message (so they compare the message with what came before); finish
checks run at the end of a run (or for a provisional report) and must not change state.

The check modules register with ``@check`` and ``@reinterprets`` as they are imported
(``conformance/checks/__init__.py`` imports them in the order they run). ``build()`` makes the
tables once, immutable, on its first call (the Monitor's import); a check registered after
that is a bug and raises, instead of running for some runs and not for others.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import cache
from types import MappingProxyType
from typing import Any, TypeVar

from conformance.checks.stash import StashKey
from conformance.rules import get
from conformance.topics import TopicKind

K = TypeVar("K")
Fn = TypeVar("Fn", bound=Callable[..., Any])


@dataclass(frozen=True)
class Check:
    """A registered check: the rules it implements and when it runs."""

    rules: tuple[str, ...]
    fn: Callable[..., Any]
    kinds: tuple[TopicKind | str, ...] = ()
    at_finish: bool = False
    reads: tuple[StashKey[Any], ...] = ()
    """The unit's components (``UnitState.stash``) it reads or keeps, itself or through what
    it calls: declared, and held to by ``tests/plugin/test_declared_reads.py``."""
    reinterprets: bool = False
    """It re-reads the validator's violations of a message (``@reinterprets``)."""

    @property
    def name(self) -> str:
        return self.fn.__name__


@dataclass(frozen=True)
class Registry:
    """Every registered check, in registration order, and the tables the Monitor runs them
    by (read-only mappings of tuples)."""

    checks: tuple[Check, ...]
    on_message: Mapping[TopicKind, tuple[Check, ...]]
    """Topic kind -> the message checks that listen to it."""
    on_kind: Mapping[str, tuple[Check, ...]]
    """Validation kind, for a narrower choice (``"sensor/position"``,
    ``"exec/command/start-task"``) -> the message checks that listen to it. A message runs
    the checks of its topic kind, then those of its validation kind. (Kept apart: a
    TopicKind compares equal to its string.)"""
    at_finish: tuple[Check, ...]
    reinterpret: Mapping[TopicKind, tuple[Check, ...]]
    """Topic kind -> checks that re-read the validator's violations of a message in the light
    of history (``fn(ctx, unit, msg, v, found) -> found``): e.g. a response answering a
    signal-task, whose form 12.3.2 leaves undefined, is judged by ERR-013 instead of
    EXEC-002."""
    by_rule: Mapping[str, tuple[Check, ...]]
    """Rule id -> the checks implementing it (a message part and a finish part at most)."""


_registered: list[Check] = []
_built = False


def _register(c: Check) -> None:
    if _built:
        raise RuntimeError(f"check {c.name} registered after the check registry was built: "
                           f"import its module in conformance/checks/__init__.py")
    for rule in c.rules:
        get(rule)  # an unknown id is a bug: fail at import, naming close ids
    _registered.append(c)


def check(*rules: str, on: Iterable[TopicKind | str] = (), finish: bool = False,
          reads: Iterable[StashKey[Any]] = ()) -> Callable[[Fn], Fn]:
    """Register a check for ``rules``: on messages of the kinds ``on``, or at ``finish``;
    ``reads`` declares the unit's components it reads or keeps (``checks/stash.py``).

    A message check returns (or yields) the violations it finds: a generator, a list, or None
    for none (the cheapest, for checks on frequent messages).
    """
    def register(fn: Fn) -> Fn:
        _register(Check(tuple(rules), fn, tuple(on), finish, tuple(reads)))
        return fn

    return register


def reinterprets(*rules: str, on: Iterable[TopicKind], reads: Iterable[StashKey[Any]] = ()
                 ) -> Callable[[Fn], Fn]:
    """Register a check that may replace validator violations by violations of ``rules``
    (``reads``: as for ``check``)."""
    def register(fn: Fn) -> Fn:
        _register(Check(tuple(rules), fn, tuple(on), reads=tuple(reads), reinterprets=True))
        return fn

    return register


def _table(pairs: Iterable[tuple[K, Check]]) -> Mapping[K, tuple[Check, ...]]:
    table: dict[K, list[Check]] = {}
    for key, c in pairs:
        table.setdefault(key, []).append(c)
    return MappingProxyType({key: tuple(cs) for key, cs in table.items()})


@cache
def build() -> Registry:
    """The checks registered so far, as the immutable tables; later registration raises."""
    global _built
    _built = True
    checks = tuple(_registered)
    message = [(kind, c) for c in checks if not c.reinterprets for kind in c.kinds]
    return Registry(
        checks=checks,
        on_message=_table((k, c) for k, c in message if isinstance(k, TopicKind)),
        on_kind=_table((k, c) for k, c in message if not isinstance(k, TopicKind)),
        at_finish=tuple(c for c in checks if c.at_finish),
        reinterpret=_table((TopicKind(k), c) for c in checks if c.reinterprets
                           for k in c.kinds),
        by_rule=_table((rule, c) for c in checks for rule in c.rules))


def covered_rules() -> set[str]:
    """Every rule id some passive check of this package implements."""
    return set(build().by_rule)

"""Where each message the Monitor is fed goes: the row of its unit (at most ``MAX_UNITS``),
the row of the commander that sent a command (by ``sender``), and per topic a ``Route`` worked
out once (the unit's row, the checks of the topic's kind, the shapes the validator examined).
A message on an operator's tst topic goes to the unit it concerns (14.1,
``checks/tst_routing.py``). ``Monitor.feed`` (``checks/monitor.py``) asks, on every message of
a fleet: what depends on the topic alone is worked out here once."""

from __future__ import annotations

import re
import sys
from collections.abc import Collection
from typing import Any

import orjson

from conformance import bounds
from conformance.checks.base import UnitState
from conformance.checks.registry import build
from conformance.checks.rows import UNATTRIBUTED, Row
from conformance.checks.tst_routing import TstRouting
from conformance.message import Message
from conformance.results import Party
from conformance.topics import TST_EXECUTION, TopicKind, UnitAddress, parse_topic
from conformance.validator import Examined, Validator

REGISTRY = build()  # built here: the package __init__ imported every check module first
MAX_UNITS = bounds.MAX_UNITS
"""Units tracked at once; further units' messages are unexamined: lint fails (``not_judged``)."""
MAX_TOPICS = bounds.MAX_TOPICS_CACHED
"""Topics whose unit is cached; further ones are looked up each time (still correct)."""
MAX_TOPIC_CHARS = 16 << 20
"""Characters of the cached topics' names, all told."""
MAX_COMMANDERS = bounds.MAX_COMMANDERS
"""Commanders with a row of their own; the commands of further ones share one row."""
MAX_SENDER = 64
_SENDER = re.compile(rb'"sender"\s*:\s*"([^"\\]{1,64})"')

IGNORED = Row(UnitState(UnitAddress(UNATTRIBUTED, "", "", "ignored")))
"""The entry of a unit the observation does not follow (``Monitor(units=...)``)."""
UNRESOLVED = Row(UnitState(UnitAddress(UNATTRIBUTED, "", "", "unresolved")))
"""The entry of a tst topic until a message shows whose it is (``Routes.tst_route``)."""
OVERFLOW = Row(UnitState(UnitAddress(UNATTRIBUTED, "", "", "overflow")))
"""The entry of a unit past ``MAX_UNITS``: its messages are counted, not examined."""

_COMMAND_KINDS = (TopicKind.EXEC_COMMAND, TopicKind.TST_COMMAND)


class Route:
    """Where the messages of one topic go, worked out once per topic: the unit's entry, the
    checks that re-read the validator's violations, and the message checks of the topic's kind
    (plus those of its validation kind where the topic fixes it: ``sensor/position``)."""

    __slots__ = ("entry", "reinterpret", "checks", "kind", "topic_kind", "content_fields",
                 "shapes", "decided_by", "last_decided", "address", "shared_tst", "command")

    def __init__(self, entry: Row, topic: str,
                 content_fields: tuple[str, ...] = ()) -> None:
        parsed = parse_topic(topic)
        self.entry = entry
        self.address = parsed.unit
        self.topic_kind = parsed.kind
        self.command = parsed.kind in _COMMAND_KINDS
        """A command topic: what is found in its messages is the commander's."""
        self.shared_tst = False
        """A tst topic: its messages may concern another unit (14.1, ``checks/tst_routing``)."""
        if parsed.kind is TopicKind.SENSOR:
            self.kind: str | None = sys.intern(f"sensor/{parsed.sensor}")  # as the validator's
        elif parsed.kind in (TopicKind.EXEC_COMMAND, TopicKind.TST_COMMAND):
            self.kind = None  # exec/command/<command>: the message says
        else:
            self.kind = parsed.kind.value
        self.reinterpret = tuple(c.fn for c in REGISTRY.reinterpret.get(parsed.kind, ()))
        self.checks = self.checks_for(self.kind)
        # What the validator examined, by message shape (``checks/shapes.py``).
        self.content_fields = content_fields
        """Fields whose types are part of a shape (``Validator.content_fields``)."""
        self.shapes: dict[tuple[Any, ...], Examined] = {}
        """Shape (and, where values decide, their values when scalars) -> examined set."""
        self.decided_by: tuple[str, ...] = ()
        """Top-level fields whose values decided a branch on some message of this topic (the
        union of ``Examined.decided_by``): their values are part of the key; the last
        message's (shape, values, examined) is kept too, for values that are lists or
        objects."""
        self.last_decided: tuple[Any, Any, Examined] | None = None

    def checks_for(self, kind: str | None) -> tuple[Any, ...]:
        """The message checks of a message of validation kind ``kind`` on this topic."""
        narrower = REGISTRY.on_kind.get(kind or "")
        return tuple(c.fn for c in REGISTRY.on_message.get(self.topic_kind, ())) + (
            tuple(c.fn for c in narrower) if narrower else ())


_TST_KINDS = (TopicKind.TST_COMMAND, TopicKind.TST_RESPONSE, TopicKind.TST_FEEDBACK)
MAX_TST_ROUTES = 4096
IGNORED_ROUTE = Route(IGNORED, "")
OVERFLOW_ROUTE = Route(OVERFLOW, "")


class Routes:
    """The rows of units and commanders, and the route of each topic seen (bounded)."""

    def __init__(self, validator: Validator, only: Collection[UnitAddress] | None) -> None:
        self.validator = validator
        self.only = frozenset(only) if only is not None else None
        self.entries: dict[UnitAddress | None, Row] = {}
        self.commanders: dict[str, Row] = {}
        """Commander name -> its row: what is wrong in a command is the commander's fault."""
        self.by_topic: dict[str, Route] = {}
        self._topic_chars = 0
        self._tst_routing = TstRouting()
        self._tst_routes: dict[tuple[str, UnitAddress], Route] = {}
        """(operator's tst topic, unit it concerns) -> the route of such messages."""

    def commander(self, unit_entry: Row, m: Any, payload: Any = None) -> Row:
        """The row of the commander that sent a command: its ``sender``, else 'the commander
        of UNIT' (v0.7 has no sender field in 12.2; implementations add one)."""
        sender = m.get("sender") if isinstance(m, dict) else None
        if m is None and isinstance(payload, bytes):  # not JSON: the sender may still be read
            match = _SENDER.search(payload, 0, 65536)
            sender = match.group(1).decode("utf-8", "replace") if match else None
        if isinstance(sender, str) and sender.strip():
            name = "".join(ch if ch.isprintable() else "?" for ch in sender.strip()[:MAX_SENDER])
        else:
            name = f"of {unit_entry.state.address.name or unit_entry.unit}"
        found = self.commanders.get(name)
        if found is None:
            if len(self.commanders) >= MAX_COMMANDERS:
                name = "(other commanders)"
                found = self.commanders.get(name)
            if found is None:
                label = f"commander {name}"
                found = self.commanders[name] = Row(
                    UnitState(UnitAddress(UNATTRIBUTED, "", "", label)), Party.COMMANDER, label)
        return found

    def tst_route(self, route: Route, message: Message) -> Route:
        """14.1: a message on an operator's tst topic (op0/tst/...) is the conversation of the
        unit it concerns (``checks/tst_routing``); else the topic's own unit's. TST messages
        are rare: decoding one twice costs nothing that matters."""
        try:
            m = orjson.loads(message.payload)
        except (orjson.JSONDecodeError, TypeError, ValueError):
            m = None
        if m is not None and len(message.payload) > bounds.ID_CHARS:
            bounds.bound_ids(m)  # as the checks see it: routes are kept by these ids
        own = route.address
        entry = self.entries.get(own) if own is not None else None
        # An operator that runs or delegates trees itself answers for them: its own.
        address = None if entry is not None and entry.state.claims(TST_EXECUTION) else \
            self._tst_routing.party(route.topic_kind, m, lambda name: self._follows(name, own))
        if address is None or address == own:
            if route.entry is UNRESOLVED:
                route.entry = self.entry_for_topic(message.topic)
            return route
        key = (message.topic, address)
        found = self._tst_routes.get(key)
        if found is None:
            entry = self.entries.get(address) or self.new_entry(address, force=True)
            assert entry is not None
            found = Route(entry, message.topic, route.content_fields)
            if len(self._tst_routes) < MAX_TST_ROUTES:
                self._tst_routes[key] = found
        return found

    def _follows(self, name: str, near: UnitAddress | None) -> UnitAddress | None:
        """The unit named ``name`` that this observation follows (under ``near``'s prefix
        first), or None."""
        if near is not None and near.name == name:
            return None
        units = self.only if self.only is not None else [a for a in self.entries if a]
        named = [a for a in units if a.name == name]
        named.sort(key=lambda a: near is None or a.prefix != near.prefix)
        return named[0] if named else None

    def for_topic(self, topic: str) -> Route:
        """The route of a topic not seen before (cached: topic strings hash fast, unit
        addresses do not)."""
        if parse_topic(topic).kind in _TST_KINDS:
            # The topic's own unit gets a row only when a message is its own (_tst_route).
            route = Route(UNRESOLVED, topic,
                           self.validator.content_fields(parse_topic(topic).kind))
            route.shared_tst = True
            self._cache(topic, route)
            return route
        entry = self.entry_for_topic(topic)
        if entry is IGNORED:
            route = IGNORED_ROUTE
        elif entry is OVERFLOW:
            route = OVERFLOW_ROUTE
        else:
            route = Route(entry, topic,
                           self.validator.content_fields(parse_topic(topic).kind))
        self._cache(topic, route)
        return route

    def _cache(self, topic: str, route: Route) -> None:
        """Keep a topic's route, up to MAX_TOPICS topics and MAX_TOPIC_CHARS of their names (an
        MQTT topic may be 64 KiB long: 65536 of them would be 4 GiB)."""
        if len(self.by_topic) < MAX_TOPICS and \
                self._topic_chars + len(topic) <= MAX_TOPIC_CHARS:
            self.by_topic[topic] = route
            self._topic_chars += len(topic)

    def entry_for_topic(self, topic: str) -> Row:
        """The entry of the unit a topic belongs to."""
        address = parse_topic(topic).unit
        if self.only is not None and address not in self.only:
            return IGNORED
        found = self.entries.get(address)
        return found if found is not None else (self.new_entry(address) or OVERFLOW)

    def new_entry(self, address: UnitAddress | None, force: bool = False) -> Row | None:
        if not force and len(self.entries) >= MAX_UNITS:
            return None
        state_address = address or UnitAddress(UNATTRIBUTED, "", "", "")
        entry = self.entries[address] = Row(UnitState(state_address))
        return entry

"""The Monitor: passive checks over a stream of messages, per unit, feeding one set of results.

The same object serves the linter (``kind="lint"``) and the certification suite
(``kind="certification"``), which also records its active scenarios into it (``record``).

``feed`` runs on every message of a fleet (bench/bench_lint.py), so what depends on the topic
alone is worked out once per topic (a ``_Route``: the unit's entry, the checks of its kind).
Which rules the validator examined on a message (``Validator.examined``) costs an evaluation
of its schema, 10-100 times validating it: ``feed`` asks once per message shape and keeps the
answer on the route (``_examined``), and counts messages per examined set, expanded into
per-rule counts only when a report is made.
"""

from __future__ import annotations

import dataclasses
import re
import sys
import time as _time
from collections.abc import Collection
from typing import Any

import orjson

from conformance.checks.base import (
    AT_FINISH,
    ON_KIND,
    ON_MESSAGE,
    REINTERPRET,
    CheckContext,
    UnitState,
)
from conformance.checks.tst_routing import TstRouting
from conformance.message import Message
from conformance.profile import Profile
from conformance.results import RunReport, UnitReport, judge_rule, skip_reason
from conformance.rules import CATALOGUE, Mode, Side
from conformance.topics import TopicKind, UnitAddress, parse_topic
from conformance.validator import Examined, Validation, Validator
from conformance.violation import Verdict, Violation

MAX_EVIDENCE = 20
"""Violations kept as evidence per rule and unit; the rest are only counted (bounded memory)."""
MAX_UNITS = 4096
"""Units tracked at once; messages of further units are counted as unexamined."""
MAX_TOPICS = 65536
"""Topics whose unit is cached; further ones are looked up each time (still correct)."""
MAX_SHAPES = 64
"""Message shapes whose examined rules are kept per topic (more are asked for each message)."""
MAX_SHARED_SHAPES = 4096
"""Message shapes whose examined rules are kept for every topic of their kind."""
MAX_SHAPE_KEYS = 64
"""Top-level keys of a message beyond which its shape is not worked out (asked each time)."""
UNATTRIBUTED = "(unattributed)"
"""The report entry for topics that name no unit (``waraps/foo``, ``waraps/unit/air``)."""
MAX_COMMANDERS = 256
"""Commanders with a row of their own; the commands of further ones share one row."""
MAX_SENDER = 64
_SENDER = re.compile(rb'"sender"\s*:\s*"([^"\\]{1,64})"')

class _RuleRecord:
    """What was recorded for one rule of one unit: a count and the first few violations."""

    __slots__ = ("count", "evidence", "explicit", "reason", "first", "last")

    def __init__(self) -> None:
        self.count = 0
        self.evidence: list[Violation] = []
        self.explicit: Verdict | None = None
        self.reason = ""
        self.first: float | None = None
        self.last: float | None = None
        """Times of the first and the latest violation (of all, not only those kept)."""

    def add(self, v: Violation) -> None:
        self.count += 1
        if len(self.evidence) < MAX_EVIDENCE:
            self.evidence.append(v)
        t = v.time
        if t is not None:
            if self.first is None or t < self.first:
                self.first = t
            if self.last is None or t > self.last:
                self.last = t


class Findings:
    """What the finish checks found for one unit: kept apart, so a provisional report (before
    ``finish``) and a repeated ``finish`` never count twice."""

    __slots__ = ("examined", "notes", "violations")

    def __init__(self) -> None:
        self.examined: dict[str, int] = {}
        self.notes: dict[str, str] = {}
        self.violations: list[Violation] = []

    def examine(self, rule: str, times: int = 1) -> None:
        self.examined[rule] = self.examined.get(rule, 0) + times

    def note(self, rule: str, why: str) -> None:
        self.notes[rule] = why


class _Entry:
    __slots__ = ("state", "records", "groups", "final", "unit", "party")

    def __init__(self, state: UnitState, party: str = "unit", label: str = "") -> None:
        self.state = state
        self.party = party
        """``unit``, or ``commander``: a row of what commanders sent (DESIGN: blame)."""
        self.unit = label or ("" if state.address.prefix == UNATTRIBUTED else str(state.address))
        self.records: dict[str, _RuleRecord] = {}
        self.groups: dict[Examined, int] = {}
        """Rules examined by the validator (shared sets) -> messages (expanded at report
        time)."""
        self.final: Findings | None = None


_IGNORED = _Entry(UnitState(UnitAddress(UNATTRIBUTED, "", "", "ignored")))
_UNRESOLVED = _Entry(UnitState(UnitAddress(UNATTRIBUTED, "", "", "unresolved")))
"""The entry of a tst topic until a message shows whose it is (``Monitor._tst_route``)."""
_OVERFLOW = _Entry(UnitState(UnitAddress(UNATTRIBUTED, "", "", "overflow")))


_COMMAND_KINDS = (TopicKind.EXEC_COMMAND, TopicKind.TST_COMMAND)


class _Route:
    """Where the messages of one topic go, worked out once per topic: the unit's entry, the
    checks that re-read the validator's violations, and the message checks of the topic's kind
    (plus those of its validation kind where the topic fixes it: ``sensor/position``)."""

    __slots__ = ("entry", "reinterpret", "checks", "kind", "topic_kind", "content_fields",
                 "shapes", "decided_by", "last_decided", "address", "shared_tst", "command")

    def __init__(self, entry: _Entry, topic: str,
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
        self.reinterpret = tuple(c.fn for c in REINTERPRET.get(parsed.kind, ()))
        self.checks = self.checks_for(self.kind)
        # What the validator examined, by message shape (Monitor._examined).
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
        narrower = ON_KIND.get(kind or "")
        return tuple(c.fn for c in ON_MESSAGE.get(self.topic_kind, ())) + (
            tuple(c.fn for c in narrower) if narrower else ())


_TST_KINDS = (TopicKind.TST_COMMAND, TopicKind.TST_RESPONSE, TopicKind.TST_FEEDBACK)
MAX_TST_ROUTES = 4096
_IGNORED_ROUTE = _Route(_IGNORED, "")
_OVERFLOW_ROUTE = _Route(_OVERFLOW, "")


class Monitor:
    """Passive checks over a stream of messages, per unit: the same code in the linter and in
    the certification suite (DESIGN: 'Passive checks').

    ``units`` limits the observation to those units (None: every unit seen). Times are the
    messages' arrival times (Unix seconds); the monitor never reads the clock while feeding, so a
    recording replays exactly as it was observed.
    """

    def __init__(self, profile: Profile | None = None, *, validator: Validator | None = None,
                 units: Collection[UnitAddress] | None = None, kind: str = "lint") -> None:
        if kind not in ("lint", "certification"):
            raise ValueError(f"kind must be 'lint' or 'certification', got {kind!r}")
        self.profile = profile or (validator.profile if validator is not None else Profile())
        self.validator = validator or Validator(self.profile)
        self.kind = kind
        self.ctx = CheckContext(self.profile, kind)
        self._only = frozenset(units) if units is not None else None
        self._entries: dict[UnitAddress | None, _Entry] = {}
        self._commanders: dict[str, _Entry] = {}
        """Commander name -> its row: what is wrong in a command is the commander's fault."""
        self._by_topic: dict[str, _Route] = {}
        self._tst_routing = TstRouting()
        self._tst_routes: dict[tuple[str, UnitAddress], _Route] = {}
        """(operator's tst topic, unit it concerns) -> the route of such messages."""
        self._shared_shapes: dict[tuple[Any, ...], Examined] = {}
        """Examined sets by topic kind and shape, for every topic (``_examined``)."""
        self._unexamined = 0
        self._last_time: float | None = None
        self._finished: float | None = None
        self.created = _time.time()

    # -- the stream -----------------------------------------------------------------------

    def feed(self, message: Message) -> list[Violation]:
        """Validate one message, run the checks that can decide now, record everything;
        the violations this message shows (stateful ones included)."""
        topic = message.topic
        route = self._by_topic.get(topic)
        if route is None:
            route = self._route_for_topic(topic)
        if route.shared_tst:
            route = self._tst_route(route, message)
        entry = route.entry
        if entry is _IGNORED:
            return []
        if entry is _OVERFLOW:
            self._unexamined += 1
            return []
        t = message.time
        v = self.validator.validate(topic, message.payload, t)
        ctx = self.ctx
        if ctx.started is None:
            ctx.started = t
        if self._last_time is None or t > self._last_time:
            self._last_time = t
        same_kind = v.kind == route.kind and v.topic.kind is route.topic_kind
        examined = self._examined(route, v)  # counted by set, expanded at report time
        state = entry.state
        if route.command:
            return self._feed_command(route, entry, message, v, examined)
        groups = entry.groups
        groups[examined] = groups.get(examined, 0) + 1
        violations = v.violations
        found = list(violations) if violations else None
        if route.reinterpret and v.topic.kind is route.topic_kind:
            for fn in route.reinterpret:
                found = fn(ctx, state, message, v, found or [])
        if same_kind:
            checks = route.checks
        else:  # a command (its kind is in its content), or a validator of its own mind
            checks = (route.checks_for(v.kind) if v.topic.kind is route.topic_kind
                      else self._checks_for(v))
        for fn in checks:
            out = fn(ctx, state, message, v)
            if out:
                if found is None:
                    found = list(out)
                else:
                    found.extend(out)
        state.observe(message, v)
        if found is None:
            return []
        if found:
            unit = entry.unit
            found = [f if f.unit or not unit else dataclasses.replace(f, unit=unit) for f in found]
            for f in found:
                self._add(entry, f)
        return found

    def _examined(self, route: _Route, v: Validation) -> Examined:
        """``Validator.examined(v)``, asked once per message shape of a topic: the kind, the
        top-level keys, which of their values are empty, the types of the content fields,
        and the values of the fields that decided a branch (``Examined.decided_by``, learnt
        from the answers: a field newly seen deciding clears what was kept). Nested optional
        parts are taken to be as in the first message of a shape. Without this cache the
        full lint runs at a fraction of its speed (bench/bench_lint.py: evaluation costs
        10-100x validation, bench/bench_validate.py)."""
        m = v.message
        m_type = m.__class__
        if v.topic.kind is not route.topic_kind:  # a validator of its own mind: ask
            return self.validator.examined(v)
        if m_type is dict:
            if len(m) > MAX_SHAPE_KEYS:
                return self.validator.examined(v)
            # Which values are empty: True when none is (the usual case, one C loop).
            fields = route.content_fields
            key: tuple[Any, ...] = (v.kind, tuple(m),
                                    all(m.values()) or tuple(map(bool, m.values())),
                                    tuple(map(type, map(m.get, fields))) if fields else ())
        elif m_type is float or m_type is int or m_type is str or m_type is bool:
            key = (v.kind, m_type)
        else:  # not decoded (few rules, no schema), or an array (its items decide)
            return self.validator.examined(v)
        decided_by = route.decided_by
        if decided_by:
            if m_type is not dict or "" in decided_by:
                return self.validator.examined(v)  # the message's own value decides
            values = tuple(map(m.get, decided_by))
            last = route.last_decided
            if last is not None and last[0] == key and last[1] == values:
                return last[2]  # a steady stream (lists and objects compared, not hashed)
            if _scalars(values):  # values that alternate (response, command): a dict
                found = route.shapes.get((key, values))
                if found is not None:
                    route.last_decided = (key, values, found)
                    return found
        else:
            found = route.shapes.get(key)
            if found is not None:
                return found
        # Units of one fleet send the same shapes: another topic's answer serves (its key
        # says all that decides, with the topic kind and whether it names a unit).
        shared_key = (route.topic_kind, v.topic.unit is None, decided_by, key,
                      tuple(map(m.get, decided_by)) if decided_by else None)
        try:
            examined = self._shared_shapes[shared_key]
        except (KeyError, TypeError):  # not seen, or a list or object among the values
            examined = self.validator.examined(v)
            if len(self._shared_shapes) < MAX_SHARED_SHAPES and _scalars(shared_key[4] or ()):
                self._shared_shapes[shared_key] = examined
        if not set(examined.decided_by) <= set(decided_by):
            decided_by = route.decided_by = tuple(sorted({*decided_by, *examined.decided_by}))
            route.shapes.clear()
        if decided_by:
            if m_type is dict:
                values = tuple(map(m.get, decided_by))
                route.last_decided = (key, values, examined)
                if _scalars(values) and len(route.shapes) < MAX_SHAPES:
                    route.shapes[(key, values)] = examined
        elif len(route.shapes) < MAX_SHAPES:
            route.shapes[key] = examined
        return examined

    def _feed_command(self, route: _Route, entry: _Entry, message: Message, v: Validation,
                      examined: Examined) -> list[Violation]:
        """A command: the unit's state learns of it (its conversations), but what is wrong in
        it is the commander's (by ``sender``), never the unit's. Commands are rare: the
        bookkeeping here may cost what the hot path may not."""
        commander = self._commander_entry(entry, v.message, message.payload)
        commander.groups[examined] = commander.groups.get(examined, 0) + 1
        commander.state.observe(message, v)
        state = entry.state
        before = dict(state.examined)
        found = list(v.violations)
        if route.reinterpret and v.topic.kind is route.topic_kind:
            for fn in route.reinterpret:
                found = fn(self.ctx, state, message, v, found)
        checks = (route.checks_for(v.kind) if v.topic.kind is route.topic_kind
                  else self._checks_for(v))
        for fn in checks:
            out = fn(self.ctx, state, message, v)
            if out:
                found.extend(out)
        state.observe(message, v)
        for rule, n in list(state.examined.items()):
            gained = n - before.get(rule, 0)
            if gained and CATALOGUE[rule].side is not Side.UNIT:
                commander.state.examine(rule, gained)
                state.examined[rule] = n - gained
        found = [dataclasses.replace(f, unit=commander.unit) for f in found]
        for f in found:
            self._add(commander, f)
        return found

    def _commander_entry(self, unit_entry: _Entry, m: Any, payload: Any = None) -> _Entry:
        """The row of the commander that sent a command: its ``sender``, else 'the commander
        of UNIT' (v0.7 has no sender field in 12.2; implementations add one)."""
        sender = m.get("sender") if isinstance(m, dict) else None
        if m is None and isinstance(payload, bytes):  # not JSON: the sender may still be read
            found = _SENDER.search(payload, 0, 65536)
            sender = found.group(1).decode("utf-8", "replace") if found else None
        if isinstance(sender, str) and sender.strip():
            name = "".join(ch if ch.isprintable() else "?" for ch in sender.strip()[:MAX_SENDER])
        else:
            name = f"of {unit_entry.state.address.name or unit_entry.unit}"
        found = self._commanders.get(name)
        if found is None:
            if len(self._commanders) >= MAX_COMMANDERS:
                name = "(other commanders)"
                found = self._commanders.get(name)
            if found is None:
                label = f"commander {name}"
                found = self._commanders[name] = _Entry(
                    UnitState(UnitAddress(UNATTRIBUTED, "", "", label)), "commander", label)
        return found

    @staticmethod
    def _checks_for(v: Validation) -> tuple[Any, ...]:
        return (tuple(c.fn for c in ON_MESSAGE.get(v.topic.kind, ()))
                + tuple(c.fn for c in ON_KIND.get(v.kind, ())))

    def _tst_route(self, route: _Route, message: Message) -> _Route:
        """14.1: a message on an operator's tst topic (op0/tst/...) is the conversation of the
        unit it concerns (``checks/tst_routing``); else the topic's own unit's. TST messages
        are rare: decoding one twice costs nothing that matters."""
        try:
            m = orjson.loads(message.payload)
        except (orjson.JSONDecodeError, TypeError, ValueError):
            m = None
        own = route.address
        entry = self._entries.get(own) if own is not None else None
        # An operator that runs or delegates trees itself answers for them: its own.
        address = None if entry is not None and entry.state.claims("tst execution") else \
            self._tst_routing.party(route.topic_kind, m, lambda name: self._follows(name, own))
        if address is None or address == own:
            if route.entry is _UNRESOLVED:
                route.entry = self._entry_for_topic(message.topic)
            return route
        key = (message.topic, address)
        found = self._tst_routes.get(key)
        if found is None:
            entry = self._entries.get(address) or self._new_entry(address, force=True)
            assert entry is not None
            found = _Route(entry, message.topic, route.content_fields)
            if len(self._tst_routes) < MAX_TST_ROUTES:
                self._tst_routes[key] = found
        return found

    def _follows(self, name: str, near: UnitAddress | None) -> UnitAddress | None:
        """The unit named ``name`` that this observation follows (under ``near``'s prefix
        first), or None."""
        if near is not None and near.name == name:
            return None
        units = self._only if self._only is not None else [a for a in self._entries if a]
        named = [a for a in units if a.name == name]
        named.sort(key=lambda a: near is None or a.prefix != near.prefix)
        return named[0] if named else None

    def _route_for_topic(self, topic: str) -> _Route:
        """The route of a topic not seen before (cached: topic strings hash fast, unit
        addresses do not)."""
        if parse_topic(topic).kind in _TST_KINDS:
            # The topic's own unit gets a row only when a message is its own (_tst_route).
            route = _Route(_UNRESOLVED, topic,
                           self.validator.content_fields(parse_topic(topic).kind))
            route.shared_tst = True
            if len(self._by_topic) < MAX_TOPICS:
                self._by_topic[topic] = route
            return route
        entry = self._entry_for_topic(topic)
        if entry is _IGNORED:
            route = _IGNORED_ROUTE
        elif entry is _OVERFLOW:
            route = _OVERFLOW_ROUTE
        else:
            route = _Route(entry, topic,
                           self.validator.content_fields(parse_topic(topic).kind))
        if len(self._by_topic) < MAX_TOPICS:
            self._by_topic[topic] = route
        return route

    def _entry_for_topic(self, topic: str) -> _Entry:
        """The entry of the unit a topic belongs to."""
        address = parse_topic(topic).unit
        if self._only is not None and address not in self._only:
            return _IGNORED
        found = self._entries.get(address)
        return found if found is not None else (self._new_entry(address) or _OVERFLOW)

    def connection_gap(self, start: float, end: float) -> None:
        """The observer was disconnected from ``start`` to ``end`` (Unix seconds): intervals
        over that time are not judged (rates, silence, uuid changes). Call it before feeding
        the messages received after the reconnect."""
        self.ctx.add_gap(float(start), float(end))

    def reboot_requested(self, t: float) -> None:
        """The observer's side rebooted the unit at ``t`` (Unix seconds): the restart is not
        judged as a silence or a rate gap, but a unit already silent for good before it had
        died (HB-012), however it came back."""
        self.ctx.add_gap(float(t), float(t))
        self.ctx.reboots.append(float(t))
        del self.ctx.reboots[:-1000]

    def unexamined(self, count: int) -> None:
        """``count`` messages the observer could not examine (dropped, queue overflow)."""
        self._unexamined += int(count)

    def finish(self, now: float | None = None) -> None:
        """End-of-run judgements at ``now`` (Unix seconds; default: the latest arrival time
        seen, so a replay ends where the recording ended). Calling it again re-judges."""
        now = self._now(now)
        for entry in self._entries.values():
            entry.final = self._run_finish(entry, now)
        self._finished = now

    # -- what the active suite reads and writes -------------------------------------------

    def units(self) -> list[UnitAddress]:
        """Every unit seen (or recorded into), in address order."""
        return sorted(a for a in self._entries if a is not None)

    def topics_cached(self) -> int:
        """Topics whose route ``feed`` keeps (at most ``MAX_TOPICS``: bounded memory)."""
        return len(self._by_topic)

    def state(self, unit: UnitAddress) -> UnitState:
        """What is known about ``unit`` (an empty state when nothing was seen yet)."""
        entry = self._entries.get(unit)
        if entry is None:
            entry = self._new_entry(unit, force=True)
        assert entry is not None
        return entry.state

    def record(self, unit: UnitAddress | None, rule: str, *, violation: Violation | None = None,
               verdict: Verdict | None = None, reason: str = "") -> None:
        """Record an active scenario's outcome for ``rule``: a violation; or an explicit
        skip / could-not-test / fail / warn with its reason; or ``verdict=PASS``: examined.
        ``unit`` None: a finding that names no unit (a ROS bag's, reported unattributed)."""
        if rule not in CATALOGUE:
            from conformance.rules import get

            get(rule)  # raises naming close ids
        entry = self._entries.get(unit) or self._new_entry(unit, force=True)
        assert entry is not None
        if violation is not None:
            if violation.rule != rule:
                violation = dataclasses.replace(violation, rule=rule)
            if violation.time is None and self._last_time is not None:
                # when it was found (no answer came by then): a death before it explains it
                violation = dataclasses.replace(violation, time=self._last_time)
            if not violation.unit and unit is not None:
                violation = dataclasses.replace(violation, unit=str(unit))
            self._add(entry, violation)
        if verdict is Verdict.PASS:
            entry.state.examine(rule)
        elif verdict is not None:
            rec = entry.records.get(rule)
            if rec is None:
                rec = entry.records[rule] = _RuleRecord()
            if rec.explicit is None or verdict.rank >= rec.explicit.rank:
                rec.explicit, rec.reason = verdict, reason
        elif violation is None:
            entry.state.examine(rule)
        if reason and verdict in (None, Verdict.PASS):
            entry.state.note(rule, reason)

    def report(self, **meta: Any) -> RunReport:
        """The results so far as a ``RunReport``. Before ``finish`` the end-of-run checks are
        judged provisionally at the latest arrival time, without being stored.

        Known keys: broker, started, finished, suite_version, schemas_hash; any other key goes
        to ``meta`` as text.
        """
        now = self._finished if self._finished is not None else self._now(None)
        units: dict[str, UnitReport] = {}
        for address, entry in sorted(self._entries.items(),
                                     key=lambda kv: (kv[0] is None, str(kv[0] or ""))):
            final = entry.final if entry.final is not None else self._run_finish(entry, now)
            report = self._unit_report(address, entry, final, now)
            units[report.unit] = report
        # In a certification the suite itself is the commander: no row of its own.
        if self.kind == "lint":
            for _, entry in sorted(self._commanders.items()):
                report = self._unit_report(None, entry, Findings(), now)
                units[report.unit] = report
        started = meta.pop("started", None)
        if started is None:
            started = min([self.ctx.started or self.created, self.created])
        return RunReport(
            kind=self.kind, started=float(started),
            finished=meta.pop("finished", self._finished),
            broker=str(meta.pop("broker", "")), profile=self.profile.name,
            suite_version=str(meta.pop("suite_version", "") or _suite_version()),
            schemas_hash=str(meta.pop("schemas_hash", "") or _schemas_hash()),
            units=units, gaps=list(self.ctx.gaps), unexamined=self._unexamined,
            meta={k: str(v) for k, v in meta.items()},
        )

    # -- internals ------------------------------------------------------------------------

    def _now(self, now: float | None) -> float:
        if now is not None:
            return float(now)
        return self._last_time if self._last_time is not None else _time.time()

    def _new_entry(self, address: UnitAddress | None, force: bool = False) -> _Entry | None:
        if not force and len(self._entries) >= MAX_UNITS:
            return None
        state_address = address or UnitAddress(UNATTRIBUTED, "", "", "")
        entry = self._entries[address] = _Entry(UnitState(state_address))
        return entry

    def _add(self, entry: _Entry, v: Violation) -> None:
        rec = entry.records.get(v.rule)
        if rec is None:
            rec = entry.records[v.rule] = _RuleRecord()
        rec.add(v)

    def _run_finish(self, entry: _Entry, now: float) -> Findings:
        findings = Findings()
        if entry.state.address.prefix == UNATTRIBUTED:
            return findings
        unit = str(entry.state.address)
        for c in AT_FINISH:
            out = c.fn(self.ctx, entry.state, now, findings)
            if out:
                findings.violations.extend(
                    v if v.unit else dataclasses.replace(v, unit=unit) for v in out)
        return findings

    def _unit_report(self, address: UnitAddress | None, entry: _Entry, final: Findings,
                     now: float) -> UnitReport:
        from conformance.checks.conversation import dropped
        from conformance.checks.identity import deaths
        from conformance.checks.rates import rate_stats

        state = entry.state
        examined = dict(state.examined)
        for group, n in entry.groups.items():
            for rule in group:
                examined[rule] = examined.get(rule, 0) + n
        for rule, n in final.examined.items():
            examined[rule] = examined.get(rule, 0) + n
        notes = {**state.notes, **final.notes}
        extra: dict[str, list[Violation]] = {}
        for v in final.violations:
            extra.setdefault(v.rule, []).append(v)
        unit = str(address) if address is not None else (entry.unit or UNATTRIBUTED)
        if entry.party == "commander":  # the commander's rules, and any other it broke
            rule_ids = [r for r, rule in CATALOGUE.items() if rule.side is Side.COMMANDER
                        or r in examined or r in entry.records]
        elif address is None:  # no unit: only the rules that were examined or broken
            rule_ids = sorted(set(examined) | set(entry.records))
        else:
            rule_ids = list(CATALOGUE)
        rules = {}
        counts = {}
        times: dict[str, tuple[float, float]] = {}
        died = deaths(self.ctx, state, now) if address is not None else []
        for rid in rule_ids:
            rule = CATALOGUE.get(rid)
            if rule is None:
                continue
            rec = entry.records.get(rid)
            evidence = (rec.evidence if rec else []) + extra.get(rid, [])
            count = (rec.count if rec else 0) + len(extra.get(rid, ()))
            explicit, reason = (rec.explicit, rec.reason) if rec else (None, "")
            if died and evidence and rule.mode is not Mode.PASSIVE:
                # A dead unit answers nothing: what a scenario found missing while it was
                # dead is its death's evidence (HB-012), not a fault of its own.
                kept = [v for v in evidence if not _during(v.time, died)]
                if len(kept) < len(evidence):
                    count -= len(evidence) - len(kept)
                    evidence = kept
                    if not count and explicit is None:
                        explicit, reason = Verdict.COULD_NOT_TEST, (
                            "the unit died (HB-012) before it could answer")
            if count:
                counts[rid] = count
                when = [t for t in (rec.first if rec else None, rec.last if rec else None,
                                    *(v.time for v in extra.get(rid, ()))) if t is not None]
                if when:
                    times[rid] = (min(when), max(when))
            rules[rid] = judge_rule(
                rule, severity=self.profile.severity_of(rid), violations=evidence[:MAX_EVIDENCE],
                count=count, examined=examined.get(rid, 0),
                explicit=explicit, explicit_reason=reason,
                default_reason=skip_reason(rule, kind=self.kind, unit=unit,
                                           levels=state.levels, note=notes.get(rid, ""),
                                           party=entry.party))
        facts: dict[str, Any] = {
            "declared_rates": dict(state.declared_rates),
            "sensors_listed": list(state.sensors_listed or ()),
            "sensors_seen": dict(state.sensors_seen),
            "tasks_available": {k: list(v) for k, v in state.tasks_available.items()},
            "tasks_executing": dict(state.tasks_executing),
            "position": list(state.position) if state.position else None,
            "message_counts": dict(state.counts),
            "conversations_dropped": dropped(state),
        }
        return UnitReport(
            party=entry.party,
            unit=unit, agent_type=address.agent_type if address else "",
            role=address.role if address else "", name=address.name if address else "",
            agent_uuids=list(state.agent_uuids), levels=list(state.levels or ()),
            message_count=state.message_count, first_seen=state.first_seen,
            last_seen=state.last_seen, rules=rules,
            rates=rate_stats(self.ctx, state) if address is not None else [],
            examined={k: examined[k] for k in sorted(examined)}, violation_counts=counts,
            violation_times=times,
            facts=facts)


_SCALAR_TYPES = (str, int, float, bool, type(None))


def _scalars(values: tuple[Any, ...]) -> bool:
    """Whether every value is a JSON scalar (hashable, and cheap to hash when short)."""
    return all(type(x) in _SCALAR_TYPES for x in values)


def _during(t: float | None, windows: list[tuple[float, float]]) -> bool:
    return t is not None and any(start <= t <= end for start, end in windows)


def _suite_version() -> str:
    try:
        from importlib.metadata import version

        return version("waraps-conformance")
    except Exception:  # not installed: the source tree's version
        from conformance import __version__

        return __version__


def _schemas_hash() -> str:
    try:
        from conformance.schema import schemas_hash  # type: ignore[attr-defined]
    except Exception:  # the schema module is not there (yet)
        return ""
    try:
        return str(schemas_hash())
    except Exception:
        return ""

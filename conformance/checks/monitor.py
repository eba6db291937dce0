"""The Monitor: passive checks over a stream of messages, per unit, feeding one set of results.

The same object serves the linter (``kind="lint"``) and the certification suite
(``kind="certification"``), which also records its active scenarios into it (``record``).

``feed`` runs on every message of a fleet (bench/bench_lint.py), so what depends on the topic
alone is worked out once per topic (a ``Route``: the unit's entry, the checks of its kind).
Which rules the validator examined on a message (``Validator.examined``) costs an evaluation
of its schema, 10-100 times validating it: ``feed`` asks once per message shape and keeps the
answer on the route (``checks/shapes.py``), and counts messages per examined set, expanded into
per-rule counts only when a report is made.
"""

from __future__ import annotations

import dataclasses
import math
import time as _time
from collections.abc import Collection
from typing import Any

from conformance import bounds
from conformance.checks.base import CheckContext, UnitState
from conformance.checks.rates import live_findings as live_rate_findings
from conformance.checks.routes import IGNORED, OVERFLOW, REGISTRY, Route, Routes
from conformance.checks.rows import (
    UNATTRIBUTED,
    Findings,
    Row,
    RuleRecord,
    row_report,
    schemas_hash,
    suite_version,
)
from conformance.checks.shapes import Shapes
from conformance.checks.suite_commands import suite_row
from conformance.facts import RunKind
from conformance.message import Message
from conformance.profile import Profile
from conformance.report_meta import RunMeta
from conformance.results import RunReport, UnitReport
from conformance.rules import CATALOGUE, Side, get
from conformance.topics import TopicKind, UnitAddress, parse_topic
from conformance.validator import Examined, Validation, Validator
from conformance.violation import Observed, Violation

MAX_NAMED_OVER_CAP = 8
"""Units past MAX_UNITS named when the run says what it did not judge."""


def _is_command(m: Any) -> bool:
    """A message that reads as a command (12.2: com-uuid and command) on any topic."""
    return (type(m) is dict and isinstance(m.get("command"), str)
            and isinstance(m.get("com-uuid"), str))


class Monitor:
    """Passive checks over a stream of messages, per unit: the same code in the linter and in
    the certification suite, so the two never disagree on the same traffic.

    ``units`` limits the observation to those units (None: every unit seen). Times are the
    messages' arrival times (Unix seconds); the monitor never reads the clock while feeding, so a
    recording replays exactly as it was observed.
    """

    def __init__(self, profile: Profile | None = None, *, validator: Validator | None = None,
                 units: Collection[UnitAddress] | None = None,
                 kind: RunKind | str = RunKind.LINT) -> None:
        if kind not in tuple(RunKind):
            raise ValueError(f"kind must be 'lint' or 'certification', got {kind!r}")
        self.profile = profile or (validator.profile if validator is not None else Profile())
        self.validator = validator or Validator(self.profile)
        self.kind = RunKind(kind)
        self.ctx = CheckContext(self.profile, self.kind)
        self.routes = Routes(self.validator, units)
        """Where each message goes: its unit's row, its commander's, its topic's route."""
        self._by_topic = self.routes.by_topic  # read on every message
        self._examined = Shapes(self.validator).examined
        """What the validator examined on a message, asked once per shape (``shapes.py``)."""
        self._unexamined = 0
        self._over = 0
        self._over_units: list[str] = []
        self._latest = float("-inf")  # the latest arrival time fed (-inf before the first)
        self.version = 0
        """Counts every change of what the Monitor knows (a message, a record, a gap, the
        end): a report made at one version stays true until the next (a cache's key)."""
        self._validate = self.validator.validate
        self._finished: float | None = None
        self.created = _time.time()

    # -- the stream -----------------------------------------------------------------------

    def feed(self, message: Message) -> list[Violation]:
        """Validate one message, run the checks that can decide now, record everything;
        the violations this message shows (stateful ones included)."""
        self.version += 1
        topic = message.topic
        route = self._by_topic.get(topic)
        if route is None or route.shared_tst or route.entry is IGNORED or route.entry is OVERFLOW:
            route = self._resolve(route, message)
            if route is None:
                return []
        entry = route.entry
        t = message.time
        v = self._validate(topic, message.payload, t)
        if v.message is not None and len(message.payload) > bounds.ID_CHARS:
            bounds.bound_ids(v.message)  # what the checks keep of a message is bounded
        self.ctx.stalls.feed(t, topic, route.topic_kind, v.message)  # before any check
        if t > self._latest:
            self._latest = t
            if self.ctx.started is None:
                self.ctx.started = t
        examined = self._examined(route, v)  # counted by set, expanded at report time
        if route.command:
            return self._feed_command(route, entry, message, v, examined)
        if route.topic_kind is TopicKind.UNKNOWN and _is_command(v.message):
            # A command on a topic of its sender's making (an operator's '.../None/command',
            # docs/FIELD-NOTES.md 'Precision'): what is wrong in it is the sender's, on its row.
            entry = self.routes.commander(entry, v.message, message.payload)
        groups = entry.groups
        groups[examined] = groups.get(examined, 0) + 1
        ctx, state = self.ctx, entry.state
        violations = v.violations
        found = list(violations) if violations else None
        if v.topic.kind is route.topic_kind:
            if route.reinterpret:
                for fn in route.reinterpret:
                    found = fn(ctx, state, message, v, found or [])
            # The topic fixes the kind but for a command (its kind is in its content).
            checks = route.checks if v.kind is route.kind else route.checks_for(v.kind)
        else:  # a validator of its own mind
            checks = self._checks_for(v)
        for fn in checks:
            out = fn(ctx, state, message, v)
            if out:
                if found is None:
                    found = list(out)
                else:
                    found.extend(out)
        state.observe(message, v)
        return entry.add_all(found) if found else []

    def _resolve(self, route: Route | None, message: Message) -> Route | None:
        """The route of a message whose topic's route is not cached yet, or concerns another
        unit (an operator's tst topic, 14.1); None when the message is not judged (a unit not
        followed; a unit past ``MAX_UNITS``: counted unexamined)."""
        if route is None:
            route = self.routes.for_topic(message.topic)
        if route.shared_tst:
            route = self.routes.tst_route(route, message)
        if route.entry is IGNORED:
            return None
        if route.entry is OVERFLOW:
            self._unexamined += 1
            self._over_cap(message.topic)
            return None
        return route

    def _feed_command(self, route: Route, entry: Row, message: Message, v: Validation,
                      examined: Examined) -> list[Violation]:
        """A command: the unit's state learns of it (its conversations), but what is wrong in
        it is the commander's (by ``sender``; the suite's own: no one's, ``suite_commands``),
        never the unit's. Commands are rare: the bookkeeping may cost what the hot path may not."""
        suite = suite_row(entry.state, v.message, message.payload)
        commander = suite or self.routes.commander(entry, v.message, message.payload)
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
        # The unit's own topic (its address: 3.1's TYPE, ROLE, UNIT) is the unit's finding,
        # recorded once on its row, never on each commander that addresses it (docs/ARCHITECTURE.md
        # 'Whose fault it is').
        own = [f for f in found if CATALOGUE[f.rule].level.value == "topic"]
        if own:
            found = [f for f in found if CATALOGUE[f.rule].level.value != "topic"]
            for f in own:
                if f.rule not in entry.records and entry.state.address.prefix != UNATTRIBUTED:
                    entry.add(dataclasses.replace(f, unit=entry.unit))
        found = [dataclasses.replace(f, unit=commander.unit) for f in found]
        for f in found:
            commander.add(f)
        # The suite's commands and deliberate probes are no one's fault (docs/ARCHITECTURE.md
        # 'Whose fault it is'): its row is never reported, so what is found in them is not
        # shown either, as it happens (lint beside a certification printed them failing).
        return [] if suite is not None else found

    @staticmethod
    def _checks_for(v: Validation) -> tuple[Any, ...]:
        return (tuple(c.fn for c in REGISTRY.on_message.get(v.topic.kind, ()))
                + tuple(c.fn for c in REGISTRY.on_kind.get(v.kind, ())))

    def connection_gap(self, start: float, end: float | None) -> None:
        """The observer was disconnected from ``start`` to ``end`` (Unix seconds): intervals
        over that time are not judged (rates, silence, uuid changes). Call it before feeding
        the messages received after the reconnect. ``end`` None: the gap stays open until
        ``heard_again`` (what the unit sent before it is back on the broker is unknown too)."""
        self.version += 1
        self.ctx.add_gap(float(start), math.inf if end is None else float(end))

    def host_held(self, start: float, end: float) -> None:
        """The host held the unit from ``start`` to ``end`` (the bundled reference unit runs in
        the observer's own process: a loaded machine holds both): like a connection gap, that
        time is not judged."""
        self.version += 1
        self.ctx.add_gap(float(start), float(end))

    def heard_again(self, t: float) -> None:
        """The unit is back on the broker at ``t``: an open ``connection_gap`` ends there."""
        self.version += 1
        self.ctx.close_gap(float(t))

    def reboot_requested(self, t: float) -> None:
        """The observer's side rebooted the unit at ``t`` (Unix seconds): the restart is not
        judged as a silence or a rate gap, but a unit already silent for good before it had
        died (HB-012), however it came back."""
        self.version += 1
        self.ctx.add_gap(float(t), float(t))
        self.ctx.reboots.append(float(t))
        del self.ctx.reboots[:-1000]

    def unexamined(self, count: int) -> None:
        """``count`` messages the observer could not examine (dropped, queue overflow)."""
        self.version += 1
        self._unexamined += int(count)

    def _over_cap(self, topic: str) -> None:
        self._over += 1
        if len(self._over_units) < MAX_NAMED_OVER_CAP:
            unit = parse_topic(topic).unit
            if unit is not None and str(unit) not in self._over_units:
                self._over_units.append(str(unit))

    def not_judged(self) -> tuple[int, list[str]]:
        """Messages of units past ``MAX_UNITS`` that were not judged, and the first units they
        name (at most ``MAX_NAMED_OVER_CAP``): lint fails on them, never passes."""
        return self._over, list(self._over_units)

    def finish(self, now: float | None = None) -> None:
        """End-of-run judgements at ``now`` (Unix seconds; default: the latest arrival time
        seen, so a replay ends where the recording ended). Calling it again re-judges."""
        self.version += 1
        now = self._now(now)
        for entry in self.routes.entries.values():
            entry.final = self._run_finish(entry, now)
        self._finished = now

    # -- what the active suite reads and writes -------------------------------------------

    def units(self) -> list[UnitAddress]:
        """Every unit seen (or recorded into), in address order."""
        return sorted(a for a in self.routes.entries if a is not None)

    def commanders(self) -> list[str]:
        """The rows of commanders seen so far (lint), by label (``commander op0``), sorted."""
        return sorted(entry.unit for entry in self.routes.commanders.values())

    def live_findings(self, unit: UnitAddress) -> list[Violation]:
        """What is wrong with ``unit`` right now that the rules judge only over the whole
        observation (its rates over their latest intervals: ``rates.live_findings``). A view
        for lint's live scorecard; nothing here is recorded."""
        entry = self.routes.entries.get(unit)
        return [] if entry is None else live_rate_findings(self.ctx, entry.state)

    def topics_cached(self) -> int:
        """Topics whose route ``feed`` keeps (at most ``MAX_TOPICS``: bounded memory)."""
        return len(self._by_topic)

    def state(self, unit: UnitAddress) -> UnitState:
        """What is known about ``unit`` (an empty state when nothing was seen yet)."""
        entry = self.routes.entries.get(unit)
        if entry is None:
            entry = self.routes.new_entry(unit, force=True)
        assert entry is not None
        return entry.state

    def record(self, unit: UnitAddress | None, rule: str, *, violation: Violation | None = None,
               seen: Observed | None = None, reason: str = "", excused: str = "") -> None:
        """Record what an active scenario saw of ``rule`` (evidence for the judge): a violation
        (``found``; with ``excused``, why it is no evidence: ``excuse``), or ``seen`` (``seen``:
        examined; not applicable or untestable, with its reason), or neither (examined).
        ``unit`` None: a finding that names no unit (a ROS bag's, reported unattributed)."""
        self.version += 1
        if rule not in CATALOGUE:
            get(rule)  # raises naming close ids
        entry = self.routes.entries.get(unit) or self.routes.new_entry(unit, force=True)
        assert entry is not None
        if violation is not None and excused:
            self._excuse(entry, rule, excused)
            return
        if violation is not None:
            self._found(entry, unit, rule, violation)
        if seen is not None:
            self._seen(entry, rule, seen, reason)
        elif violation is None:
            entry.state.examine(rule)
        if reason and seen in (None, Observed.EXAMINED):
            entry.state.note(rule, reason)

    @staticmethod
    def _excuse(entry: Row, rule: str, excused: str) -> None:
        """A violation that is no evidence (the unit had died, the link was down), and why:
        the judge says could-not-test."""
        rec = entry.records.get(rule)
        if rec is None:
            rec = entry.records[rule] = RuleRecord()
        rec.excused = rec.excused or excused

    def _found(self, entry: Row, unit: UnitAddress | None, rule: str,
               violation: Violation) -> None:
        """A violation a scenario found, on ``rule``, at the time it was found, of ``unit``."""
        if violation.rule != rule:
            violation = dataclasses.replace(violation, rule=rule)
        if violation.time is None and self._latest > float("-inf"):
            # when it was found (no answer came by then): a death before it explains it
            violation = dataclasses.replace(violation, time=self._latest)
        if not violation.unit and unit is not None:
            violation = dataclasses.replace(violation, unit=str(unit))
        entry.add(violation)

    @staticmethod
    def _seen(entry: Row, rule: str, seen: Observed, reason: str) -> None:
        """Examined, or said not applicable or untestable (and why); an untestable outweighs
        what was said before."""
        if seen is Observed.EXAMINED:
            entry.state.examine(rule)
            return
        rec = entry.records.get(rule)
        if rec is None:
            rec = entry.records[rule] = RuleRecord()
        if rec.explicit is None or seen is Observed.UNTESTABLE:
            rec.explicit, rec.reason = seen, reason

    def report(self, meta: RunMeta | None = None, **run: Any) -> RunReport:
        """The results so far as a ``RunReport``, with ``meta``. Before ``finish`` the
        end-of-run checks are judged provisionally at the latest arrival time, not stored.

        ``run``: broker, started, finished, suite_version, schemas_hash (each optional).
        """
        if unknown := set(run) - {"broker", "started", "finished", "suite_version", "schemas_hash"}:
            raise TypeError(f"not fields of a run (what it was is a RunMeta): {sorted(unknown)}")
        now = self._finished if self._finished is not None else self._now(None)
        units: dict[str, UnitReport] = {}
        for address, entry in sorted(self.routes.entries.items(),
                                     key=lambda kv: (kv[0] is None, str(kv[0] or ""))):
            final = entry.final if entry.final is not None else self._run_finish(entry, now)
            report = row_report(self.ctx, self.profile, self.kind, address, entry, final, now)
            units[report.unit] = report
        # In a certification the suite itself is the commander: no row of its own.
        if self.kind is RunKind.LINT:
            for _, entry in sorted(self.routes.commanders.items()):
                report = row_report(self.ctx, self.profile, self.kind, None, entry, Findings(), now)
                units[report.unit] = report
        started = run.pop("started", None)
        if started is None:
            started = min([self.ctx.started or self.created, self.created])
        return RunReport(
            kind=self.kind, started=float(started),
            finished=run.pop("finished", self._finished),
            broker=str(run.pop("broker", "")), profile=self.profile.name,
            suite_version=str(run.pop("suite_version", "") or suite_version()),
            schemas_hash=str(run.pop("schemas_hash", "") or schemas_hash()),
            units=units, gaps=self.ctx.gaps_until(now), unexamined=self._unexamined,
            meta=meta or RunMeta())

    # -- internals ------------------------------------------------------------------------

    def _now(self, now: float | None) -> float:
        if now is not None:
            return float(now)
        return self._latest if self._latest > float("-inf") else _time.time()


    def _run_finish(self, entry: Row, now: float) -> Findings:
        findings = Findings()
        if entry.state.address.prefix == UNATTRIBUTED:
            return findings
        unit = str(entry.state.address)
        for c in REGISTRY.at_finish:
            out = c.fn(self.ctx, entry.state, now, findings)
            if out:
                findings.violations.extend(
                    v if v.unit else dataclasses.replace(v, unit=unit) for v in out)
        return findings

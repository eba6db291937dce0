"""The history of commands, as the observer keeps it: what exec (spec 12) and TST (spec 14)
conversations have in common.

12.1: 'If a response is not arriving re-send the command with the same com-uuid. The receiver
of commands has to keep track of the history of commands' (and a new agent-uuid says it lost
it). The observer keeps the same history to judge the answers: commands known by com-uuid,
answers matched by response-to, resends, answers overdue, the unit's lives. TST is the same
pattern one level up: ``conversation`` and ``tst_conversation`` build on this module.
"""

from __future__ import annotations

import dataclasses
import functools
from collections import OrderedDict
from collections.abc import Callable
from copy import deepcopy
from typing import Any, TypeVar

from conformance.checks.base import BoundedDict, CheckContext, UnitState
from conformance.checks.stash import StashKey
from conformance.message import Message
from conformance.violation import Violation

PENDING_KEPT = 256
"""Commands awaiting an answer per unit; beyond it the oldest is dropped (and counted)."""
UNANSWERED_KEPT = 64
LIVES_KEPT = 8
VALUES_KEPT = 4
KINDS_KEPT = 16
OVER_A_GAP = ("could not be judged: the broker lost or held the unit's traffic meanwhile (the "
              "observer's connection was down, or the broker stalled), the capture cut a "
              "message then, or the host held the bundled unit (a loaded machine), so what the "
              "unit sent then is unknown (a broker's, a capture's or a host's fault is never "
              "the unit's)")
"""The reason a deadline over a gap of the observer is not judged."""

Judge = Callable[[CheckContext, UnitState, Any, float], list[Violation]]
"""``judge(ctx, unit, c, now)``: violations in what is still open in conversations ``c``."""
FinishCheck = Callable[[CheckContext, UnitState, float, Any], list[Violation]]


class SentCommand:
    """One command sent to a unit, known by its com-uuid, and what came back."""

    __slots__ = ("com_uuid", "name", "time", "last_sent", "sends", "answers", "owed",
                 "values", "digest", "excerpt", "life", "judged", "missed")

    def __init__(self, com_uuid: str, name: str, t: float, digest: bytes, excerpt: bytes,
                 life: str | None) -> None:
        self.com_uuid = com_uuid
        self.name = name
        self.time = self.last_sent = t
        self.sends = 1
        self.answers = 0
        self.owed = 1
        """Answers owed: one, and one more for each resend after an answer came (2, 12.1:
        the commander resends 'until ... a response has arrived'; a resend of a command that
        was never answered is answered once in all)."""
        self.values: list[tuple[str | None, str | None]] = []
        """(response, the task-uuid or root-uuid it named) of each answer, at most 4."""
        self.digest = digest
        """Of the content: a resend is the same content under the same com-uuid (12.1)."""
        self.excerpt = excerpt
        self.life = life
        """The unit's agent-uuid when the command was sent."""
        self.judged = False
        """Not judged any further: its com-uuid was reused for another command (EXEC-008)."""
        self.missed = False
        """Already judged unanswered: a late answer after that is EXEC-010's, not again its
        command's rule."""

    def describe(self) -> str:
        """The command as a finding names it; exec and TST commands add what they carry."""
        return f"{self.name} (com-uuid {self.com_uuid})"


class CommandHistory:
    """What one unit was told and how it answered (bounded); ``life`` is its agent-uuid."""

    def __init__(self, commands_kept: int) -> None:
        self.commands: BoundedDict = BoundedDict(commands_kept)
        self.pending: OrderedDict[str, Any] = OrderedDict()
        """Commands (and resends) awaiting an answer, oldest first."""
        self.unanswered: list[Any] = []
        """Commands that got no answer in time, judged when the unit next answers (or not)."""
        self.answered_any = False
        self.answered_kinds: set[str] = set()
        """The kinds of command (their names) the unit answered, at most KINDS_KEPT: only
        those, left unanswered, say it stopped answering (EXEC-ROBUST-001)."""
        self.last_answer: float | None = None
        """When the unit last answered a command it was sent (any answer, even a late one):
        only commands sent after it, left unanswered, say it stopped answering."""
        self.life: str | None = None
        self.lives: list[str] = []
        self.first_command: float | None = None
        self.dropped = 0
        """Open expectations dropped for bounded memory (said in the report)."""

    def await_answer(self, cmd: SentCommand) -> None:
        self.pending.pop(cmd.com_uuid, None)
        self.pending[cmd.com_uuid] = cmd
        if len(self.pending) > PENDING_KEPT:
            self.pending.popitem(last=False)
            self.dropped += 1

    def resent(self, cmd: SentCommand, t: float) -> None:
        """12.1: a resend (same com-uuid, same content) is answered again, not executed again."""
        cmd.sends += 1
        if cmd.answers:
            cmd.owed += 1
        cmd.last_sent = t
        self.commands[cmd.com_uuid] = cmd
        self.await_answer(cmd)

    def heard(self, cmd: SentCommand, value: str | None, named: str | None) -> None:
        """An answer to ``cmd``: once answered as often as owed, it awaits nothing more."""
        cmd.answers += 1
        if len(self.answered_kinds) < KINDS_KEPT:
            self.answered_kinds.add(cmd.name)
        if len(cmd.values) < VALUES_KEPT:
            cmd.values.append((value, named))
        if cmd.answers >= cmd.owed:
            self.pending.pop(cmd.com_uuid, None)
        if cmd in self.unanswered:
            self.unanswered.remove(cmd)

    def overdue(self, now: float, timeout: float, reboot: bool) -> list[Any]:
        """Take the commands whose answer deadline has passed (at a reboot: all) off
        ``pending``. Those never answered join ``unanswered``, to be judged when the unit next
        answers or at the end; those answered fewer times than sent (a resend left unanswered)
        are returned."""
        resent: list[Any] = []
        while self.pending:
            cmd = next(iter(self.pending.values()))
            if cmd.last_sent + timeout >= now and not reboot:
                break
            self.pending.popitem(last=False)
            if cmd.judged:
                continue
            if cmd.answers == 0:
                self.unanswered.append(cmd)
                if len(self.unanswered) > UNANSWERED_KEPT:
                    self.unanswered.pop(0)
                    self.dropped += 1
            elif cmd.answers < cmd.owed:
                resent.append(cmd)
        return resent

    def unanswered_before(self, t: float) -> list[Any]:
        """Take the commands left unanswered that were sent at or before ``t`` off
        ``unanswered``: the unit answered a later command, so each is its own fault."""
        due = [cmd for cmd in self.unanswered if cmd.last_sent <= t]
        self.unanswered = [cmd for cmd in self.unanswered if cmd.last_sent > t]
        return due

    def begin_life(self, agent: str) -> None:
        """12.1: a new agent-uuid is a new life, which lost the history of commands."""
        self.life = agent
        if agent not in self.lives:
            self.lives.append(agent)
            del self.lives[:-LIVES_KEPT]


H = TypeVar("H", bound=CommandHistory)


def per_unit(unit: UnitState, key: StashKey[H], make: Callable[[], H]) -> H:
    """The unit's conversation state under ``key``, made on first use and starting in the
    unit's current life (its agent-uuid): exec and TST conversations alike."""
    c = unit.stash.get(key)
    if c is None:
        c = unit.stash[key] = make()
        c.life = unit.agent_uuid
        if c.life is not None:
            c.lives.append(c.life)
    return c


def str_of(m: Any, key: str) -> str | None:
    """``m[key]`` when ``m`` is an object and that is a string, else None."""
    x = m.get(key) if isinstance(m, dict) else None
    return x if isinstance(x, str) else None


def response_timeout(ctx: CheckContext) -> float:
    """Seconds an answer may take (the profile's ``response_timeout``)."""
    return ctx.profile.response_timeout


def dead_since(unit: UnitState, c: CommandHistory, t: float, period: float,
               silence_periods: float) -> tuple[float, float] | None:
    """(dying since, last heartbeat) of a unit whose new life began at ``t``, if it was down
    for more than ``silence_periods`` heartbeat periods of ``period`` seconds (``identity``'s
    measures): what it left unanswered since then is the silence's (HB-010, HB-012), not
    each command's (see ``dying_from``). None when it was not down that long."""
    last = unit.last_heartbeat
    if last is None or not period or t - last <= silence_periods * period:
        return None
    return dying_from(c, last, period), last


def died_on(c: CommandHistory, last: float, period: float) -> Any:
    """The command a unit heard until its last heartbeat ``last`` may have died on: the last
    one it left unanswered within a period before ``last`` (the last a live unit received),
    else the first it left unanswered within a period after it; None when none came near."""
    near = [cmd for cmd in c.commands.values()
            if last - period <= cmd.last_sent <= last + period and cmd.answers == 0]
    before = [cmd for cmd in near if cmd.last_sent <= last]
    if before:
        return max(before, key=lambda cmd: cmd.last_sent)
    return min(near, key=lambda cmd: cmd.last_sent) if near else None


def died_on_any(c: CommandHistory, last: float, period: float) -> list[Any]:
    """Every command a unit heard until its last heartbeat ``last`` may have died on, the last
    first: those it left unanswered within a period before ``last``, and the first within a
    period after it, sent after the last command it answered: a command it answered another
    one after did not kill it. Which of them killed it the traffic cannot tell
    (docs/FIELD-NOTES.md 'Precision': a non-UTF-8 payload killed a unit that then received
    an unknown command; a unit with a 5 s heartbeat left one command unanswered and died on
    the next, sent after its last heartbeat)."""
    answered = max((cmd.last_sent for cmd in c.commands.values() if cmd.answers),
                   default=float("-inf"))
    near = [cmd for cmd in c.commands.values()
            if last - period <= cmd.last_sent <= last + period and cmd.answers == 0
            and cmd.last_sent > answered]
    before = sorted((cmd for cmd in near if cmd.last_sent <= last),
                    key=lambda cmd: cmd.last_sent, reverse=True)
    after = [cmd for cmd in near if cmd.last_sent > last]
    return ([min(after, key=lambda cmd: cmd.last_sent)] if after else []) + before


def dying_from(c: CommandHistory, last: float, period: float) -> float:
    """When a unit heard until its last heartbeat ``last`` began dying, as far as the commands
    it left unanswered go: at the command it may have died on (``died_on``), else at ``last``.
    Commands before that one were received by a live unit: each is its own finding
    (docs/FIELD-NOTES.md 'Precision': dying after a command)."""
    named = died_on(c, last, period)
    return min(named.last_sent, last) if named is not None else last


def judged_on_a_copy(key: StashKey[Any], dropped: tuple[str, str]
                     ) -> Callable[[Judge], FinishCheck]:
    """Make ``judge(ctx, unit, c, now) -> violations``, which judges what is still open in the
    unit's conversations ``c`` (under ``key``) when the observation ends, a finish check
    ``(ctx, unit, now, findings)``. Pure, so that a provisional report changes nothing:
    ``judge`` works on copies of the unit and of ``c``, and what they examined and noted is
    told to ``findings``; what the bounds dropped is noted on ``dropped`` (rule, what)."""
    def finish_check(judge: Judge) -> FinishCheck:
        @functools.wraps(judge)
        def at_end(ctx: CheckContext, unit: UnitState, now: float,
                   findings: Any) -> list[Violation]:
            original = unit.stash.get(key)
            if original is None:
                return []
            c = deepcopy(original)
            copy = dataclasses.replace(unit, examined={}, notes={},
                                       stash=unit.stash.with_item(key, c))
            found = judge(ctx, copy, c, now)
            if c.dropped:
                rule, what = dropped
                copy.note(rule, f"{c.dropped} {what} dropped (bounded memory): not judged")
            for rule, n in copy.examined.items():
                findings.examine(rule, n)
            for rule, why in copy.notes.items():
                findings.note(rule, why)
            return found

        return at_end

    return finish_check


def resends_unanswered(ctx: CheckContext, unit: UnitState, c: CommandHistory, now: float,
                       reboot: bool, rule: str, topic: Callable[[Any], str], detail: str
                       ) -> list[Violation]:
    """12.1: a resend is answered again. Each resent command whose second answer is overdue at
    ``now`` (at a reboot: every one) fails ``rule``, its evidence the command (on
    ``topic(cmd)``), unless the broker lost or held traffic meanwhile (the first may never have
    reached the unit): exec and TST conversations alike."""
    found: list[Violation] = []
    timeout = response_timeout(ctx)
    for cmd in c.overdue(now, timeout, reboot):
        if ctx.gaps and ctx.in_gap(cmd.time, cmd.last_sent + timeout):
            unit.note(rule, OVER_A_GAP)  # the first may never have reached it
            continue
        unit.examine(rule)
        found.append(late(rule, topic(cmd), cmd, f"a second answer to the resent "
                          f"{cmd.describe()} within {timeout:.1f} s", "none", cmd.last_sent,
                          detail))
    return found


def left_unanswered(ctx: CheckContext, unit: UnitState, rule: str, cmd: SentCommand,
                    topic: str, detail: str) -> list[Violation]:
    """12.1, 14.4: a command the unit never answered fails ``rule``, its evidence the command
    (on ``topic``), unless the broker lost or held traffic within its response timeout (its
    answer may be what was lost). Marked ``missed``: an answer after this is
    only late (EXEC-010). Exec and TST conversations alike."""
    timeout = response_timeout(ctx)
    if ctx.gaps and ctx.in_gap(cmd.last_sent, cmd.last_sent + timeout):
        unit.note(rule, OVER_A_GAP)
        return []
    unit.examine(rule)
    cmd.missed = True
    return [dataclasses.replace(late(rule, topic, cmd, f"an answer to {cmd.describe()} within "
                                     f"{timeout:.1f} s", "no answer", cmd.last_sent, detail),
                                command=cmd.com_uuid)]


def violation(rule: str, msg: Message, *, expected: str, observed: str, path: str,
              detail: str = "") -> Violation:
    """A violation found in ``msg``: it is the evidence."""
    return Violation.of(rule, expected=expected, observed=observed, topic=msg.topic, path=path,
                        time=msg.time, payload=msg.payload, detail=detail)


def late(rule: str, topic: str, cmd: SentCommand | None, expected: str, observed: str,
         t: float, detail: str) -> Violation:
    """A violation found when a deadline passed: its evidence is the command (on ``topic``)."""
    return Violation.of(rule, expected=expected, observed=observed, topic=topic, path="$",
                        time=t, payload=cmd.excerpt if cmd is not None else None, detail=detail)

"""TST execution (14): trees the unit runs, signals at node, tree and unit level, refusals, a
resend, and tst_execution_info while and after trees run.

This scenario only sends stimuli and waits for them to take effect, with deadlines; the verdicts
of the conversation rules (TST-004, TST-006..TST-013) are the Monitor's
(``checks/tst_conversation.py``), which judges the same traffic in ``lint``. It records only what
it alone knows: which trees the unit can run (TST-004 for a refused tree of a task the unit
lists, TST-005 for the trees it must refuse).

The stimuli, with tasks the safety policy lets it start (docs/ARCHITECTURE.md 'Safety'; positions
near the unit), every node written as 11's examples write them (``tst_commander.node``):
- seq [a, b, c]: node $pause, $continue and $enough of a (then b runs), tree $pause and
  $continue, node $abort of b (the seq then revokes c and ends aborted);
- conc [a, b] of two tasks of different kinds: unit $pause and $continue, node $abort of b
  (the conc then aborts a and ends aborted);
- a one-leaf tree per task, each ended by a signal: tree $abort and $enough, unit $enough
  and $abort;
- trees it must refuse (TST-005): a node name no unit offers, and a seq with a node for
  another execunit; then (own topic only: on an operator's, a unit stays silent about nodes
  it does not know) a signal for a node no tree has;
- a resend of a start-tst (TST-006, TST-007);
- a tst_execution_info composed after the last node ended (TST-013).
"""

from __future__ import annotations

from itertools import cycle

from conformance.protocol import NO_SUCH_TASK
from conformance.scenarios.context import Context, describe
from conformance.scenarios.deviation import SHORT
from conformance.scenarios.params import valid_params
from conformance.scenarios.safety import Position
from conformance.scenarios.sender import new_uuid
from conformance.scenarios.traffic import Entry
from conformance.scenarios.tst_commander import TstCommander, node
from conformance.tst import FINAL
from conformance.violation import Observed

RULES = ("TST-004", "TST-005", "TST-006", "TST-007", "TST-008", "TST-009", "TST-010",
         "TST-011", "TST-012", "TST-013")
LIVE = ("active", "running", "waiting")
PAUSE = ("$pause", "$continue")
LEAF_ENDINGS = (("signal-tst-tree", "$abort"), ("signal-tst-tree", "$enough"),
                ("signal-unit", "$enough"), ("signal-unit", "$abort"))
"""The signals the leaf trees end with: those the seq and conc trees do not send."""


class _Drive:
    """One run of the scenario: the unit, where it is, and what was sent."""

    def __init__(self, ctx: Context, tc: TstCommander, origin: Position) -> None:
        self.ctx, self.tc, self.origin = ctx, tc, origin
        self.refused: list[tuple[list[str], int, str]] = []
        """(node-uuids, mark, what) of trees it refused: nothing of them may run."""
        self.salt = 0
        self.misread = False
        """A tree came back under a root-uuid of the unit's own: it did not read the nodes'
        common_params (TST-004's finding), so it cannot see an execunit either."""

    def takes(self, *tasks: str) -> bool:
        """Whether each of ``tasks`` lists $pause and $continue (5.3: 'for each task a list of
        signals it understands'; a task the unit does not describe is taken to)."""
        available = self.ctx.tasks_available()
        return all(s in available.get(t, PAUSE) for t in tasks for s in PAUSE)

    def params(self, task: str) -> dict[str, object]:
        self.salt += 1
        return valid_params(task, self.origin, self.ctx.safety, self.ctx.seed + self.salt)

    def started(self, task: str, answer: Entry | None) -> bool:
        """Whether a tree of tasks the unit lists runs; a refusal is TST-004's (only the
        suite knows the unit can run it: it offers the task)."""
        if answer is None:
            return False  # unanswered: the Monitor's finding (TST-004)
        if answer.get("response") == "failed":
            self.ctx.record("TST-004", violation=self.ctx.violation(
                "TST-004", expected=f"'started' for a tree of '{task}', a task the unit lists "
                "in tasks-available", observed=f"'failed': {answer.get('fail-reason')!r}",
                subtopic="tst/response", entry=answer))
            return False
        return True

    def signal(self, command: str, target: str, signal: str, watch: str,
               wanted: tuple[str, ...]) -> bool:
        """Send a signal; once answered 'ok', wait for ``watch`` to report one of ``wanted``
        (unless it has ended already). Whether it did."""
        ctx, tc = self.ctx, self.tc
        mark = ctx.traffic.mark()
        if tc.over(watch):
            return False
        _, answer = tc.signal(command, target, signal, ctx.timing.response)
        if answer is None or answer.get("response") != "ok":
            return False
        # The full feedback deadline until the unit showed it does not do this (deviation.py).
        return tc.effect(signal, watch, wanted, after=mark, timeout=ctx.timing.feedback,
                         short=SHORT * ctx.timing.response, target=target) is not None

    def end(self, root: str, command: str, signal: str) -> None:
        """End a tree with a signal at ``command``'s level; if it goes on, with the tree's
        $enough (teardown aborts what is left)."""
        target = self.tc.me if command == "signal-unit" else root
        if not self.signal(command, target, signal, root, FINAL) and not self.tc.over(root):
            self.signal("signal-tst-tree", root, "$enough", root, FINAL)

    # --- the trees ----------------------------------------------------------------------
    def leaf(self, task: str, ending: tuple[str, str]) -> None:
        ctx, tc = self.ctx, self.tc
        given = new_uuid()
        sent, answer, root = tc.start(node(task, self.params(task), given, execunit=tc.me),
                                      ctx.timing.response)
        if not self.started(task, answer):
            return
        root, live = tc.follow(given, root, LIVE, ctx.timing.response, after=sent.mark)
        self.misread |= root != given  # its own node-uuids: it did not read common_params
        if live is None:
            return
        self.end(root, *ending)

    def seq(self, a: str, b: str) -> None:
        ctx, tc = self.ctx, self.tc
        s, na, nb, nc = new_uuid(), new_uuid(), new_uuid(), new_uuid()
        me = tc.me
        sent, answer, root = tc.start(node("seq", {}, s, [
            node(a, self.params(a), na, execunit=me), node(b, self.params(b), nb, execunit=me),
            node(a, self.params(a), nc, execunit=me)], execunit=me), ctx.timing.response)
        if not self.started(f"seq [{a}, {b}, {a}]", answer):
            return
        if root != s:
            root, _ = tc.follow(s, root, None, ctx.timing.response, after=sent.mark)
        if root == s and tc.feedback(na, ("running",), ctx.timing.response,
                                     after=sent.mark) is not None:
            if self.takes(a):  # pause and resume only what lists them (5.3)
                self.signal("signal-tst-node", na, "$pause", na, ("paused",))
                self.signal("signal-tst-node", na, "$continue", na, ("running",))
            self.wait_info()  # nodes-executing while they run (TST-013)
            if self.signal("signal-tst-node", na, "$enough", na, FINAL):
                tc.feedback(nb, ("running",), ctx.timing.response, after=sent.mark)
            if self.takes(b):  # the node the tree runs now
                self.signal("signal-tst-tree", s, "$pause", s, ("paused",))
                self.signal("signal-tst-tree", s, "$continue", s, ("running",))
            self.signal("signal-tst-node", nb, "$abort", s, FINAL)
        if not tc.over(root, sent.mark):
            self.end(root, "signal-tst-tree", "$enough")

    def conc(self, a: str, b: str) -> None:
        ctx, tc = self.ctx, self.tc
        c, na, nb = new_uuid(), new_uuid(), new_uuid()
        me = tc.me
        sent, answer, root = tc.start(node("conc", {}, c, [
            node(a, self.params(a), na, execunit=me), node(b, self.params(b), nb, execunit=me)],
            execunit=me), ctx.timing.response)
        if not self.started(f"conc [{a}, {b}]", answer):
            return
        if root != c:
            root, _ = tc.follow(c, root, None, ctx.timing.response, after=sent.mark)
        if root == c and all(tc.feedback(n, ("running",), ctx.timing.response, after=sent.mark)
                             for n in (na, nb)):
            if self.takes(a, b):
                self.signal("signal-unit", tc.me, "$pause", c, ("paused",))
                self.signal("signal-unit", tc.me, "$continue", c, ("running",))
            self.signal("signal-tst-node", nb, "$abort", c, FINAL)
        if not tc.over(root, sent.mark):
            self.end(root, "signal-tst-tree", "$enough")

    def refusals(self, task: str) -> None:
        """TST-005: trees the unit cannot run are answered 'failed', and nothing of them
        runs (judged after the next tree's answer: a unit answers in order)."""
        ctx, tc = self.ctx, self.tc
        unknown = new_uuid()
        s, foreign = new_uuid(), new_uuid()
        other = f"/{ctx.unit.name}-not"
        trees = [([unknown], node(NO_SUCH_TASK, {}, unknown, execunit=tc.me),
                  f"a tree of '{NO_SUCH_TASK}', a name no unit offers")]
        if not self.misread:  # else it cannot see the execunit: TST-004's finding
            trees.append(([s, foreign], node("seq", {}, s, [
                node(task, self.params(task), foreign, execunit=other)], execunit=tc.me),
                f"a tree with a node for execunit {other} (the catalogue's decision: a unit "
                "runs only its own nodes)"))
        for ids, tree, what in trees:
            sent, answer, root = tc.start(tree, ctx.timing.response)
            if answer is None:
                continue  # unanswered: the Monitor's finding (TST-004)
            if answer.get("response") == "failed":
                self.refused.append((ids, sent.mark, what))
                continue
            ctx.record("TST-005", violation=ctx.violation(
                "TST-005", expected=f"'failed' with a reason for {what}",
                observed=describe(answer), subtopic="tst/response", entry=answer))
            self.end(root, "signal-tst-tree", "$abort")
        if not tc.shared:
            # 14.3: a signal for a node no tree has is refused (the Monitor judges TST-011).
            tc.signal("signal-tst-node", new_uuid(), "$abort", ctx.timing.response)

    def nothing_ran(self) -> None:
        for ids, mark, what in self.refused:
            ran = [n for n in ids if self.tc.statuses(n, mark)]
            if ran:
                self.ctx.record("TST-005", violation=self.ctx.violation(
                    "TST-005", expected=f"nothing of {what} runs once it is refused",
                    observed=f"feedback for node {ran[0]}: {self.tc.statuses(ran[0], mark)}",
                    subtopic="tst/feedback"))
            else:
                self.ctx.record("TST-005", seen=Observed.EXAMINED)

    def resend(self, task: str) -> None:
        """12.1 for start-tst: answered again (TST-007), started once (TST-006)."""
        ctx, tc = self.ctx, self.tc
        given = new_uuid()
        sent, answer, root = tc.start(node(task, self.params(task), given, execunit=tc.me),
                                      ctx.timing.response)
        if answer is None:
            return
        again = tc.resend(sent)
        tc.response(sent, ctx.timing.response, after=again.mark)
        self.nothing_ran()  # the refusals' messages are in by now
        if answer.get("response") != "failed":
            root, _ = tc.follow(given, root, LIVE, ctx.timing.response, after=sent.mark)
            self.end(root, "signal-tst-node", "$abort")

    def wait_info(self, after_time: float | None = None) -> None:
        """The next tst_execution_info (arriving after ``after_time``, Unix seconds)."""
        ctx = self.ctx
        period = ctx.timing.periods(2, ctx.rate_of("tst_execution_info"))
        since = after_time or 0.0
        ahead = max(0.0, since - ctx.traffic.clock.now())
        ctx.traffic.wait_for(lambda e: e.time > since, period + ahead,
                             after=ctx.traffic.mark(), subtopic="tst_execution_info")

    def info_after_the_ends(self) -> None:
        """TST-013: an info composed a period after the last node ended lists none of them."""
        finals = [e.time for e in self.ctx.traffic.since(0, "tst/feedback")
                  if e.get("status") in FINAL]
        if finals:
            rate = self.ctx.rate_of("tst_execution_info")
            self.wait_info(max(finals) + max(1.0, 1.0 / rate if rate else 1.0))


def _kind(task: str) -> str:
    return task.split("-", 1)[0]


def run(ctx: Context) -> None:
    tc = ctx.tst
    origin = ctx.position()
    tasks = ctx.startable("tst")
    if tc is None or origin is None or not tasks:
        reason = ("no TST command topic" if tc is None else
                  "the unit reports no sensor/position: task positions are generated near it "
                  "(docs/ARCHITECTURE.md 'Safety')" if origin is None else
                  ctx.none_startable("tst"))
        for rule in RULES:
            ctx.record(rule, seen=Observed.UNTESTABLE, reason=reason)
        return
    drive = _Drive(ctx, tc, origin)
    # Tasks that list $pause and $continue first: the composite trees pause and resume them.
    tasks = sorted(tasks, key=lambda t: not drive.takes(t))
    safe = [t for t in tasks if not ctx.safety.moves(t)] or tasks
    a = safe[0]
    b = next((t for t in safe if _kind(t) != _kind(a)), next(
        (t for t in tasks if _kind(t) != _kind(a)), a))
    # The composite trees first: the deadline a seq or conc's final status has in the
    # Monitor (TST-009) then runs out while the leaf trees run, not in the settle at the end.
    drive.seq(a, safe[1] if len(safe) > 1 else a)
    drive.conc(a, b)
    leaves = list(tasks)
    while len(leaves) < len(LEAF_ENDINGS):  # each ending at least once
        leaves.append(tasks[len(leaves) % len(tasks)])
    for task, ending in zip(leaves, cycle(LEAF_ENDINGS)):
        drive.leaf(task, ending)
    drive.refusals(a)
    drive.resend(a)
    drive.info_after_the_ends()
    ctx.settle()

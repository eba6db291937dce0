"""TST conversations judged from traffic alone (checks/tst_conversation.py): each judgement shown
passing on a conformant exchange and failing on the matching fault, with the blame on the root
cause; and commands sent to an operator's tst/command judged as the unit's they concern
(checks/tst_routing.py)."""

from __future__ import annotations

import uuid
from typing import Any

from conformance.checks import Monitor
from conformance.profile import Profile
from conformance.topics import UnitAddress
from conformance.violation import Verdict

TIMEOUTS = Profile(response_timeout=1.0, feedback_timeout=3.0)
TST_RULES = ("TST-004", "TST-006", "TST-007", "TST-008", "TST-009", "TST-010", "TST-011",
             "TST-012", "TST-013")


def new() -> str:
    return str(uuid.uuid4())


class Tst:
    """The TST side of a unit's traffic: commands (on its own tst/command or an operator's),
    answers and feedback, tst_execution_info with nodes-executing."""

    def __init__(self, stream: Any, operator: UnitAddress | None = None) -> None:
        self.s = stream
        self.t0 = stream.msg("heartbeat", b"{}", 0.0).time
        self.s.levels = ["sensor", "direct execution", "tst execution"]
        self.base = operator or stream.address

    def _msg(self, sub: str, body: dict[str, Any], t: float):
        import orjson

        from conformance.client import Message

        return Message(self.t0 + t, self.base.topic(sub), orjson.dumps(body), 0, False)

    def command(self, t: float, command: str, com: str | None = None, **extra: Any):
        return self._msg("tst/command", {"com-uuid": com or new(), "command": command,
                                         "sender": "commander", **extra}, t)

    def start(self, t: float, tree: dict[str, Any], com: str | None = None):
        return self.command(t, "start-tst", com, tst=tree)

    def signal(self, t: float, command: str, target: str, signal: str, com: str | None = None):
        key = "unit" if command == "signal-unit" else "node-uuid"
        return self.command(t, command, com, **{key: target, "signal": signal})

    def response(self, t: float, to: str, response: str, reason: str = "", **extra: Any):
        return self._msg("tst/response", {"com-uuid": new(), "fail-reason": reason,
                                          "response": response, "response-to": to, **extra}, t)

    def feedback(self, t: float, node: str, status: str, root: bool):
        return self._msg("tst/feedback", {"com-uuid": new(), "fail-reason": "",
                                          "node-uuid": node, "root-flag": root,
                                          "status": status}, t)

    def info(self, t: float, nodes: list[tuple[str, str]]):
        """tst_execution_info listing (node-uuid, root-uuid) pairs."""
        return self.s.msg("tst_execution_info", {
            "name": self.s.address.name, "rate": self.s.rate, "stamp": self.t0 + t,
            "type": "TstExecutionInfo", "agent-uuid": self.s.agent_uuid,
            "nodes-executing": [{"node-name": "n", "node-uuid": n, "root-uuid": r}
                                for n, r in nodes]}, t)


def leaf(name: str, node_uuid: str, execunit: str = "/dji0") -> dict[str, Any]:
    return {"name": name, "params": {"bearing": 10.0}, "children": [],
            "common_params": {"execunit": execunit, "node-uuid": node_uuid}}


def composite(kind: str, node_uuid: str, children: list[dict[str, Any]]) -> dict[str, Any]:
    return {"name": kind, "params": {}, "children": children,
            "common_params": {"execunit": "/dji0", "node-uuid": node_uuid}}


def com_of(msg) -> str:
    import orjson

    return str(orjson.loads(msg.payload)["com-uuid"])


def judge(stream: Any, extra: list, seconds: float = 20.0, *, units=None,
          profile: Profile = TIMEOUTS):
    m = Monitor(profile, units=units)
    stream.feed(m, stream.alive(seconds) + extra)
    m.finish()
    return m.report()


def failing(report, unit: str) -> set[str]:
    """Rules that fail or warn (TST-007 and TST-013 are warnings by default)."""
    return {r for r, res in report.units[unit].rules.items()
            if res.verdict in (Verdict.FAIL, Verdict.WARN)}


def a_leaf_run(x: Tst, t: float, node: str, *, end: str = "$enough", answer: str = "started",
               root_uuid: str | None = None, flag_children: bool = False) -> list:
    """start-tst of one leaf, answered, running, listed, then ended by a node signal."""
    start = x.start(t, leaf("look-at-bearing", node))
    sig = x.signal(t + 2.0, "signal-tst-node", node, end)
    final = {"$enough": "succeeded", "$abort": "aborted"}[end]
    return [start, x.response(t + 0.1, com_of(start), answer, **{"root-uuid": root_uuid or node}),
            x.feedback(t + 0.2, node, "active", True), x.feedback(t + 0.3, node, "running", True),
            x.info(t + 1.5, [(node, node)]), sig, x.response(t + 2.1, com_of(sig), "ok"),
            x.feedback(t + 2.2, node, final, True), x.info(t + 4.5, [])]


def test_a_conformant_tree_passes_every_rule_it_shows(stream):
    x = Tst(stream)
    report = judge(stream, a_leaf_run(x, 2.0, new()))
    rules = report.units[str(stream.address)].rules
    assert {r: rules[r].verdict.value for r in ("TST-004", "TST-008", "TST-009", "TST-011",
                                                "TST-012", "TST-013")} == dict.fromkeys(
        ("TST-004", "TST-008", "TST-009", "TST-011", "TST-012", "TST-013"), "pass")
    assert not failing(report, str(stream.address))


def test_root_uuid_other_than_the_roots_node_uuid_fails_tst_004_alone(stream):
    x = Tst(stream)
    node = new()
    report = judge(stream, a_leaf_run(x, 2.0, node, root_uuid=new()))
    assert failing(report, str(stream.address)) == {"TST-004"}
    v = report.units[str(stream.address)].rules["TST-004"].violations[0]
    assert node in v.expected


def test_running_answers_open_the_tree_like_started(stream):
    x = Tst(stream)
    report = judge(stream, a_leaf_run(x, 2.0, new(), answer="running"))
    # 'running' is ERR-015's (the validator's, a warning by default): the tree is judged.
    assert failing(report, str(stream.address)) == {"ERR-015"}
    assert report.units[str(stream.address)].rules["TST-012"].verdict is Verdict.PASS


def seq_run(x: Tst, t: float, *, root_flags: bool = False, seq_final: str = "aborted",
            second_runs: bool = False, seq_silent: bool = False,
            announced: bool = False) -> tuple[list, str]:
    """seq [a, b]: a is aborted by a node signal, then b is revoked and the seq ends aborted
    (or, bent: b runs anyway; the seq says another status, or none). ``announced``: every
    node says 'not-active' (14.5) when the tree starts, before the seq is active."""
    s, a, b = new(), new(), new()
    start = x.start(t, composite("seq", s, [leaf("look-at-bearing", a),
                                             leaf("look-at-bearing", b)]))
    sig = x.signal(t + 1.0, "signal-tst-node", a, "$abort")
    out = [start, x.response(t + 0.1, com_of(start), "started", **{"root-uuid": s})]
    if announced:
        out += [x.feedback(t + 0.15, n, "not-active", n == s or root_flags) for n in (s, a, b)]
    out += [x.feedback(t + 0.2, s, "active", True), x.feedback(t + 0.21, s, "running", True),
           x.feedback(t + 0.3, a, "active", root_flags), x.feedback(t + 0.31, a, "running",
                                                                      root_flags),
           sig, x.response(t + 1.1, com_of(sig), "ok"),
           x.feedback(t + 1.2, a, "aborted", root_flags)]
    if second_runs:
        out += [x.feedback(t + 1.3, b, "active", root_flags),
                x.feedback(t + 1.4, b, "succeeded", root_flags)]
    else:
        out.append(x.feedback(t + 1.3, b, "revoked", root_flags))
    if not seq_silent:
        out.append(x.feedback(t + 1.5, s, seq_final, True))
    return out, s


def test_a_seq_that_stops_at_an_aborted_child_passes(stream):
    x = Tst(stream)
    msgs, _ = seq_run(x, 2.0)
    report = judge(stream, msgs)
    assert failing(report, str(stream.address)) == set()
    rules = report.units[str(stream.address)].rules
    assert rules["TST-010"].verdict is Verdict.PASS and rules["TST-008"].verdict is Verdict.PASS


def test_a_seq_whose_nodes_are_announced_not_active_at_the_start_passes(stream):
    # An independent unit says 'not-active' for every node before running the
    # first: b's 'not-active' is not b started while a runs.
    x = Tst(stream)
    msgs, _ = seq_run(x, 2.0, announced=True)
    report = judge(stream, msgs)
    assert failing(report, str(stream.address)) == set()
    assert report.units[str(stream.address)].rules["TST-010"].verdict is Verdict.PASS


def test_a_node_announced_not_active_need_not_be_in_nodes_executing(stream):
    # seq [a, b], every node 'not-active' first: b is not executing while a runs, so an info
    # that lists s and a only is right (TST-013), and b starts once a succeeded (TST-010).
    x = Tst(stream)
    s, a, b = new(), new(), new()
    t = 2.0
    start = x.start(t, composite("seq", s, [leaf("look-at-bearing", a),
                                             leaf("look-at-bearing", b)]))
    enough_a, enough_b = (x.signal(t + 3.0, "signal-tst-node", a, "$enough"),
                          x.signal(t + 5.0, "signal-tst-node", b, "$enough"))
    msgs = [start, x.response(t + 0.1, com_of(start), "started", **{"root-uuid": s}),
            *[x.feedback(t + 0.15, n, "not-active", n == s) for n in (s, a, b)],
            x.feedback(t + 0.2, s, "active", True), x.feedback(t + 0.21, s, "running", True),
            x.feedback(t + 0.3, a, "active", False), x.feedback(t + 0.31, a, "running", False),
            x.info(t + 1.5, [(s, s), (a, s)]), x.info(t + 2.5, [(s, s), (a, s)]),
            enough_a, x.response(t + 3.05, com_of(enough_a), "ok"),
            x.feedback(t + 3.1, a, "succeeded", False), x.feedback(t + 3.2, b, "active", False),
            x.feedback(t + 3.21, b, "running", False), x.info(t + 4.5, [(s, s), (b, s)]),
            enough_b, x.response(t + 5.05, com_of(enough_b), "ok"),
            x.feedback(t + 5.1, b, "succeeded", False), x.feedback(t + 5.2, s, "succeeded", True),
            x.info(t + 7.0, [])]
    report = judge(stream, msgs)
    assert failing(report, str(stream.address)) == set()
    rules = report.units[str(stream.address)].rules
    assert rules["TST-013"].verdict is Verdict.PASS and rules["TST-010"].verdict is Verdict.PASS


def test_an_announced_seq_that_goes_on_after_a_failure_fails_tst_010_alone(stream):
    x = Tst(stream)
    msgs, _ = seq_run(x, 2.0, announced=True, second_runs=True, seq_final="succeeded")
    report = judge(stream, msgs)
    assert failing(report, str(stream.address)) == {"TST-010"}
    v = report.units[str(stream.address)].rules["TST-010"].violations[0]
    assert v.observed.startswith("'active' while child") and "ended 'aborted'" in v.observed


def test_root_flag_on_every_node_fails_tst_008_alone(stream):
    x = Tst(stream)
    msgs, _ = seq_run(x, 2.0, root_flags=True)
    assert failing(judge(stream, msgs), str(stream.address)) == {"TST-008"}


def test_a_seq_that_goes_on_after_a_failure_and_succeeds_fails_tst_010_alone(stream):
    x = Tst(stream)
    msgs, _ = seq_run(x, 2.0, second_runs=True, seq_final="succeeded")
    report = judge(stream, msgs)
    assert failing(report, str(stream.address)) == {"TST-010"}
    assert report.units[str(stream.address)].violation_counts["TST-010"] == 1


def test_a_composite_that_never_says_its_end_fails_tst_009_alone(stream):
    x = Tst(stream)
    msgs, s = seq_run(x, 2.0, seq_silent=True)
    # and a signal to it: its children ended as asked; its silence is TST-009's, not TST-012's
    sig = x.signal(4.0, "signal-tst-tree", s, "$enough")
    report = judge(stream, msgs + [sig, x.response(4.1, com_of(sig), "ok")])
    assert failing(report, str(stream.address)) == {"TST-009"}
    (v,) = report.units[str(stream.address)].rules["TST-009"].violations
    assert s in v.expected and "children all ended" in v.observed


def test_feedback_after_a_final_status_fails_tst_009(stream):
    x = Tst(stream)
    node = new()
    msgs = a_leaf_run(x, 2.0, node) + [x.feedback(5.0, node, "running", True)]
    assert failing(judge(stream, msgs), str(stream.address)) == {"TST-009"}


def test_signals_answered_wrongly_fail_tst_011(stream):
    x = Tst(stream)
    node = new()
    msgs = a_leaf_run(x, 2.0, node)
    ended = x.signal(6.0, "signal-tst-node", node, "$abort")  # its tree has ended: 'failed'
    ghost = x.signal(7.0, "signal-tst-node", new(), "$pause")  # never seen: 'failed'
    bare = x.signal(8.0, "signal-tst-node", new(), "$pause")  # 'started': no signal answer
    lost = x.signal(9.0, "signal-unit", "/dji0", "$pause")  # never answered
    later = x.signal(12.0, "signal-tst-node", new(), "$pause")
    wrong = msgs + [ended, x.response(6.1, com_of(ended), "ok"),
                    ghost, x.response(7.1, com_of(ghost), "ok"),
                    bare, x.response(8.1, com_of(bare), "started"), lost,
                    later, x.response(12.1, com_of(later), "failed", "no such node")]
    report = judge(stream, wrong)
    assert failing(report, str(stream.address)) == {"TST-011"}
    assert report.units[str(stream.address)].violation_counts["TST-011"] == 4
    right = msgs + [ended, x.response(6.1, com_of(ended), "failed", "the tree has ended"),
                    ghost, x.response(7.1, com_of(ghost), "failed", "no such node")]
    assert failing(judge(stream, right), str(stream.address)) == set()


def test_a_leaf_refusing_a_signal_its_task_does_not_list_is_not_faulted(stream):
    """5.3: 'for each task a list of signals it understands': the stream's move-to lists
    $abort and $enough only, so a running move-to node may refuse $pause; a node of a task
    that lists $pause (or one the unit does not describe) may not."""
    x = Tst(stream)

    def refused(task: str) -> list:
        node = new()
        start = x.start(2.0, {**leaf(task, node), "params": {}})
        sig = x.signal(3.0, "signal-tst-node", node, "$pause")
        return [start, x.response(2.1, com_of(start), "started", **{"root-uuid": node}),
                x.feedback(2.2, node, "active", True), x.feedback(2.3, node, "running", True),
                sig, x.response(3.1, com_of(sig), "failed", "move-to does not understand $pause")]

    unlisted = judge(stream, refused("move-to")).units[str(stream.address)].rules
    assert unlisted["TST-011"].verdict is Verdict.PASS
    listed = judge(stream, refused("look-at-bearing")).units[str(stream.address)].rules
    assert listed["TST-011"].verdict is Verdict.WARN  # decided: warns by default


def test_a_signal_whose_final_feedback_came_before_its_answer_examines_tst_012(stream):
    """12 orders no topics: a node that ends as its signal asks before the (slow) answer
    came is evidence of TST-012, not nothing to judge."""
    x = Tst(stream)
    node = new()
    start = x.start(2.0, leaf("look-at-bearing", node))
    sig = x.signal(3.0, "signal-tst-node", node, "$abort")
    msgs = [start, x.response(2.1, com_of(start), "started", **{"root-uuid": node}),
            x.feedback(2.2, node, "active", True), x.feedback(2.3, node, "running", True),
            sig, x.feedback(3.2, node, "aborted", True), x.response(5.0, com_of(sig), "ok")]
    rules = judge(stream, msgs).units[str(stream.address)].rules
    assert rules["TST-012"].verdict is Verdict.PASS


def test_an_abort_answered_ok_and_ignored_fails_tst_012_at_its_deadline(stream):
    x = Tst(stream)
    node = new()
    start = x.start(2.0, leaf("look-at-bearing", node))
    sig = x.signal(3.0, "signal-tst-node", node, "$abort")
    msgs = [start, x.response(2.1, com_of(start), "started", **{"root-uuid": node}),
            x.feedback(2.2, node, "active", True), x.feedback(2.3, node, "running", True),
            sig, x.response(3.1, com_of(sig), "ok")]
    report = judge(stream, msgs)
    assert failing(report, str(stream.address)) == {"TST-012"}
    # still running at the end: TST-009 is not judged on it
    assert report.units[str(stream.address)].rules["TST-009"].verdict is not Verdict.FAIL


def test_resends_answered_again_and_started_once(stream):
    x = Tst(stream)
    node = new()
    com = new()
    start = x.start(2.0, leaf("look-at-bearing", node), com)
    again = x.start(3.0, leaf("look-at-bearing", node), com)
    base = [start, x.response(2.1, com, "started", **{"root-uuid": node}),
            x.feedback(2.2, node, "active", True), x.feedback(2.3, node, "running", True), again]
    end = x.signal(5.0, "signal-tst-node", node, "$abort")
    ending = [end, x.response(5.1, com_of(end), "ok"), x.feedback(5.2, node, "aborted", True)]
    good = base + [x.response(3.1, com, "started", **{"root-uuid": node})] + ending
    report = judge(stream, good)
    assert failing(report, str(stream.address)) == set()
    assert report.units[str(stream.address)].rules["TST-007"].verdict is Verdict.PASS
    unanswered = base + ending
    assert failing(judge(stream, unanswered), str(stream.address)) == {"TST-007"}
    twice = base + [x.response(3.1, com, "started", **{"root-uuid": node}),
                    x.feedback(3.2, node, "active", True),
                    x.feedback(3.3, node, "running", True)] + ending
    assert failing(judge(stream, twice), str(stream.address)) == {"TST-006"}


def test_a_final_status_said_again_after_a_resend_is_tst_009_not_a_second_start(stream):
    """After a resent start-tst, a node running again was started twice (TST-006's words);
    its final status said once more is only TST-009's (decided: 14.5 names no final)."""
    x = Tst(stream)
    node, com = new(), new()
    start = x.start(2.0, leaf("look-at-bearing", node), com)
    end = x.signal(4.0, "signal-tst-node", node, "$abort")
    done = [start, x.response(2.1, com, "started", **{"root-uuid": node}),
            x.feedback(2.2, node, "active", True), x.feedback(2.3, node, "running", True),
            end, x.response(4.1, com_of(end), "ok"), x.feedback(4.2, node, "aborted", True),
            x.start(6.0, leaf("look-at-bearing", node), com),
            x.response(6.1, com, "started", **{"root-uuid": node})]
    said_again = judge(stream, done + [x.feedback(6.2, node, "aborted", True)])
    assert failing(said_again, str(stream.address)) == {"TST-009"}
    restarted = judge(stream, done + [x.feedback(6.2, node, "running", True)])
    assert "TST-006" in failing(restarted, str(stream.address))


def test_nodes_executing_that_lists_ended_nodes_or_misses_running_ones_fails_tst_013(stream):
    x = Tst(stream)
    node = new()
    stale = a_leaf_run(x, 2.0, node)[:-1] + [x.info(5.5, [(node, node)])]
    assert failing(judge(stream, stale), str(stream.address)) == {"TST-013"}
    other = new()
    start = x.start(2.0, leaf("look-at-bearing", other))
    sig = x.signal(6.0, "signal-tst-node", other, "$enough")
    missing = [start, x.response(2.1, com_of(start), "started", **{"root-uuid": other}),
               x.feedback(2.2, other, "active", True), x.feedback(2.3, other, "running", True),
               x.info(4.0, []), sig, x.response(6.1, com_of(sig), "ok"),
               x.feedback(6.2, other, "succeeded", True)]
    assert failing(judge(stream, missing), str(stream.address)) == {"TST-013"}


def test_an_unanswered_start_tst_fails_tst_004(stream):
    x = Tst(stream)
    lost = x.start(2.0, leaf("look-at-bearing", new()))
    later = x.signal(5.0, "signal-tst-node", new(), "$pause")
    report = judge(stream, [lost, later, x.response(5.1, com_of(later), "failed", "unknown")])
    assert failing(report, str(stream.address)) == {"TST-004"}


def test_commands_on_an_operators_topic_are_judged_as_the_units_they_concern(stream):
    """14.1: start-tst on op0/tst/command naming /dji0, answered on op0's topics: dji0's
    conversation, in lint and in a certification that follows dji0 alone."""
    op0 = UnitAddress(stream.address.prefix, "ground", "real", "op0")
    x = Tst(stream, operator=op0)
    node = new()
    for units in (None, [stream.address]):
        report = judge(stream, a_leaf_run(x, 2.0, node, root_uuid=new()), units=units)
        assert failing(report, str(stream.address)) == {"TST-004"}
        assert str(op0) not in report.units
        rules = report.units[str(stream.address)].rules
        assert rules["TST-012"].verdict is Verdict.PASS
    # An operator that runs trees itself (it declares 'tst execution') answers for them.
    op = type(stream)(op0, levels=("tst execution",))
    m = Monitor(TIMEOUTS)
    stream.feed(m, stream.alive(20.0) + op.alive(20.0, info=False, sensors=False)
                + a_leaf_run(x, 2.0, new(), root_uuid=new()))
    m.finish()
    report = m.report()
    assert report.units[str(stream.address)].rules["TST-004"].verdict is not Verdict.FAIL
    assert report.units[str(op0)].rules["TST-004"].verdict is Verdict.FAIL


def test_a_start_tst_whose_answer_falls_in_an_outage_is_not_failed(stream):
    """The observer's connection was down while the answer was due; what the
    unit sent then is unknown (the same traffic without the gap fails TST-004, above)."""
    x = Tst(stream)
    lost = x.start(2.0, leaf("look-at-bearing", new()))
    later = x.signal(5.0, "signal-tst-node", new(), "$pause")
    m = Monitor(TIMEOUTS)
    gap = (lost.time + 0.05, lost.time + 2.0)
    m.connection_gap(*gap)
    heard = [msg for msg in stream.alive(20.0) if not gap[0] <= msg.time <= gap[1]]
    stream.feed(m, [*heard, lost, later, x.response(5.1, com_of(later), "failed", "unknown")])
    m.finish()
    r = m.report().units[str(stream.address)].rules["TST-004"]
    assert r.verdict is not Verdict.FAIL and "broker" in r.reason, r

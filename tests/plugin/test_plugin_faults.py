"""Every fault of the reference unit makes its certification fail, naming exactly the rules the
fault breaks (no other rule fails by accident); and each failure's printed rerun line reproduces
its rule: every line, as printed, repeats the run with ``-k RULE`` (and ``--observe`` when the
evidence came late) and selects exactly that rule's test; one rule for each way a rerun selects
what it runs (``RERUN``) is run again against the same faults and fails that rule again, alone.

The matrix runs in virtual time (``--broker virtual``: the reference unit, the suite and the
Monitor on one simulated clock, through the in-memory broker double ``conformance.sim.virtual``),
but for the runs of ``REAL_BROKER``, end to end on Mosquitto: together every kind of
scenario. To keep the matrix short, faults that touch different spec areas run together, at
2 Hz with the matrix profile's short windows; faults of the areas that gate others (heartbeat,
ping, robustness, start-task, signals, reboot, stamps) run alone, but for those that change
only what their own rule judges (JOIN). A combined run must fail
exactly the union of its faults' rules: one that does not fails, naming its faults and the
rules (faults interact: those that legitimately affect each other are kept apart, in ALONE,
SAME_MESSAGES or ALSO, with a comment saying why).
"""

from __future__ import annotations

import re
import shlex
from collections import Counter

import pytest
from certify_helpers import (
    MATRIX,
    RULE_IN_NODEID,
    UNIT,
    Certified,
    Rebooter,
    certify,
    certify_selected,
    certify_sim,
    certify_virtual,
)

from conformance.plugin import NOT_CERTIFIED_EXIT
from conformance.sim import FAULTS

pytestmark = pytest.mark.slow

# Where the suite and the reference unit's fault table disagree on the rules a fault breaks.
# strict: once they agree, the XPASS fails this test and the entry must go. In virtual time,
# as the rest of the matrix.
AWAITING_SCENARIOS: dict[str, str] = {
    # Behaviours of the public agents, misjudged as the checks stand:
    # (heartbeat-rate-gross and start-no-task-uuid-unanswered waited here; both fail exactly
    # their rules now.)
}
# Areas whose faults change what every scenario sees (levels, identity, timing, answers).
# Signal faults too (the scenarios end their tasks with signals), and tst_execution_info ones
# (they declare one more level).
ALONE = {"HB", "EXEC-PING", "EXEC-ROBUST", "EXEC-START", "EXEC-SIG", "REBOOT", "TEI",
         "MSG-005", "MSG-007", "MSG-008", "ERR-008", "ERR-014"}
GROUP_SIZE = 5
# Rules that judge the same messages as another area's: a fault of one and a fault of the
# other would alter the same message (a sensor value, a query or signal answer).
# MSG-008 (a stamp in ms) and MSG-005 (a clock far off) judge the same stamps.
SAME_MESSAGES = {"MSG": "SENS", "ERR-010": "SENS", "ERR-006": "EXEC-QUERY", "MSG-008": "MSG-005",
                 "ERR-013": "EXEC-SIG", "ERR-001": "SI", "ERR-012": "SI"}
# Rules whose faults also change what another area's scenario or check relies on: feedback
# without task-uuid hides when a task ends, so the query scenario has no finished task to ask
# about (ERR-006's evidence); SENS-004 judges the camera sensor on sensor/camera_url, where the
# topic faults that rename that sensor (TOPIC-002/003/004/008) leave nothing to judge.
ALSO = {"EXEC-FB-001": ("EXEC-QUERY",), "SENS-004": ("TOPIC",)}
# What the suite's own traffic adds to a fault's rules (the passive matrix of tests/sim sends
# other commands). (crash-on-malformed's unanswered start-task probes without a task object are
# malformed commands, EXEC-ROBUST-002's alone, no longer also EXEC-START-001: the real agents
# showed the double count.) twin-agent: two agents under one name (HB-011) take turns with agent-uuids seen before, so
# after the reboot scenario the query of a task from before it is judged against the life the
# twin's uuid keeps open: the fault's own ambiguity, shown on its run.
SUITE_ALSO = {"twin-agent": ("EXEC-QUERY-001",)}
# Faults of ALONE areas that only change what their own rule alone judges, and nothing a
# scenario reads: the heartbeat's type (HB-002), an unknown level besides the known ones
# (HB-007), stamps (MSG-005, MSG-008; MSG-007 reads them on retained messages only, and its fault runs
# alone). They join combined groups, one of each area per group.
JOIN = {"heartbeat-type-case", "level-unknown", "stamp-clock-skew", "stamp-milliseconds"}
# Faults that leave the unit without a readable position: the scenarios that start tasks
# place them near it (docs/ARCHITECTURE.md 'Safety') and cannot test without one, whatever their
# area.
ALONE_FAULTS = {"position-deg-e7", "position-as-list"}


# Runs end to end on Mosquitto (the rest run in virtual time): a group holding one of these.
# Together they run every kind of scenario (ping, start, signal, query, resend, robustness,
# reboot, TST, the passive window). Not on amqtt: the embedded broker shares this process (and
# its GIL) with the unit and the suite, and on a loaded 2-core machine its stalls at 2 Hz read
# as silences (HB-010, DEI-002: seen in a full -n 2 run); amqtt runs end to end in
# test_plugin_certify.py, test_plugin_explore.py and the demo.
REAL_BROKER = {
    "pong-missing",  # ping (the gate) and robustness
    "reboot-remembers-history",  # reboot after start (Scenario.needs)
    "query-forgets-finished",  # a combined group: query, resend, TST, passive
    "abort-ignored",  # start and signal
}


def on_mosquitto(faults: list[str]) -> bool:
    """Whether a group runs end to end on Mosquitto (else in virtual time)."""
    return bool(REAL_BROKER & set(faults))


# In virtual time the suite's own overheads take no time, so a run is as short as its waits
# (about 5 s of the unit's time at 2 Hz): a fault whose evidence needs longer is observed so
# long (--observe), as a run on a real broker lasts anyway. agent-uuid-changes: HB-006 fails on
# the second change without a silence (identity.FAST_RESTART_PERIODS), 5 periods (2.5 s) after
# the first.
OBSERVE = {"agent-uuid-changes": "15"}


def areas(rule: str) -> set[str]:
    if rule in ALONE or rule in SAME_MESSAGES:
        own = SAME_MESSAGES.get(rule, rule)
    else:
        m = re.match(r"(EXEC-[A-Z]+|[A-Z]+)-\d+", rule)
        name = m.group(1) if m else rule
        own = SAME_MESSAGES.get(name, name)
    return {own, *ALSO.get(rule, ())}


def groups() -> list[list[str]]:
    """Unit faults, combined when they touch different spec areas (deterministic): those of
    ALONE areas one by one; the others first-fit into groups of GROUP_SIZE, the faults of the
    most crowded areas first (every TST fault opens a group: the fewest runs)."""
    out: list[list[str]] = []
    combinable: list[tuple[str, set[str]]] = []
    for name, fault in sorted(FAULTS.items()):
        if fault.scope != "unit" or name in AWAITING_SCENARIOS or fault.sequence:
            continue  # a sequence fault: no scripted scenario sends its order (exploration)
        mine = {a for r in fault.rules for a in areas(r)}
        if (mine & ALONE and name not in JOIN) or name in ALONE_FAULTS:
            out.append([name])
        else:
            combinable.append((name, mine))
    crowd = Counter(a for _, mine in combinable for a in mine)
    combinable.sort(key=lambda f: (-max(crowd[a] for a in f[1]), -len(f[1]), f[0]))
    combined: list[list[str]] = []
    for name, mine in combinable:
        for group in combined:
            theirs = {a for f in group for r in FAULTS[f].rules for a in areas(r)}
            if len(group) < GROUP_SIZE and not theirs & mine:
                group.append(name)
                break
        else:
            combined.append([name])
    return combined + out


def explain(run: Certified, expected: set[str]) -> str:
    rules = run.unit_rules() if run.report else {}
    lines = []
    for rule in sorted(run.failed ^ expected):
        r = rules.get(rule, {})
        why = r.get("violations", [{}])[0] if r.get("violations") else {}
        lines.append(f"{rule}: {'unexpected failure' if rule in run.failed else 'did not fail'}"
                     f" ({r.get('verdict')}: {r.get('reason')}; {why.get('observed', '')})")
    return "\n".join(lines)



# The rerun lines run again against their faults: one rule for each way a rerun selects what it
# runs (``selection``), from a fault alone and from a combined group. Every other rule's line is
# checked as printed, without a broker: it repeats the run with -k RULE and selects exactly
# that rule's test, so it runs what the representative of its kind ran.
RERUN: dict[str, str] = {  # rule -> the fault whose run reruns it
    "EXEC-PING-001": "pong-missing",  # ping: the gate of the others
    "EXEC-START-002": "start-response-no-task-uuid",
    "EXEC-START-005": "accept-unknown-task",  # refuse
    "EXEC-SIG-005": "signal-unknown-task-ok",
    "EXEC-QUERY-001": "query-forgets-finished",  # in a combined group
    "EXEC-RESEND-002": "resend-unanswered",  # in a combined group
    "TST-008": "tst-root-flag-everywhere",  # the TST level; in a combined group
    "EXEC-ROBUST-001": "crash-on-malformed",  # robustness
    "REBOOT-002": "reboot-remembers-history",  # runs start first (Scenario.needs)
    "SENS-002": "heading-signed",  # passive, the window alone; in a combined group
    "EXEC-FB-002": "feedback-status-typo",  # passive, after start (EVIDENCE)
    # passive, evidence late (a drifting rate shows after more intervals than the passive
    # window holds): the line adds --observe
    "TEI-002": "tst-info-rate-drift",
}
LATE = {"TEI-002"}
"""Representatives whose evidence comes later than the passive window: their line must carry
``--observe`` (else a rerun would end before the violation shows)."""


def selection(rule: str) -> str:
    """What ``-k RULE`` runs: the rule's own scenario (and the scenarios it needs), or the
    passive window, after the scenarios whose traffic is the rule's evidence."""
    from conformance.scenarios import EVIDENCE, RULE_SCENARIO

    if rule in RULE_SCENARIO:
        return f"the {RULE_SCENARIO[rule]} scenario"
    return "the passive window after its evidence" if rule in EVIDENCE else "the passive window"


def test_real_broker_runs_are_kept() -> None:
    """The virtual-time matrix keeps end-to-end runs on Mosquitto, one group each."""
    real = [g for g in groups() if on_mosquitto(g)]
    assert len(real) == len(REAL_BROKER), "each in a group of its own"
    assert all(f in FAULTS for f in OBSERVE)
    assert len(real) < len(groups()) // 4, "most of the matrix runs in virtual time"


def test_the_reruns_cover_every_way_a_rerun_selects_what_it_runs() -> None:
    broken = {r for f in FAULTS.values() if f.scope == "unit" for r in f.rules}
    assert all(rule in FAULTS[f].rules for rule, f in RERUN.items()), "a rule its fault breaks"
    kinds = {selection(r) for r in broken}
    missing = kinds - {selection(r) for r in RERUN}
    assert not missing, f"no rerun runs again for: {sorted(missing)}"
    sizes = {len(g) for g in groups() for f in g if f in RERUN.values()}
    assert 1 in sizes and max(sizes) > 1, "reruns from a fault alone and from a combined group"
    assert LATE <= set(RERUN)


@pytest.mark.parametrize("faults", [pytest.param(g, id="+".join(g)) for g in groups()] + [
    pytest.param([name], id=name, marks=pytest.mark.xfail(strict=True, reason=why,
                                                          raises=AssertionError))
    for name, why in AWAITING_SCENARIOS.items()])
def test_faults_fail_exactly_their_rules(pytester: pytest.Pytester, faults: list[str],
                                         request: pytest.FixtureRequest, prefix: str) -> None:
    unit = f"{prefix}/unit/air/simulation/dji0"
    broker = None
    if on_mosquitto(faults):
        broker = request.getfixturevalue("mosquitto")
        run = certify_sim(pytester, broker, unit, f"--profile={MATRIX}", "--seed", "1",
                          faults=tuple(faults))
    else:
        observe = [o for f in faults if (o := OBSERVE.get(f))]
        run = certify_virtual(pytester, unit, f"--profile={MATRIX}", "--seed", "1",
                              *(["--observe", max(observe)] if observe else []),
                              faults=tuple(faults))
    expected = {r for f in faults for r in FAULTS[f].rules} | {
        r for f in faults for r in SUITE_ALSO.get(f, ())}
    assert run.failed == expected, f"{' + '.join(faults)}:\n{explain(run, expected)}"
    assert run.result.ret == pytest.ExitCode.TESTS_FAILED
    lines = rerun_lines(pytester, run, expected)
    for rule, fault in RERUN.items():
        if fault in faults:
            assert rule not in LATE or "--observe" in lines[rule], lines[rule]
            fails_again(pytester, lines[rule], rule, faults, broker, unit)


def rerun_lines(pytester: pytest.Pytester, run: Certified, rules: set[str]) -> dict[str, str]:
    """Each failure names its rule and how to rerun just that rule: the run's own command
    (its 'repeat this run' line) with -k RULE, and --observe when the evidence came late; that
    command selects exactly the rule's test (collected only: no broker, no unit)."""
    repeat = re.search(r"^repeat this run: (pytest .*)$", run.text, re.M)
    assert repeat, "no 'repeat this run' line"
    lines = {}
    later = (run.report or {}).get("conclusion", {}).get("judged_after_test", [])
    for rule in sorted(rules):
        if rule in later:  # failed on a later scenario's traffic: the whole run reproduces it
            assert re.search(rf"^{re.escape(rule)} .*\n(.*\n)*?\s*rerun\s+"
                             rf"{re.escape(repeat.group(1))}$", run.text, re.M), rule
            lines[rule] = repeat.group(1)
            continue
        found = re.search(rf"^\s*rerun\s+(pytest .* -k {re.escape(rule)})$", run.text, re.M)
        assert found, f"no rerun line for {rule}"
        line = lines[rule] = found.group(1)
        assert re.fullmatch(rf"{re.escape(repeat.group(1))}( --observe \d+)? -k {re.escape(rule)}",
                            line), line
        listed = pytester.inline_run("-p", "no:cacheprovider", "-o", "addopts=",
                                     *shlex.split(line)[1:], "--collect-only")
        (done,) = listed.getcalls("pytest_collection_finish")
        selected = [m.group(1) if (m := RULE_IN_NODEID.search(i.nodeid)) else i.nodeid
                    for i in done.session.items]
        assert selected == [rule], f"{line} selects {selected}"
    return lines


def fails_again(pytester: pytest.Pytester, line: str, rule: str, faults: list[str],
                broker: str | None, unit: str) -> None:
    """The rerun line, run against the same faults, fails the rule again (and judges nothing
    else). In virtual time (``broker`` None) the line itself names the faults."""
    from conformance.sim import SimUnit

    if broker is None:
        again = certify(pytester, *shlex.split(line)[1:])
    else:
        with SimUnit(unit, broker, faults=tuple(faults), rate=2.0, seed=1) as sim:
            again = certify(pytester, *shlex.split(line)[1:], plugins=(Rebooter(sim),))
    assert again.failed == {rule}, f"{line}:\n{explain(again, {rule})}"
    assert again.result.ret == pytest.ExitCode.TESTS_FAILED


@pytest.mark.parametrize("fault", sorted(n for n, f in FAULTS.items() if f.scope == "broker"))
def test_fault_outside_the_unit_address_stops_with_one_error(pytester: pytest.Pytester,
                                                             fault: str) -> None:
    """The unit publishes at another address: certification stops at once (it is not alive
    where it was said to be), and the one error names what is wrong with the topics seen."""
    run = certify(pytester, "--unit", UNIT, "--broker", "embedded", "--sim-rate", "3",
                  f"--sim-fault={fault}", f"--profile={MATRIX}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert run.outcomes == {}
    assert "is not alive" in run.text
    for rule in FAULTS[fault].rules:
        assert rule in run.text, run.text


def test_a_unit_deaf_to_start_task_without_task_uuid_has_its_resend_judged(
        pytester: pytest.Pytester, prefix: str) -> None:
    """Public agents answer no start-task without a task-uuid: the resend scenario
    then asks with one, as the spec's examples do, so their resend handling is judged instead
    of could-not-test, and a unit that runs the resend again still fails EXEC-RESEND-001."""
    deaf = certify_selected(pytester, prefix, "RESEND", "start-no-task-uuid-unanswered")
    rules = deaf.unit_rules()
    assert {r: rules[r]["verdict"] for r in ("EXEC-RESEND-001", "EXEC-RESEND-002")} == {
        "EXEC-RESEND-001": "pass", "EXEC-RESEND-002": "pass"}, deaf.text
    twice = certify_selected(pytester, prefix, "RESEND", "start-no-task-uuid-unanswered",
                             "resend-executes-twice")
    assert "EXEC-RESEND-001" in twice.failed, twice.text


def test_a_unit_deaf_to_start_task_without_task_uuid_has_its_task_followed(
        pytester: pytest.Pytester, prefix: str) -> None:
    """With one task to start (the public L2 agents' case), the start-task without a task-uuid
    goes unanswered (EXEC-START-001's finding, EXEC-START-002 could-not-test); the scenario
    then asks with one, as the spec's examples do, so the task's end and listing (EXEC-START-003,
    DEI-004) are judged instead of 'no message this rule applies to was seen'."""
    one = pytester.path / "one-task.yaml"
    one.write_text(f"extends: {MATRIX}\nname: one-task\ntasks: [move-to]\n")
    run = certify_virtual(pytester, f"{prefix}/unit/air/simulation/dji0", f"--profile={one}",
                          "--seed", "1", "-k", "EXEC-START or DEI-004",
                          faults=("start-no-task-uuid-unanswered",))
    verdicts = {r: v["verdict"] for r, v in run.unit_rules().items()
                if r.startswith("EXEC-START-00") or r == "DEI-004"}
    assert {r: verdicts.get(r) for r in ("EXEC-START-001", "EXEC-START-002", "EXEC-START-003",
                                         "DEI-004")} == {
        "EXEC-START-001": "fail", "EXEC-START-002": "could-not-test",
        "EXEC-START-003": "pass", "DEI-004": "pass"}, run.text[-3000:]


def test_no_tasks_executing_fails_dei_001_and_leaves_dei_004_untested(
        pytester: pytest.Pytester, prefix: str) -> None:
    """The official L2 agents send direct_execution_info without tasks-executing: DEI-001's
    finding; with no list, whether a task is listed or leaves it cannot be told (DEI-004
    could-not-test, never a pass)."""
    run = certify_selected(pytester, prefix, "DEI", "dei-no-tasks-executing")
    rules = run.unit_rules()
    assert rules["DEI-001"]["verdict"] == "fail", run.text
    assert rules["DEI-004"]["verdict"] == "could-not-test", rules["DEI-004"]
    assert "DEI-001" in rules["DEI-004"]["reason"]

"""Every variant switch changes exactly what it names, and nothing else.

Each test drives two reference units' cores in simulated time through one scripted conversation
(the same commands at the same moments, the same random numbers and clock): one plain, one with
the variant. Undoing what the variant names must give back the plain unit's traffic, message
for message. That a variant is conformant (certified, linted clean) is shown over a real broker
by tests/plugin/test_plugin_variants.py.
"""

from __future__ import annotations

import json
import random
import subprocess
import sys
from typing import Any

import orjson
import pytest

from conformance.rules import CATALOGUE
from conformance.sim.unit import UnitCore
from conformance.sim.variants import (
    EDGE,
    RESPAWN_METRES,
    SLOW_PERIODS,
    VARIANTS,
    VariantError,
    check_variants,
)
from conformance.sim.vehicle import GeoPoint, distance
from conformance.topics import UnitAddress

ADDRESS = UnitAddress("h", "air", "simulation", "dji0")
RATE = 2.0
STEP = 0.05
T1, T2 = "5c0ed702-2f6a-46b4-a1a4-ea2e86e04282", "49fb88b8-4d4a-4268-a69a-35e620a1a5f4"
ROOT, LEAF = "fe1fbcee-1cae-4a69-b9f7-83914454a7a7", "ff200942-73a2-401f-83e2-8397d28facf8"
HELD = ("/exec/response", "/exec/feedback", "/tst/response", "/tst/feedback")


def com(i: int) -> str:
    return f"7300d049-176f-4dcb-b0bf-{i:012d}"


def tst_node(name: str, params: dict[str, Any], node_uuid: str,
             children: list[dict[str, Any]] = ()) -> dict[str, Any]:  # type: ignore[assignment]
    """A node as every example of section 11 writes it."""
    return {"name": name, "params": params, "children": list(children),
            "common_params": {"execunit": "/dji0", "node-uuid": node_uuid}}


# The script: (time, topic, command), each command as the spec's examples write it.
SCRIPT: list[tuple[float, str, dict[str, Any] | bytes]] = [
    (1.0, "exec", {"com-uuid": com(1), "command": "ping", "sender": "commander"}),
    (1.2, "exec", {"com-uuid": com(2), "command": "start-task", "execution-unit": "dji0",
                   "sender": "commander", "task": {"name": "look-at-bearing",
                                                   "params": {"bearing": 45.0}},
                   "task-uuid": T1}),
    (2.0, "exec", {"com-uuid": com(3), "command": "signal-task", "sender": "commander",
                   "signal": "$enough", "task-uuid": T1}),
    (2.6, "exec", {"com-uuid": com(4), "command": "query-status", "sender": "commander",
                   "task-uuid": T1}),
    (2.8, "exec", {"com-uuid": com(5), "command": "query-status", "sender": "commander",
                   "task-uuid": T2}),
    (3.0, "exec", b'{"com-uuid": "' + com(6).encode() + b'", "command": "start-ta'),
    (3.2, "tst", {"com-uuid": com(7), "command": "start-tst", "sender": "commander",
                  "tst": tst_node("seq", {}, ROOT, [tst_node("take-off", {}, LEAF)])}),
]


class Run:
    """A unit's core driven in simulated time; ``sent`` is (time, subtopic, payload bytes)."""

    def __init__(self, *variants: str, script: list = SCRIPT, seconds: float = 6.0) -> None:
        self.now = 0.0
        self.sent: list[tuple[float, str, bytes]] = []
        self.retained: set[str] = set()
        self.unit = UnitCore(ADDRESS, self._emit, variants=variants, rate=RATE,
                             rng=random.Random(1), clock=lambda: 1.7e9 + self.now,
                             task_seconds=0.5, tst_execution=True)
        self.unit.start(0.0)
        todo = sorted(script, key=lambda s: s[0])
        while self.now < seconds:
            self.now = round(self.now + STEP, 6)
            while todo and todo[0][0] <= self.now:
                _, where, body = todo.pop(0)
                payload = body if isinstance(body, bytes) else orjson.dumps(body)
                if where == "reboot":  # as --reboot-cmd would (SimUnit.reboot)
                    self.unit.request_reboot()
                    self.unit.due = self.now
                elif where == "exec":
                    self.unit.command(payload, self.now)
                else:
                    self.unit.tst_command(payload, self.now, f"{ADDRESS.base}/tst/command")
                if self.unit.busy():  # as the runtime reschedules a unit after a command
                    self.unit.due = min(self.unit.due, self.now)
            if self.now >= self.unit.due:
                self.unit.run(self.now)

    def _emit(self, topic: str, payload: bytes, retain: bool) -> None:
        self.sent.append((self.now, topic.removeprefix(ADDRESS.base), payload))
        if retain:
            self.retained.add(topic.removeprefix(ADDRESS.base))

    def messages(self, *suffixes: str) -> list[tuple[str, Any]]:
        return [(t, orjson.loads(p)) for _, t, p in self.sent
                if not suffixes or t.endswith(suffixes)]

    def answer(self, com_uuid: str) -> dict[str, Any]:
        return next(m for t, m in self.messages("/exec/response", "/tst/response")
                    if m.get("response-to") == com_uuid)


@pytest.fixture(scope="module")
def plain() -> Run:
    return Run()


def without(msg: Any, *keys: str) -> Any:
    return {k: v for k, v in msg.items() if k not in keys} if isinstance(msg, dict) else msg


# --- the catalogue of variants ------------------------------------------------------------------

def test_every_variant_cites_the_spec_and_warns_only_on_decided_rules() -> None:
    """A variant does what the spec allows: it may warn only on a decided rule (an erratum
    reading, or a decision where the spec is silent: rules.toml), never on the spec's words."""
    for v in VARIANTS.values():
        assert v.section and v.description, v.name
        for rule in v.warns:
            assert CATALOGUE[rule].is_decided, (v.name, rule)


def test_unknown_or_conflicting_variants_are_refused_naming_close_ones() -> None:
    with pytest.raises(VariantError, match="did you mean strict"):
        check_variants(["strikt"])
    with pytest.raises(VariantError, match="terse and verbose"):
        check_variants(["terse", "verbose"])
    assert check_variants("slow") == {"slow"}


def test_list_variants_prints_every_variant() -> None:
    out = subprocess.run([sys.executable, "-m", "conformance.cli", "sim", "--list-variants",
                          "--json"], capture_output=True, text=True, check=True).stdout
    assert {v["name"]: v["warns"] for v in json.loads(out)["variants"]} == {
        v.name: list(v.warns) for v in VARIANTS.values()}
    text = subprocess.run([sys.executable, "-m", "conformance.cli", "sim", "--list-variants"],
                          capture_output=True, text=True, check=True).stdout
    assert all(name in text for name in VARIANTS)


def test_the_plain_script_is_answered_as_the_spec_describes(plain: Run) -> None:
    assert plain.answer(com(1))["response"] == "pong"
    assert plain.answer(com(2))["response"] == "running"
    assert plain.answer(com(4))["response"] == "finished"
    assert plain.answer(com(5))["response"] == "unknown"
    assert plain.answer(com(6))["response"] == "failed"
    assert plain.answer(com(7))["response"] == "started"
    assert [m["status"] for _, m in plain.messages("/tst/feedback")
            if m["node-uuid"] == ROOT][-1] == "succeeded"


# --- one test per variant: what it changes, and only that ----------------------------------------

def test_key_order_reverses_every_object_and_changes_nothing_else(plain: Run) -> None:
    run = Run("key-order")
    assert [(t, orjson.loads(p)) for _, t, p in run.sent] == plain.messages()
    for _, _, payload in run.sent:
        body = orjson.loads(payload)
        if isinstance(body, dict):
            assert list(body) == sorted(body, reverse=True), payload
            assert payload != orjson.dumps(body, option=orjson.OPT_SORT_KEYS)


def test_success_vocabulary_changes_only_the_query_of_a_finished_task(plain: Run) -> None:
    run = Run("success-vocabulary")
    assert run.answer(com(4))["response"] == "success"
    changed = [(a, b) for a, b in zip(plain.messages(), run.messages(), strict=True) if a != b]
    assert [b["response-to"] for _, (_, b) in changed] == [com(4)]


def test_level_spelling_changes_only_the_levels_of_the_heartbeat(plain: Run) -> None:
    run = Run("level-spelling")
    for (t, a), (_, b) in zip(plain.messages(), run.messages(), strict=True):
        if t == "/heartbeat":
            assert b["levels"] == ["sensor", "direct_execution", "tst execution"]
            assert without(a, "levels") == without(b, "levels")
        else:
            assert a == b, t


def test_geopoint_type_changes_only_the_tag_of_the_position(plain: Run) -> None:
    run = Run("geopoint-type")
    for (t, a), (_, b) in zip(plain.messages(), run.messages(), strict=True):
        if t == "/sensor/position":
            assert b.pop("type") == a.pop("rostype") == "GeoPoint"
        assert a == b, t


def test_verbose_adds_its_field_and_fail_reason_to_every_response(plain: Run) -> None:
    run = Run("verbose")
    for (t, a), (_, b) in zip(plain.messages(), run.messages(), strict=True):
        if isinstance(b, dict):
            assert b.pop("x-software")["variant"] == "verbose"
            if t == "/exec/response":
                assert "fail-reason" in b and "task-uuid" in b
                for key in ("fail-reason", "task-uuid"):
                    if key not in a:
                        assert b.pop(key) == "", key
                assert b["response-to"] not in (com(1), com(6)) or "task-uuid" not in a
        assert a == b, t


def test_terse_leaves_out_optional_fields_and_the_optional_sensor(plain: Run) -> None:
    run = Run("terse")
    assert not [t for _, t, _ in run.sent if "camera_url" in t]
    ours = [(t, m) for t, m in plain.messages() if "camera_url" not in t]
    for (t, a), (_, b) in zip(ours, run.messages(), strict=True):
        if t == "/sensor_info":
            assert b["sensor-data-provided"] == ["position", "heading", "course", "speed"]
            a = without(a, "sensor-data-provided")
            b = without(b, "sensor-data-provided")
        elif t == "/exec/response":
            dropped = set(a) - set(b)
            assert dropped <= {"fail-reason", "task-uuid"}, t
            assert "fail-reason" in b or b["response"] != "failed"
            assert "task-uuid" in b or b["response-to"] != com(2)  # start-task keeps it
            a = without(a, *dropped)
        elif t == "/tst/response":
            assert "fail-reason" not in b
            a = without(a, "fail-reason")
        elif t == "/tst/feedback":
            a = without(a, "root-flag", "fail-reason")
        elif t == "/tst_execution_info":
            a = without(a, "nodes-executing")
        assert a == b, t
    assert len(run.sent) == len(ours)


def test_slow_holds_back_exactly_the_answers_and_feedback_and_keeps_their_order(
        plain: Run) -> None:
    run = Run("slow", seconds=8.0)
    delay = SLOW_PERIODS / RATE
    held = [(w, t, orjson.loads(p)) for w, t, p in run.sent if t.endswith(HELD)]
    before = [(w, t, orjson.loads(p)) for w, t, p in plain.sent if t.endswith(HELD)]
    assert [(t, m) for _, t, m in held] == [(t, m) for _, t, m in before]
    for (late, _, _), (early, t, _) in zip(held, before, strict=True):
        assert delay - 1e-6 <= late - early <= delay + STEP + 1e-6, t
    rest = [(t, orjson.loads(p)) for w, t, p in run.sent if not t.endswith(HELD) and w <= 6]
    assert rest == [(t, m) for t, m in plain.messages() if not t.endswith(HELD)]


def test_sensor_rate_edge_slows_sensor_info_and_sensors_inside_the_tolerance(
        plain: Run) -> None:
    run = Run("sensor-rate-edge", script=[], seconds=30.0)
    base = Run(script=[], seconds=30.0)

    def count(r: Run, sub: str) -> int:
        return sum(t == sub for _, t, _ in r.sent)

    for sub in ("/heartbeat", "/direct_execution_info", "/tst_execution_info"):
        assert count(run, sub) == count(base, sub)
    for sub in ("/sensor_info", "/sensor/position", "/sensor/speed"):
        ratio = count(run, sub) / count(base, sub)
        assert abs(ratio - (1 - EDGE)) < 0.04, (sub, ratio)  # slower, not past 20 %
    assert run.messages("/sensor_info") and all(
        without(a, "stamp") == without(b, "stamp")
        for (_, a), (_, b) in zip(run.messages("/sensor_info"), base.messages("/sensor_info"),
                                  strict=False))


STRICT_REFUSED: dict[str, dict[str, Any]] = {
    "an unknown field": {"command": "ping", "sender": "commander", "priority": 1},
    "no sender": {"command": "ping"},
    "no execution-unit": {"command": "start-task", "sender": "commander", "task-uuid": T2,
                          "task": {"name": "look-at-bearing", "params": {"bearing": 1.0}}},
    "another execution-unit": {"command": "start-task", "sender": "commander",
                               "execution-unit": "dji9", "task-uuid": T2,
                               "task": {"name": "look-at-bearing",
                                        "params": {"bearing": 1.0}}},
    "task without params": {"command": "start-task", "sender": "commander",
                            "execution-unit": "dji0", "task-uuid": T2,
                            "task": {"name": "take-off"}},
    "query-status without sender": {"command": "query-status", "task-uuid": T1},
}


def test_strict_answers_the_examples_as_the_plain_unit_does(plain: Run) -> None:
    run = Run("strict")
    assert run.messages() == plain.messages()


@pytest.mark.parametrize("what", sorted(STRICT_REFUSED))
def test_strict_refuses_a_command_unlike_the_examples(what: str) -> None:
    body = {"com-uuid": com(90), **STRICT_REFUSED[what]}
    script = [(1.0, "exec", body)]
    lenient, strict = Run(script=script, seconds=1.5), Run("strict", script=script, seconds=1.5)
    assert lenient.answer(com(90))["response"] != "failed"
    refused = strict.answer(com(90))
    assert refused["response"] == "failed" and refused["fail-reason"], refused
    assert refused.get("task-uuid") == body.get("task-uuid")  # EXEC-START-002: as sent


def test_strict_refuses_a_tree_whose_inner_node_lacks_common_params() -> None:
    """Section 11's examples write common_params (execunit, node-uuid) on every node; a tree
    with them on the root only is refused (the suite must send every node complete)."""
    tree = tst_node("seq", {}, ROOT, [{"name": "take-off", "params": {}, "children": []}])
    script = [(1.0, "tst", {"com-uuid": com(91), "command": "start-tst",
                            "sender": "commander", "tst": tree})]
    assert Run(script=script, seconds=1.5).answer(com(91))["response"] == "started"
    refused = Run("strict", script=script, seconds=1.5).answer(com(91))
    assert refused["response"] == "failed"
    assert "children[0]" in refused["fail-reason"] and "common_params" in refused["fail-reason"]


def test_starting_feedback_adds_one_starting_before_running(plain: Run) -> None:
    run = Run("starting-feedback")
    extra = [m for t, m in run.messages("/exec/feedback") if m["status"] == "starting"]
    assert [m["task-uuid"] for m in extra] == [T1]
    statuses = [m["status"] for t, m in run.messages("/exec/feedback") if m["task-uuid"] == T1]
    assert statuses[:2] == ["starting", "running"]
    rest = [(t, m) for t, m in run.messages() if m not in extra]
    assert [(t, without(m, "com-uuid")) for t, m in rest] == [
        (t, without(m, "com-uuid")) for t, m in plain.messages()]


def test_feedback_first_sends_the_feedback_a_command_causes_before_its_answer(
        plain: Run) -> None:
    run = Run("feedback-first")
    order = [(t, m.get("response-to") or m.get("status")) for t, m in run.messages(
        "/exec/response", "/exec/feedback")]
    assert order.index(("/exec/feedback", "running")) < order.index(("/exec/response", com(2)))
    assert order.index(("/exec/feedback", "finished")) < order.index(("/exec/response", com(3)))
    tst = [(t, m.get("response-to") or m.get("status")) for t, m in run.messages(
        "/tst/response", "/tst/feedback")]
    assert tst.index(("/tst/feedback", "active")) < tst.index(("/tst/response", com(7)))
    def same(r: Run) -> list[str]:  # com-uuids are drawn in the order messages go out
        return sorted(repr((t, without(m, "com-uuid"))) for t, m in r.messages())

    assert same(run) == same(plain)


def test_announce_nodes_reports_every_node_not_active_before_the_root_is_active(
        plain: Run) -> None:
    run = Run("announce-nodes")
    statuses = [(m["node-uuid"], m["status"]) for _, m in run.messages("/tst/feedback")]
    assert statuses[:3] == [(ROOT, "not-active"), (LEAF, "not-active"), (ROOT, "active")]
    rest = [(t, m) for t, m in run.messages()
            if not (t == "/tst/feedback" and m["status"] == "not-active")]

    def same(msgs: list) -> list[str]:  # com-uuids are drawn in the order messages go out
        return sorted(repr((t, without(m, "com-uuid"))) for t, m in msgs)

    assert same(rest) == same(plain.messages())


def test_periodic_feedback_repeats_a_live_tasks_status_with_each_heartbeat() -> None:
    script = [(1.0, "exec", {"com-uuid": com(80), "command": "start-task",
                             "sender": "commander", "task-uuid": T1,
                             "task": {"name": "look-at-bearing", "params": {"bearing": 1.0}}}),
              (4.0, "exec", {"com-uuid": com(81), "command": "signal-task",
                             "sender": "commander", "signal": "$enough", "task-uuid": T1})]
    run, plain = Run("periodic-feedback", script=script), Run(script=script)
    beats = [t for t, sub, _ in run.sent if sub == "/heartbeat" and 1.0 <= t < 4.0]
    statuses = [m["status"] for _, m in run.messages("/exec/feedback")]
    assert len(beats) >= 2
    assert statuses == ["running"] * (1 + len(beats)) + ["finished"]
    assert [m["status"] for _, m in plain.messages("/exec/feedback")] == ["running", "finished"]

    def others(r: Run) -> list[str]:  # com-uuids are drawn in the order messages go out
        return sorted(repr((t, without(m, "com-uuid"))) for t, m in r.messages()
                      if t != "/exec/feedback")

    assert others(run) == others(plain)


def test_silent_start_leaves_out_only_the_running_feedback_of_a_start(plain: Run) -> None:
    run = Run("silent-start")
    assert [(m["task-uuid"], m["status"]) for _, m in run.messages("/exec/feedback")] == [
        (T1, "finished")]
    assert run.answer(com(2))["response"] == "running"
    dropped = [m for t, m in plain.messages("/exec/feedback") if m["status"] == "running"]
    assert [m["task-uuid"] for m in dropped] == [T1]

    def same(msgs: list) -> list[str]:  # com-uuids are drawn in the order messages go out
        return sorted(repr((t, without(m, "com-uuid"))) for t, m in msgs)

    assert same(run.messages()) == same([(t, m) for t, m in plain.messages()
                                         if not (t == "/exec/feedback" and m in dropped)])


def test_info_rates_halves_the_info_messages_and_declares_it(plain: Run) -> None:
    run = Run("info-rates", script=[], seconds=20.0)
    base = Run(script=[], seconds=20.0)
    for sub in ("/sensor_info", "/direct_execution_info", "/tst_execution_info"):
        ours, theirs = run.messages(sub), base.messages(sub)
        assert abs(len(ours) / len(theirs) - 0.5) < 0.05, sub
        assert {m["rate"] for _, m in ours} == {RATE / 2}
    for sub in ("/heartbeat", "/sensor/position"):
        assert run.messages(sub) == base.messages(sub)


def test_pretty_json_changes_only_the_layout(plain: Run) -> None:
    run = Run("pretty-json")
    assert [(t, orjson.loads(p)) for _, t, p in run.sent] == plain.messages()
    assert all(b"\n  " in p for _, t, p in run.sent if t.endswith(("/heartbeat", "/exec/response")))


def test_integer_numbers_writes_whole_numbers_without_a_fraction(plain: Run) -> None:
    run = Run("integer-numbers")
    assert [(t, orjson.loads(p)) for _, t, p in run.sent] == plain.messages()  # 2 == 2.0
    heartbeat = next(p for _, t, p in run.sent if t == "/heartbeat")
    assert b'"rate":2,' in heartbeat
    assert next(p for _, t, p in run.sent if t == "/sensor/heading") == b"270"


def test_success_vocabulary_answers_a_paused_task_running_and_an_aborted_one_failed() -> None:
    script = [
        (1.0, "exec", {"com-uuid": com(80), "command": "start-task", "execution-unit": "dji0",
                       "sender": "commander", "task-uuid": T1,
                       "task": {"name": "look-at-bearing", "params": {"bearing": 1.0}}}),
        (1.5, "exec", {"com-uuid": com(81), "command": "signal-task", "sender": "commander",
                       "signal": "$pause", "task-uuid": T1}),
        (1.8, "exec", {"com-uuid": com(82), "command": "query-status", "sender": "commander",
                       "task-uuid": T1}),
        (2.0, "exec", {"com-uuid": com(83), "command": "signal-task", "sender": "commander",
                       "signal": "$abort", "task-uuid": T1}),
        (2.3, "exec", {"com-uuid": com(84), "command": "query-status", "sender": "commander",
                       "task-uuid": T1}),
    ]
    plain, words = Run(script=script, seconds=3.0), Run("success-vocabulary", script=script,
                                                        seconds=3.0)
    assert [plain.answer(com(i))["response"] for i in (82, 84)] == ["paused", "aborted"]
    assert [words.answer(com(i))["response"] for i in (82, 84)] == ["running", "failed"]


def test_strict_refuses_a_unit_not_named_slash_name() -> None:
    tree = tst_node("take-off", {}, ROOT)
    tree["common_params"]["execunit"] = "dji0"
    script = [(1.0, "tst", {"com-uuid": com(92), "command": "start-tst", "sender": "commander",
                            "tst": tree}),
              (1.1, "tst", {"com-uuid": com(93), "command": "signal-unit", "sender": "commander",
                            "signal": "$abort", "unit": "dji0"})]
    lenient, strict = Run(script=script, seconds=1.5), Run("strict", script=script, seconds=1.5)
    assert [lenient.answer(com(i))["response"] for i in (92, 93)] == ["started", "ok"]
    assert [strict.answer(com(i))["response"] for i in (92, 93)] == ["failed", "failed"]


def test_retained_info_retains_the_info_messages_only(plain: Run) -> None:
    run = Run("retained-info")
    assert plain.retained == set()
    assert run.retained == {"/sensor_info", "/direct_execution_info", "/tst_execution_info"}
    assert run.messages() == plain.messages()


@pytest.mark.parametrize("profile,rate", [
    ("default", 1.0), ("reference", 1.0), ("strict", 1.0),
    ("tests/plugin/profiles/fast.yaml", 3.0), ("tests/plugin/profiles/matrix.yaml", 2.0),
    ("tests/plugin/profiles/stall.yaml", 2.0), ("tests/plugin/profiles/variants.yaml", 2.0)])
def test_slow_stays_well_inside_every_profiles_deadlines(profile: str, rate: float) -> None:
    """Variant slow is slow, not late: its delay at the rate each profile is used with is at
    most half the profile's response_timeout (the margin is for a loaded machine's jitter),
    and far inside its feedback_timeout."""
    from pathlib import Path

    from conformance.profile import load

    root = Path(__file__).resolve().parents[2]
    p = load(root / profile if profile.endswith(".yaml") else profile)
    delay = SLOW_PERIODS / rate
    assert delay <= 0.5 * p.response_timeout and delay <= 0.2 * p.feedback_timeout


def test_rate_edge_speeds_the_heartbeat_and_execution_info_inside_the_tolerance() -> None:
    run = Run("rate-edge", script=[], seconds=30.0)
    base = Run(script=[], seconds=30.0)

    def count(r: Run, sub: str) -> int:
        return sum(t == sub for _, t, _ in r.sent)

    for sub in ("/heartbeat", "/direct_execution_info", "/tst_execution_info"):
        ratio = count(run, sub) / count(base, sub)
        assert abs(ratio - (1 + EDGE)) < 0.04, (sub, ratio)  # faster, not past 20 %
    for sub in ("/sensor_info", "/sensor/position"):
        assert count(run, sub) == count(base, sub)


# --- behaviours of the public agents certified live (docs/FIELD-NOTES.md)
# -------------------------------

def test_silent_unknown_command_leaves_only_the_unknown_command_unanswered(plain: Run) -> None:
    unknown = (5.5, "exec", {"com-uuid": com(8), "command": "waraps-conformance-no-such",
                             "sender": "commander"})
    base, run = Run(script=[*SCRIPT, unknown]), Run("silent-unknown-command",
                                                    script=[*SCRIPT, unknown])
    assert base.answer(com(8))["response"] == "failed"
    assert all(m.get("response-to") != com(8) for _, m in run.messages("/exec/response"))
    # the malformed command (com 6) and the four commands are answered as before
    assert run.answer(com(6))["response"] == "failed"
    kept = [(t, without(m, "com-uuid")) for t, m in base.messages()
            if not (isinstance(m, dict) and m.get("response-to") == com(8))]
    assert [(t, without(m, "com-uuid")) for t, m in run.messages()] == kept


def test_respawn_moves_only_the_position_of_the_life_after_a_reboot() -> None:
    script = [(1.0, "reboot", b"")]
    base, run = Run(script=script, seconds=5.0), Run("respawn", script=script, seconds=5.0)
    uuids = {m["agent-uuid"] for _, m in run.messages("/heartbeat")}
    assert len(uuids) == 2 and uuids == {m["agent-uuid"] for _, m in base.messages("/heartbeat")}

    def positions(r: Run) -> list[GeoPoint]:
        return [GeoPoint(m["latitude"], m["longitude"], m["altitude"])
                for _, m in r.messages("/sensor/position")]

    before, after = positions(run)[0], positions(run)[-1]
    assert positions(base)[0] == before and positions(base)[-1] == before  # it stands still
    assert abs(distance(before, after) - RESPAWN_METRES) < 1.0
    assert [m for t, m in run.messages() if t != "/sensor/position"] == [
        m for t, m in base.messages() if t != "/sensor/position"]


def test_signed_heading_changes_only_headings_past_180(plain: Run) -> None:
    run = Run("signed-heading")
    headings = [(m, p) for (t, m), (_, p) in zip(run.messages(), plain.messages(), strict=True)
                if t == "/sensor/heading"]
    assert headings and all(-180.0 < m <= 180.0 for m, _ in headings)
    assert all(m == (p - 360.0 if p > 180.0 else p) for m, p in headings)
    assert any(m < 0 for m, _ in headings)  # it faces west at start: 270 reads -90
    assert [m for t, m in run.messages() if t != "/sensor/heading"] == [
        m for t, m in plain.messages() if t != "/sensor/heading"]


def test_own_task_adds_go_home_to_tasks_available_and_needs_its_speed(plain: Run) -> None:
    """5.3: a task beyond section 9; started without 'speed' it is refused with a reason
    (the public agents raise KeyError 'speed' instead), with one it runs."""
    script = [(0.6, "exec", {"com-uuid": com(1), "command": "start-task", "sender": "c",
                             "execution-unit": "dji0", "task-uuid": T1,
                             "task": {"name": "go-home", "params": {}}}),
              (0.8, "exec", {"com-uuid": com(2), "command": "start-task", "sender": "c",
                             "execution-unit": "dji0", "task-uuid": T2,
                             "task": {"name": "go-home", "params": {"speed": 3.0}}})]
    own, bare = Run("own-task", script=script, seconds=2.0), Run(script=script, seconds=2.0)

    def listed(run: Run) -> list[str]:
        info = [m for _, m in run.messages("/direct_execution_info")][-1]
        return [t["name"] for t in info["tasks-available"]]
    assert set(listed(own)) - set(listed(bare)) == {"go-home"}
    assert set(listed(bare)) <= set(listed(own))
    refused = own.answer(com(1))
    assert refused["response"] == "failed" and "speed" in refused["fail-reason"]
    assert own.answer(com(2))["response"] == "running"
    assert bare.answer(com(2))["response"] == "failed"  # the plain unit has no go-home


def test_signal_running_accepts_signals_in_12_1s_word_and_changes_nothing_else(
        plain: Run) -> None:
    run = Run("signal-running")
    assert plain.answer(com(3))["response"] == "ok"
    assert run.answer(com(3)) == {**plain.answer(com(3)), "response": "running",
                                  "com-uuid": run.answer(com(3))["com-uuid"]}
    refused = Run("signal-running", script=SCRIPT + [
        (4.0, "exec", {"com-uuid": com(90), "command": "signal-task", "sender": "commander",
                       "signal": "$abort", "task-uuid": T1})])
    assert refused.answer(com(90))["response"] == "failed"  # ended: refused as before

    def same(r: Run) -> list[str]:
        return sorted(repr((t, without(m, "com-uuid", "response"))) for t, m in r.messages())

    assert same(run) == same(plain)


def test_slow_answers_holds_only_the_answers_one_to_three_seconds_in_order(
        plain: Run) -> None:
    from conformance.sim.variants import SLOW_ANSWERS

    run = Run("slow-answers")
    sent_at = {body["com-uuid"]: t for t, _, body in SCRIPT if isinstance(body, dict)}
    answers = [(t, orjson.loads(p)) for t, sub, p in run.sent if sub.endswith("/response")]
    low, high = SLOW_ANSWERS
    for t, m in answers:
        if m["response-to"] in sent_at:
            assert low - STEP <= t - sent_at[m["response-to"]] <= high + STEP, (t, m)
    assert [t for t, _ in answers] == sorted(t for t, _ in answers)
    assert [m["response-to"] for _, m in answers] == [
        m["response-to"] for _, m in plain.messages("/exec/response", "/tst/response")]

    def feedback(r: Run) -> list[tuple[float, str, Any]]:  # not held (a step of the unit's)
        return [(t, sub, without(orjson.loads(p), "com-uuid")) for t, sub, p in r.sent
                if sub.endswith("/feedback")]

    assert [f[1:] for f in feedback(run)] == [f[1:] for f in feedback(plain)]
    assert all(abs(a[0] - b[0]) <= STEP + 1e-9 for a, b in zip(feedback(run), feedback(plain),
                                                            strict=True))

    def same(r: Run) -> list[str]:
        return sorted(repr((t, without(m, "com-uuid"))) for t, m in r.messages())

    assert same(run) == same(plain)


def test_two_signals_lists_and_takes_only_abort_and_enough_for_look_at_tasks(
        plain: Run) -> None:
    from conformance.sim.variants import TWO_SIGNALS

    script = SCRIPT[:2] + [(1.5, "exec", {"com-uuid": com(91), "command": "signal-task",
                                          "sender": "commander", "signal": "$pause",
                                          "task-uuid": T1})] + SCRIPT[2:]
    run, before = Run("two-signals", script=script), Run(script=script)
    (_, info), *_ = run.messages("/direct_execution_info")
    (_, usual), *_ = before.messages("/direct_execution_info")
    lists = {t["name"]: t["signals"] for t in info["tasks-available"]}
    assert {n for n, s in lists.items() if tuple(s) == tuple(sorted(TWO_SIGNALS))} == {
        n for n in lists if n.startswith("look-at-")} != set()
    assert {n: s for n, s in lists.items() if not n.startswith("look-at-")} == {
        t["name"]: t["signals"] for t in usual["tasks-available"]
        if not t["name"].startswith("look-at-")}
    assert before.answer(com(91))["response"] == "ok"
    refusal = run.answer(com(91))
    assert refusal["response"] == "failed" and "$pause" in refusal["fail-reason"]
    # the rest of the script as before: $enough ends the look-at task, 'finished'
    assert run.answer(com(3))["response"] == "ok"
    assert [m["status"] for _, m in run.messages("/exec/feedback")] == ["running", "finished"]


def test_real_speed_keeps_a_short_move_running_where_the_plain_unit_arrives() -> None:
    """A move-to 100 m away: the plain unit (time compressed) arrives within seconds, the
    real-speed unit is still moving, and so still lists it, well past them; then $enough
    ends both alike."""
    here = GeoPoint(58.3945, 15.5645, 0.0)
    there = {"latitude": 58.3954, "longitude": 15.5645, "altitude": 0.0, "rostype": "GeoPoint"}
    assert 90 < distance(here, GeoPoint(58.3954, 15.5645, 0.0)) < 110
    script = [(1.0, "exec", {"com-uuid": com(90), "command": "start-task",
                             "sender": "commander", "task-uuid": T1,
                             "task": {"name": "move-to", "params": {"waypoint": there}}}),
              (11.0, "exec", {"com-uuid": com(91), "command": "signal-task",
                              "sender": "commander", "signal": "$enough", "task-uuid": T1})]

    def ends(r: Run) -> list[tuple[float, str]]:
        return [(t, json.loads(p)["status"]) for t, sub, p in r.sent if sub == "/exec/feedback"]

    plain, real = Run(script=script, seconds=12.0), Run("real-speed", script=script, seconds=12.0)
    assert [s for _, s in ends(plain)] == ["running", "finished"] and ends(plain)[1][0] < 11.0
    assert [s for _, s in ends(real)] == ["running", "finished"] and ends(real)[1][0] >= 11.0

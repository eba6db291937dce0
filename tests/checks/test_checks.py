"""Every stateful passive check: a passing stream and the failing stream of its fault."""

from __future__ import annotations

import uuid

import orjson
import pytest

from conformance.checks import Monitor, covered_rules
from conformance.profile import Profile
from conformance.violation import Verdict

STRICT = Profile(strict=True)
# Rate tests that show a check finding past the profile's tolerance or over a single long
# interval use STRICT: those bounds are the suite's (decided conditions), warnings by default.
"""HB-008 and TEI-002 are decided rules (rules.toml): they fail only in a strict run."""


def verdict(m: Monitor, stream, rule: str, finish: bool = True):
    if finish:
        m.finish()
    return m.report().units[str(stream.address)].rules[rule]


STATEFUL = covered_rules() - {"ERR-014"}  # the validator's; a stateful check only withdraws it
C1, C2 = str(uuid.uuid4()), str(uuid.uuid4())


def stateful(found) -> list[str]:
    """The rules of the stateful checks among ``found`` (the validator's own rules, which grow
    with the schemas, are tested with the validator)."""
    return [v.rule for v in found if v.rule in STATEFUL]


def rules_found(found) -> set[str]:
    return set(stateful(found))


# -- rates: HB-003, SI-002, DEI-002, TEI-002 -------------------------------------------------

def test_rate_passes_at_declared_rate_with_jitter(stream):
    m = Monitor()
    msgs = [stream.heartbeat(i + (0.03 if i % 2 else -0.03)) for i in range(12)]
    stream.feed(m, msgs)
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.PASS, r
    stat = m.report().units[str(stream.address)].rates[0]
    assert stat.intervals == 11 and stat.verdict is Verdict.PASS
    assert stat.min_interval == pytest.approx(0.94) and stat.max_interval == pytest.approx(1.06)


def test_rate_fails_when_slower_than_declared(stream):
    """Off by 60 %: past the profile's tolerance (a decided condition: warns, fails under
    strict); off by 3x or more: the declared rate is not the rate (the rule's words: fails)."""
    m = Monitor()
    stream.feed(m, [stream.heartbeat(i * 1.6) for i in range(12)])  # declares 1 Hz, sends 0.625
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.WARN and "interop risk" in r.reason
    assert r.violations[0].condition == "tolerance"
    assert "0.63 Hz over 11 intervals" in r.violations[0].observed
    assert "1.00 Hz +-20%" in r.violations[0].expected
    strict = Monitor(STRICT)
    stream.feed(strict, [stream.heartbeat(i * 1.6) for i in range(12)])
    assert verdict(strict, stream, "HB-003").verdict is Verdict.FAIL
    gross = Monitor()
    stream.feed(gross, [stream.heartbeat(i * 4.0) for i in range(12)])  # a quarter of 1 Hz
    r = verdict(gross, stream, "HB-003")
    assert r.verdict is Verdict.FAIL and r.violations[0].condition == ""


def test_rate_fails_on_a_single_long_gap(stream):
    """One interval of 2.2 periods with the mean in tolerance: the suite's bound on a single
    interval (decided: warns; fails under strict)."""
    times = [0, 1, 2, 3, 4, 6.2, 7, 8, 9, 10, 11, 12]  # one gap of 2.2 periods
    for profile, expected in ((Profile(), Verdict.WARN), (STRICT, Verdict.FAIL)):
        m = Monitor(profile)
        stream.feed(m, [stream.heartbeat(t) for t in times])
        r = verdict(m, stream, "HB-003")
        assert r.verdict is expected
        assert any("2.200 s" in v.observed and v.condition == "interval" for v in r.violations)


def test_a_rate_is_judged_live_over_its_latest_intervals_and_finally_over_the_whole(stream):
    """The live view turns red once min_intervals (10) clean intervals are off, a
    gross mismatch after 2 or 3, and clears when the rate recovers; the rule is judged over the
    whole observation at the end (a rate that recovered may pass)."""
    m = Monitor()
    unit = stream.address
    slow = [stream.heartbeat(i * 1.35) for i in range(10)]  # 9 intervals at 0.74 Hz
    stream.feed(m, slow)
    assert m.live_findings(unit) == []  # 9 intervals: not enough for a fine mismatch
    stream.feed(m, [stream.heartbeat(10 * 1.35)])
    (live,) = m.live_findings(unit)
    assert live.rule == "HB-003" and "0.74 Hz over the latest 10 intervals" in live.observed
    assert "live" in live.detail
    t = 10 * 1.35
    stream.feed(m, [stream.heartbeat(t + i + 1) for i in range(30)])  # back at 1 Hz
    assert m.live_findings(unit) == []
    assert verdict(m, stream, "HB-003").verdict is Verdict.PASS  # 40 intervals: 1.09 s mean


@pytest.mark.parametrize("times", [
    [i + (0.04 if i % 2 else -0.04) for i in range(60)],                # jitter
    [t for t in range(80) if not 25 <= t % 30 < 29],                    # silences (HB-010)
], ids=["jitter", "silences"])
def test_a_conformant_rate_is_never_shown_off_live(stream, times):
    m = Monitor()
    for t in times:  # looked at after every message, as often as a scorecard could
        stream.feed(m, [stream.heartbeat(t)])
        assert m.live_findings(stream.address) == [], t


def test_a_gross_rate_mismatch_shows_live_after_two_intervals(stream):
    """Every interval 3 declared periods or longer is gross after 2 intervals."""
    m = Monitor()
    stream.feed(m, [stream.heartbeat(i * 5.0) for i in range(2)])
    assert m.live_findings(stream.address) == []
    stream.feed(m, [stream.heartbeat(10.0)])
    (live,) = m.live_findings(stream.address)
    assert "0.20 Hz over the latest 2 intervals" in live.observed and "gross" in live.observed
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.FAIL
    # Regular, only far slower than declared: said so, not called silences.
    assert "(min 5.000 s, max 5.000 s, every one over 3 declared periods)" in \
        r.violations[0].observed, r.violations[0].observed


def test_rate_skips_with_too_few_intervals(stream):
    m = Monitor()
    stream.feed(m, [stream.heartbeat(i) for i in range(5)])
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.SKIP and r.reason == "only 4 intervals observed; need 10"


def test_rate_excludes_connection_gaps(stream):
    m = Monitor()
    m.connection_gap(stream.heartbeat(4.5).time, stream.heartbeat(6.5).time)
    times = [0, 1, 2, 3, 4, 8, 9, 10, 11, 12, 13, 14, 15]
    stream.feed(m, [stream.heartbeat(t) for t in times])
    assert verdict(m, stream, "HB-003").verdict is Verdict.PASS
    assert verdict(m, stream, "HB-010").verdict is Verdict.PASS


def test_rate_leaves_out_the_interval_across_a_reboot(stream):
    # 2.4 s of restart at 1 Hz: over max_gap_periods (1.5), under a silence (3 periods).
    m = Monitor()
    new = str(uuid.uuid4())
    msgs = [stream.heartbeat(i) for i in range(8)]
    msgs += [stream.heartbeat(9.4 + i, agent_uuid=new) for i in range(8)]
    stream.feed(m, msgs)
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.PASS, r
    assert m.report().units[str(stream.address)].rates[0].intervals == 14


def test_rate_counts_the_same_pause_without_a_reboot(stream):
    # The matching fault: the same 2.4 s pause with the same agent-uuid is a stall.
    m = Monitor(STRICT)
    msgs = [stream.heartbeat(i) for i in range(8)] + [stream.heartbeat(9.4 + i) for i in range(8)]
    stream.feed(m, msgs)
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.FAIL and "2.400 s" in r.violations[0].observed


@pytest.mark.parametrize("rule,builder", [
    ("SI-002", "sensor_info"), ("DEI-002", "direct_execution_info")])
def test_info_rate_without_agent_uuid_starts_afresh_with_the_heartbeats_new_life(stream, rule,
                                                                                  builder):
    """The RISE agent's info messages carry no agent-uuid: its restart (2.4 s at 1 Hz, a new
    agent-uuid in the heartbeat) is the heartbeat's life boundary for them too,
    while the same pause without a new life stays a stall."""
    def life(new: str | None) -> list:
        msgs = []
        for i in range(16):
            t = i if i < 8 else 1.4 + i
            info = getattr(stream, builder)(t)
            body = orjson.loads(info.payload)
            del body["agent-uuid"]
            msgs += [stream.heartbeat(t, agent_uuid=new if i >= 8 else None),
                     stream.msg(info.topic.rsplit("/", 1)[1], body, t)]
        return msgs
    rebooted, stalled = Monitor(STRICT), Monitor(STRICT)
    stream.feed(rebooted, life(str(uuid.uuid4())))
    stream.feed(stalled, life(None))
    r = verdict(rebooted, stream, rule)
    assert r.verdict is Verdict.PASS, r
    bad = verdict(stalled, stream, rule)
    assert bad.verdict is Verdict.FAIL and "2.400 s" in bad.violations[0].observed


def test_rate_of_two_agents_taking_turns_under_one_name_is_doubled(stream):
    # Not a reboot: each message alternates between two known agent-uuids (HB-011's twins).
    m = Monitor(STRICT)
    twin = str(uuid.uuid4())
    stream.feed(m, [stream.heartbeat(i * 0.5, agent_uuid=twin if i % 2 else None)
                    for i in range(24)])
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.FAIL and "2.00 Hz" in r.violations[0].observed


def test_rate_of_a_unit_always_far_slower_than_declared_fails(stream):
    m = Monitor()
    stream.feed(m, [stream.heartbeat(i * 10.0, rate=10.0) for i in range(12)])
    r = verdict(m, stream, "HB-003")
    assert r.verdict is Verdict.FAIL and "0.10 Hz" in r.violations[0].observed


@pytest.mark.parametrize("rule,builder", [
    ("SI-002", "sensor_info"), ("DEI-002", "direct_execution_info")])
def test_info_rates(stream, rule, builder):
    good, bad = Monitor(STRICT), Monitor(STRICT)
    stream.feed(good, [getattr(stream, builder)(i) for i in range(12)])
    stream.feed(bad, [getattr(stream, builder)(i * 2.0) for i in range(12)])
    assert verdict(good, stream, rule).verdict is Verdict.PASS
    assert verdict(bad, stream, rule).verdict is Verdict.FAIL


def test_sensor_info_on_both_spellings_is_two_streams_each_at_its_rate(stream):
    """3.1 names sensor_info, 5.2 'UNIT/sensor.info': a unit that publishes on both, each at
    the declared 1 Hz, sends two streams at 1 Hz, not one at 2 Hz (the spelling warns,
    ERR-001). The same spelling twice a period is one stream at twice the rate (its
    tolerance condition: decided, so judged strictly here)."""
    def dotted(t: float):
        info = stream.sensor_info(t)
        return stream.msg("sensor.info", orjson.loads(info.payload), t)

    both = [m for i in range(12) for m in (stream.sensor_info(i), dotted(i + 0.01))]
    default, strict, doubled = Monitor(), Monitor(STRICT), Monitor(STRICT)
    stream.feed(default, both)
    stream.feed(strict, both)
    stream.feed(doubled, [stream.sensor_info(i * 0.5) for i in range(24)])
    assert verdict(default, stream, "SI-002").verdict is Verdict.PASS
    assert verdict(default, stream, "ERR-001").verdict is Verdict.WARN
    assert verdict(strict, stream, "SI-002").verdict is Verdict.PASS
    assert verdict(doubled, stream, "SI-002").verdict is Verdict.FAIL


def test_tst_execution_info_rate(stream):
    def tei(t):
        return stream.msg("tst_execution_info", {"name": "dji0", "rate": 2.0, "stamp": t,
                                                 "type": "TstExecutionInfo"}, t)
    good, bad = Monitor(STRICT), Monitor(STRICT)
    stream.feed(good, [tei(i * 0.5) for i in range(12)])
    stream.feed(bad, [tei(i * 0.3) for i in range(12)])
    assert verdict(good, stream, "TEI-002").verdict is Verdict.PASS
    assert verdict(bad, stream, "TEI-002").verdict is Verdict.FAIL


def test_a_new_declared_rate_starts_a_new_window(stream):
    m = Monitor()
    msgs = [stream.heartbeat(i) for i in range(12)]
    msgs += [stream.heartbeat(12 + i * 0.5, rate=2.0) for i in range(12)]
    assert not rules_found(stream.feed(m, msgs)) & {"HB-003"}
    assert verdict(m, stream, "HB-003").verdict is Verdict.PASS
    assert [s.declared_hz for s in m.report().units[str(stream.address)].rates] == [1.0, 2.0]


def test_rate_memory_is_bounded(stream):
    m = Monitor()
    for i in range(5000):
        m.feed(stream.heartbeat(i * 0.1, rate=10.0))
    stat = m.report().units[str(stream.address)].rates[0]
    assert stat.intervals == 4999 and len(stat.series) <= 600
    assert verdict(m, stream, "HB-003").verdict is Verdict.PASS


# -- identity: HB-006, HB-011, HB-010, MSG-007, HB-008 --------------------------------------------

def test_agent_uuid_change_after_silence_is_a_reboot(stream):
    m = Monitor()
    msgs = [stream.heartbeat(i) for i in range(5)]
    new = str(uuid.uuid4())
    msgs += [stream.heartbeat(7 + i, agent_uuid=new) for i in range(5)]  # 3 s silence
    found = stream.feed(m, msgs)
    assert "HB-006" not in rules_found(found)
    assert verdict(m, stream, "HB-006").verdict is Verdict.PASS


def test_agent_uuid_changing_again_without_silence_fails(stream):
    """A second change soon after a first may be a second restart (HB-006's decided
    'restarts': warns, strict fails); a third in a row is a uuid made per thread or message."""
    stream.levels = []  # heartbeats only: no level claimed (else HB-008 fails too)
    msgs = [stream.heartbeat(i) for i in range(5)]
    new, newer, newest = str(uuid.uuid4()), str(uuid.uuid4()), str(uuid.uuid4())
    msgs += [stream.heartbeat(5 + i, agent_uuid=new) for i in range(5)]
    msgs += [stream.heartbeat(10 + i, agent_uuid=newer) for i in range(5)]
    for profile, expected in ((Profile(), Verdict.WARN), (STRICT, Verdict.FAIL)):
        m = Monitor(profile)
        found = stream.feed(m, msgs)
        assert rules_found(found) == {"HB-006"}
        assert verdict(m, stream, "HB-006").verdict is expected
    m = Monitor()
    stream.feed(m, msgs + [stream.heartbeat(15 + i, agent_uuid=newest) for i in range(5)])
    r = verdict(m, stream, "HB-006")
    # The finding it fails on first, then the decided one (``judge.failing_first``).
    assert r.verdict is Verdict.FAIL and [v.condition for v in r.violations] == ["", "restarts"]


def test_one_fast_restart_is_a_reboot(stream):
    """5.1: the agent-uuid 'should change when rebooting'; a process restarted within a
    heartbeat period (an independently written unit did in 0.56 s) is no fault, and the short
    silence it leaves is no HB-010 either."""
    stream.levels = []
    m = Monitor()
    new = str(uuid.uuid4())
    msgs = [stream.heartbeat(i) for i in range(5)]
    msgs += [stream.heartbeat(4.5 + i, agent_uuid=new) for i in range(5)]
    assert stream.feed(m, msgs) == []
    assert verdict(m, stream, "HB-006").verdict is Verdict.PASS
    slow = Monitor()  # a reboot of 5 periods: a new agent-uuid, no silence warned of
    msgs = [stream.heartbeat(i) for i in range(5)]
    msgs += [stream.heartbeat(9 + i, agent_uuid=new) for i in range(5)]
    assert stream.feed(slow, msgs) == []


def test_two_agents_under_one_name(stream):
    m = Monitor()
    other = str(uuid.uuid4())
    msgs = [stream.heartbeat(i * 0.5, agent_uuid=other if i % 2 else None) for i in range(10)]
    stream.feed(m, msgs)
    assert verdict(m, stream, "HB-011").verdict is Verdict.FAIL
    good = Monitor()
    stream.feed(good, [stream.heartbeat(i) for i in range(5)])
    assert verdict(good, stream, "HB-011").verdict is Verdict.PASS


def test_silence_warns_and_says_how_the_unit_came_back(stream):
    stream.levels = []
    m = Monitor()
    msgs = [stream.heartbeat(i) for i in range(3)] + [stream.heartbeat(10 + i) for i in range(3)]
    found = stream.feed(m, msgs)
    assert rules_found(found) == {"HB-010"}
    r = verdict(m, stream, "HB-010")
    assert r.verdict is Verdict.WARN and "same agent-uuid (resumed)" in r.violations[0].observed


def test_a_heartbeat_that_stops_for_good_is_a_death_at_finish(stream):
    """With no command before it, a unit that stops is switched off or gone (the decided
    'no-command' condition: warns; strict fails); after a command, it died on it (fails)."""
    m = Monitor()
    stream.feed(m, [stream.heartbeat(i) for i in range(3)])
    m.finish(now=stream.heartbeat(10).time)
    rules = m.report().units[str(stream.address)].rules
    r = rules["HB-012"]
    assert r.verdict is Verdict.WARN and "never came back" in r.violations[0].observed
    assert r.violations[0].condition == "no-command"
    strict = Monitor(STRICT)
    stream.feed(strict, [stream.heartbeat(i) for i in range(3)])
    strict.finish(now=stream.heartbeat(10).time)
    assert strict.report().units[str(stream.address)].rules["HB-012"].verdict is Verdict.FAIL
    commanded = Monitor(Profile(response_timeout=1.0))
    stream.feed(commanded, [stream.heartbeat(i) for i in range(3)]
                + [stream.command(2.5, "ping")])
    commanded.finish(now=stream.heartbeat(10).time)
    died = commanded.report().units[str(stream.address)].rules["HB-012"]
    assert died.verdict is Verdict.FAIL and died.violations[0].condition == "", died
    assert "it had received no command" in r.violations[0].observed
    assert "dies on a command" not in r.violations[0].detail  # the hint fits the finding
    assert rules["HB-010"].verdict is Verdict.PASS  # a silence that resumed is HB-010's
    m.finish(now=stream.heartbeat(3).time)  # finish again: re-judged, not counted twice
    assert m.report().units[str(stream.address)].rules["HB-012"].verdict is Verdict.PASS


def test_a_recording_cut_just_after_a_fast_unit_s_heartbeat_is_no_death(stream):
    """A 10 Hz unit whose recording stops 0.36 s (3.6 periods) after its last heartbeat: the
    recorder stopped, not the unit (a death needs DEATH_FLOOR seconds of silence too)."""
    fast = type(stream)(stream.address, rate=10.0)
    m = Monitor()
    stream.feed(m, fast.alive(5, info=False, sensors=False))
    m.finish(now=fast.heartbeat(5.0).time + 0.36)
    assert verdict(m, stream, "HB-012").verdict is Verdict.PASS


def test_stale_retained_heartbeat_warns(stream):
    m = Monitor()
    found = stream.feed(m, [stream.heartbeat(100, stamp=stream.heartbeat(0).time, retain=True)])
    assert rules_found(found) == {"MSG-007"}
    fresh = Monitor()
    assert stateful(stream.feed(fresh, [stream.heartbeat(100, retain=True)])) == []
    assert verdict(fresh, stream, "MSG-007").verdict is Verdict.PASS
    assert verdict(m, stream, "MSG-007").verdict is Verdict.WARN


def test_retained_heartbeat_does_not_count_as_a_uuid_change(stream):
    m = Monitor()
    old = stream.heartbeat(0, agent_uuid=str(uuid.uuid4()), stamp=stream.heartbeat(-1).time, retain=True)
    found = stream.feed(m, [old] + [stream.heartbeat(0.1 + i) for i in range(3)])
    assert "HB-006" not in rules_found(found) and "HB-011" not in rules_found(found)


def test_declared_level_without_info_fails(stream):
    m = Monitor(STRICT)
    stream.feed(m, [stream.heartbeat(i) for i in range(32)])  # 31 s >= info_wait (30 s)
    r = verdict(m, stream, "HB-008")
    assert r.verdict is Verdict.FAIL and "sensor_info" in r.violations[0].expected
    assert {v.observed for v in r.violations} == {"no sensor_info in 31.0 s",
                                                  "no direct_execution_info in 31.0 s"}
    good = Monitor(STRICT)
    assert stateful(stream.feed(good, stream.alive(31))) == []
    assert verdict(good, stream, "HB-008").verdict is Verdict.PASS


def test_declared_level_judged_at_finish_only_after_enough_time(stream):
    m = Monitor(STRICT)
    found = stream.feed(m, [stream.heartbeat(i) for i in range(5)])
    assert "HB-008" not in rules_found(found)  # decided at finish, never mid-stream
    r = verdict(m, stream, "HB-008")
    assert r.verdict is Verdict.SKIP and "observed 4.0 s; need 30.0 s to judge" in r.reason
    m.finish(now=stream.heartbeat(30).time)
    assert m.report().units[str(stream.address)].rules["HB-008"].verdict is Verdict.FAIL
    short = Monitor(Profile(info_wait=3.0, strict=True))  # a profile may wait less
    stream.feed(short, [stream.heartbeat(i) for i in range(5)])
    assert verdict(short, stream, "HB-008").verdict is Verdict.FAIL


def test_declared_level_with_slow_info_passes(stream):
    """Spec 5: info messages may come slower than the heartbeat; one at 20 s backs the level
    (it failed after 3 heartbeat periods before HB-008 was decided over the observation)."""
    m = Monitor()
    msgs = [stream.heartbeat(i) for i in range(40)]
    msgs += [stream.sensor_info(20.5, rate=0.05), stream.direct_execution_info(25.5, rate=0.05)]
    assert "HB-008" not in rules_found(stream.feed(m, msgs))
    assert verdict(m, stream, "HB-008").verdict is Verdict.PASS


def test_declared_level_waits_three_heartbeat_periods_at_least(stream):
    slow = type(stream)(stream.address, rate=0.05)  # one heartbeat every 20 s
    m = Monitor(STRICT)
    slow.feed(m, [slow.heartbeat(0), slow.heartbeat(20), slow.heartbeat(40)])
    r = verdict(m, slow, "HB-008")
    assert r.verdict is Verdict.SKIP and "need 60.0 s" in r.reason
    m.finish(now=slow.heartbeat(60).time)
    assert m.report().units[str(slow.address)].rules["HB-008"].verdict is Verdict.FAIL


def test_declared_level_not_judged_over_a_connection_gap(stream):
    m = Monitor()
    m.connection_gap(stream.heartbeat(2).time, stream.heartbeat(30).time)
    stream.feed(m, [stream.heartbeat(i) for i in (0, 1, 31, 32, 33)])
    r = verdict(m, stream, "HB-008")
    assert r.verdict is Verdict.SKIP and "observed 5.0 s" in r.reason


# -- sensors: SI-003, SI-004, SI-005, SENS-005 -----------------------------------------------------

def test_a_heading_outside_the_decided_range_warns_once_per_unit_not_per_message(stream):
    """6.1 says 'heading : float': [0, 360) is SENS-002's decision, an interop risk said once
    per unit (a unit sending headings in (-180, 180] warned at every message: 228 times)."""
    m = Monitor()
    msgs = stream.alive(5) + [stream.sensor("heading", -143.0, 0.5 + i) for i in range(5)]
    msgs += [stream.sensor("course", -10.0, 0.6 + i) for i in range(5)]
    stream.feed(m, msgs)
    r = verdict(m, stream, "SENS-002")
    assert r.verdict is Verdict.WARN and len(r.violations) == 1
    assert "-143" in r.violations[0].observed and "no range" in r.violations[0].detail
    good = Monitor()
    stream.feed(good, stream.alive(5))
    assert verdict(good, stream, "SENS-002").verdict is Verdict.PASS


def test_listed_sensor_not_published_fails(stream):
    m = Monitor()
    msgs = stream.alive(5)
    msgs += [stream.sensor_info(i + 0.5, sensors=["position", "heading", "course", "speed",
                                                  "camera_url"]) for i in range(6)]
    stream.feed(m, msgs)
    r = verdict(m, stream, "SI-003")
    assert r.verdict is Verdict.FAIL and "camera_url" in r.violations[0].observed
    good = Monitor()
    stream.feed(good, stream.alive(5))
    assert verdict(good, stream, "SI-003").verdict is Verdict.PASS


def test_listed_sensor_not_judged_before_the_window(stream):
    m = Monitor()
    stream.feed(m, [stream.heartbeat(0), stream.sensor_info(0.1)])
    r = verdict(m, stream, "SI-003")
    assert r.verdict is Verdict.SKIP and "observed only" in r.reason


def test_mandatory_sensors_listed_and_published(stream):
    m = Monitor()
    msgs = [stream.heartbeat(i) for i in range(5)]
    msgs += [stream.sensor_info(i + 0.1, sensors=["position", "speed"]) for i in range(5)]
    msgs += [stream.position(58.4, 15.6, i + 0.2) for i in range(5)]
    found = stream.feed(m, msgs)
    assert stateful(found).count("SI-004") == 1  # once per distinct list
    r = verdict(m, stream, "SI-004")
    assert r.verdict is Verdict.FAIL
    assert any("heading" in v.observed and "nothing on" in v.observed for v in r.violations)


def test_mandatory_sensors_published_but_not_listed_warn_as_5_2_s_examples_do(stream):
    """Both 5.2 examples list position and speed only: a unit that publishes all four
    mandatory sensors with such a list warns (SI-004's decided 'listed'), fails only strict."""
    msgs = stream.alive(8, info=False)
    msgs += [stream.sensor_info(i + 0.01, sensors=["position", "speed"]) for i in range(9)]
    for profile, expected in ((Profile(), Verdict.WARN), (STRICT, Verdict.FAIL)):
        m = Monitor(profile)
        stream.feed(m, msgs)
        r = verdict(m, stream, "SI-004")
        assert r.verdict is expected, r
        assert [v.condition for v in r.violations] == ["listed"]


def test_mandatory_sensors_unpublished_fail_without_sensor_info(stream):
    """6.1 makes the four sensors mandatory whether or not sensor_info is sent: a unit that
    claims the sensor level and publishes only sensor/position, with no sensor_info at all
    (the public drone operator), fails SI-004's own words once the window (3 heartbeat
    periods) has passed; before it, the rule waits and says so."""
    msgs = stream.alive(8, info=False, sensors=False)
    msgs += [stream.position(58.4, 15.6, i + 0.03) for i in range(9)]
    m = Monitor()
    stream.feed(m, msgs)
    r = verdict(m, stream, "SI-004")
    assert r.verdict is Verdict.FAIL, r
    assert [v.condition for v in r.violations] == [""]
    assert "nothing on heading, course, speed" in r.violations[0].observed
    early = Monitor()
    stream.feed(early, [x for x in msgs if x.time < msgs[0].time + 1.5])
    r = verdict(early, stream, "SI-004")
    assert r.verdict is Verdict.SKIP and "need 3.0 s" in r.reason, r


def test_mandatory_sensors_of_a_unit_that_claims_no_sensor_level_are_not_asked_for(stream):
    """A unit that claims no sensor level and publishes no sensor: SI-004 does not apply."""
    m = Monitor()
    stream.feed(m, [stream.heartbeat(i, levels=["direct execution"]) for i in range(8)])
    r = verdict(m, stream, "SI-004")
    assert r.verdict is Verdict.SKIP and not r.violations, r


def test_mandatory_sensors_are_judged_up_to_the_units_last_message(stream):
    """A unit that dies publishes nothing after: the window is measured up to its last
    message (its death is HB-012's finding), not up to the end of the observation."""
    msgs = [stream.heartbeat(i) for i in range(2)]
    msgs += [stream.position(58.4, 15.6, i + 0.03) for i in range(2)]
    m = Monitor()
    stream.feed(m, msgs)
    m.finish(msgs[0].time + 40.0)  # the observation goes on long after
    r = verdict(m, stream, "SI-004", finish=False)
    assert r.verdict is Verdict.SKIP and "observed 1.0 s" in r.reason, r


def test_unlisted_sensor_warns_once(stream):
    m = Monitor()
    msgs = stream.alive(3) + [stream.sensor("battery", 0.5, i + 0.5) for i in range(3)]
    found = stream.feed(m, msgs)
    assert stateful(found) == ["SI-005"]
    assert verdict(m, stream, "SI-005").verdict is Verdict.WARN
    good = Monitor()
    stream.feed(good, stream.alive(3))
    assert verdict(good, stream, "SI-005").verdict is Verdict.PASS


def test_unlisted_sensor_seen_before_the_list_warns_at_finish(stream):
    m = Monitor()
    stream.feed(m, [stream.sensor("battery", 0.5, 0)] + stream.alive(3, start=1))
    assert verdict(m, stream, "SI-005").verdict is Verdict.WARN


def test_position_jump_warns(stream):
    m = Monitor()
    msgs = [stream.sensor("speed", 2.0, 0), stream.position(58.4, 15.6, 0.1),
            stream.position(58.41, 15.6, 1.1),  # 1.1 km in 1 s at 2 m/s
            stream.sensor("speed", 2.0, 1.102)]  # the speed of the same instant: still 2 m/s
    found = stream.feed(m, msgs)
    assert rules_found(found) == {"SENS-005"}
    good = Monitor()
    stream.feed(good, [stream.sensor("speed", 2.0, 0), stream.position(58.4, 15.6, 0.1),
                       stream.position(58.40001, 15.6, 1.1)])  # 1.1 m
    assert verdict(good, stream, "SENS-005").verdict is Verdict.PASS


def test_a_position_is_judged_with_the_speed_published_at_the_same_instant(stream):
    """A unit that publishes each instant's position just before its speed (12: no order
    between topics), setting off from standstill at 20 m/s: the step of 20 m in 1 s is
    judged with the 20 m/s of its own instant, not the 0 m/s before it (no SENS-005). A
    step too fast even for it still warns, also when nothing follows it."""
    def steps(metres: float, speed: float, last: bool = False) -> list:
        msgs = []
        for i in range(4):
            moving = i == 3
            msgs.append(stream.position(58.4 + (metres / 111_195 if moving else 0.0), 15.6,
                                        0.1 + i))
            if not (last and moving):
                msgs.append(stream.sensor("speed", speed if moving else 0.0, 0.102 + i))
        return msgs

    good = Monitor()
    stream.feed(good, steps(20.0, 20.0))
    assert verdict(good, stream, "SENS-005").verdict is Verdict.PASS
    for last in (False, True):
        bad = Monitor()
        stream.feed(bad, steps(1_100.0, 20.0, last=last))  # 1.1 km in 1 s at 20 m/s
        r = verdict(bad, stream, "SENS-005")
        assert r.verdict is Verdict.WARN and len(r.violations) == 1, (last, r)
        assert "moved 1100" in r.violations[0].observed


# -- execution: EXEC-004, EXEC-FB-003, EXEC-006, EXEC-008, EXEC-FB-004 -----------------------------

def test_response_agent_uuid_must_be_the_heartbeats(stream):
    m = Monitor()
    ping = stream.command(0.5)
    com = ping.payload.decode()
    cu = __import__("json").loads(com)["com-uuid"]
    msgs = stream.alive(2) + [ping, stream.response(0.6, cu),
                              stream.response(0.7, cu, agent_uuid=str(uuid.uuid4()))]
    stream.feed(m, msgs)
    r = verdict(m, stream, "EXEC-004")
    assert r.verdict is Verdict.FAIL and len(r.violations) == 1


def test_response_with_the_next_lifes_uuid_is_fine_after_reboot(stream):
    m = Monitor()
    new = str(uuid.uuid4())
    msgs = [stream.heartbeat(0), stream.response(5.0, C1, agent_uuid=new),
            stream.heartbeat(5.1, agent_uuid=new)]
    found = stream.feed(m, msgs)
    assert "EXEC-004" not in rules_found(found)
    assert verdict(m, stream, "EXEC-004").verdict is Verdict.PASS


def test_twin_agents_answers_are_judged_by_hb_011_not_exec_004(stream):
    """Two live agents under one name (HB-011): each answers with its own heartbeat's uuid,
    which is not a stale uuid; a uuid whose heartbeats stopped long ago still is."""
    m = Monitor()
    twin = str(uuid.uuid4())
    task = str(uuid.uuid4())
    msgs = []
    for i in range(6):  # both heartbeat every second, interleaved
        msgs += [stream.heartbeat(i), stream.heartbeat(i + 0.5, agent_uuid=twin)]
    msgs += [stream.feedback(5.6, task, "running"),  # the first agent's, after the twin's heartbeat
             stream.feedback(5.7, task, "running", agent_uuid=twin)]
    found = stream.feed(m, msgs)
    assert "HB-011" in rules_found(found) | {r for r, res in _unit_rules(m, stream).items()
                                              if res.verdict is Verdict.FAIL}
    assert "EXEC-FB-003" not in rules_found(found)
    assert verdict(m, stream, "EXEC-FB-003").verdict is Verdict.PASS


def _unit_rules(m: Monitor, stream):
    m.finish()
    return m.report().units[str(stream.address)].rules


def test_feedback_agent_uuid(stream):
    m = Monitor()
    task = str(uuid.uuid4())
    stale = stream.agent_uuid
    msgs = [stream.heartbeat(0), stream.heartbeat(4, agent_uuid=str(uuid.uuid4())),
            stream.feedback(4.5, task, "running", agent_uuid=stale)]
    found = stream.feed(m, msgs)
    assert "EXEC-FB-003" in rules_found(found)
    good = Monitor()
    stream.feed(good, [stream.heartbeat(0), stream.feedback(0.5, task, "running")])
    assert verdict(good, stream, "EXEC-FB-003").verdict is Verdict.PASS


def test_response_must_answer_a_command_seen(stream):
    m = Monitor(Profile(response_timeout=1.0))
    cmd = stream.command(2.0, com_uuid=C1)
    msgs = [stream.heartbeat(0), cmd, stream.response(2.1, C1), stream.response(2.2, C2)]
    found = stream.feed(m, msgs)
    assert rules_found(found) == {"EXEC-006"}
    r = verdict(m, stream, "EXEC-006")
    assert r.verdict is Verdict.FAIL and C2 in r.violations[0].observed


def test_response_not_judged_without_commands_seen(stream):
    m = Monitor(Profile(response_timeout=1.0))
    stream.feed(m, [stream.heartbeat(0), stream.response(3, C2)])
    r = verdict(m, stream, "EXEC-006")
    assert r.verdict is Verdict.SKIP and "subscribe" in r.reason


def test_com_uuid_reused_for_another_command_fails(stream):
    m = Monitor()
    msgs = [stream.command(0, "ping", com_uuid=C1), stream.command(1, "ping", com_uuid=C1),
            stream.command(2, "query-status", com_uuid=C1, **{"task-uuid": str(uuid.uuid4())})]
    found = stream.feed(m, msgs)
    assert stateful(found) == ["EXEC-008"]  # the identical resend is fine
    m.finish()
    report = m.report()
    # What is wrong in a command is the commander's fault: its own row, not the unit's.
    commander = report.units["commander commander"]
    assert commander.party == "commander" and commander.rules["EXEC-008"].verdict is Verdict.FAIL
    unit = report.units[str(stream.address)].rules["EXEC-008"]
    assert unit.verdict is Verdict.SKIP and "commander-side" in unit.reason


def test_feedback_after_final_status_fails(stream):
    m = Monitor()
    task = str(uuid.uuid4())
    msgs = [stream.heartbeat(0), stream.feedback(1, task, "running"),
            stream.feedback(2, task, "finished", com_uuid="f1"),
            stream.feedback(2.1, task, "finished", com_uuid="f1"),  # a redelivery: fine
            stream.feedback(3, task, "running")]
    found = stream.feed(m, msgs)
    assert stateful(found) == ["EXEC-FB-004"]
    good = Monitor()
    stream.feed(good, msgs[:4])
    assert verdict(good, stream, "EXEC-FB-004").verdict is Verdict.PASS


def test_response_right_after_the_start_is_judged_when_its_command_was_seen(stream):
    m = Monitor()  # response timeout 5 s: unknown responses that early are not judged
    found = stream.feed(m, [stream.command(0.1, com_uuid=C1), stream.response(0.2, C1),
                            stream.response(0.3, C2)])
    assert "EXEC-006" not in rules_found(found)
    assert verdict(m, stream, "EXEC-006").verdict is Verdict.PASS


def test_answer_to_a_malformed_command_with_a_readable_com_uuid_answers_a_command(stream):
    m = Monitor(Profile(response_timeout=0.0))
    bad = stream.msg("exec/command", f'{{"com-uuid": "{C1}", "command": ping,}}'.encode(), 1)
    found = stream.feed(m, [stream.heartbeat(0), bad,
                            stream.response(1.1, C1, response="failed",
                                            **{"fail-reason": "not JSON"})])
    assert "EXEC-006" not in rules_found(found)
    assert verdict(m, stream, "EXEC-006").verdict is Verdict.PASS


def test_signal_task_response_in_another_form_is_err_013_not_exec_002(stream):
    import orjson

    task = str(uuid.uuid4())
    signal = stream.command(1, "signal-task", com_uuid=C1, signal="$abort",
                            **{"task-uuid": task})
    ping = stream.command(2, "ping", com_uuid=C2)
    tst_form = {"com-uuid": str(uuid.uuid4()), "response": "ok"}
    m = Monitor()
    found = stream.feed(m, [stream.heartbeat(0), signal, ping,
                            stream.msg("exec/response", orjson.dumps(
                                {**tst_form, "response-to": C1}), 1.1),
                            stream.msg("exec/response", orjson.dumps(
                                {**tst_form, "response-to": C2}), 2.1)])
    err013 = [v for v in found if v.rule == "ERR-013"]
    exec002 = [v for v in found if v.rule == "EXEC-002"]
    assert err013 and all(C1 in v.excerpt for v in err013)
    assert exec002 and all(C2 in v.excerpt for v in exec002)
    assert verdict(m, stream, "ERR-013").verdict is Verdict.WARN


def test_a_silence_while_the_host_held_the_unit_is_not_judged(stream):
    """The bundled reference unit runs in the suite's own process: a loaded machine that held
    it (``Monitor.host_held``) made that silence, not the unit."""
    stream.levels = []
    msgs = [stream.heartbeat(i) for i in range(3)] + [stream.heartbeat(10 + i) for i in range(3)]
    held = Monitor()
    held.host_held(msgs[2].time + 0.2, msgs[3].time - 0.1)
    assert "HB-010" not in rules_found(stream.feed(held, msgs))
    assert verdict(held, stream, "HB-010").verdict is Verdict.PASS
    elsewhere = Monitor()
    elsewhere.host_held(msgs[-1].time + 5, msgs[-1].time + 9)  # another time: no excuse
    assert rules_found(stream.feed(elsewhere, msgs)) == {"HB-010"}

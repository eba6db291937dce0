"""Reports: JSON round trip, JUnit structure, HTML escaping, atomic writes, text rendering."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import orjson
import pytest

from conformance.client import BrokerURL
from conformance.conclusion import conclude
from conformance.display import printable, shorten
from conformance.facts import RunFacts
from conformance.report_meta import RunMeta
from conformance.reporting import files as files_mod
from conformance.reporting import (
    read_json,
    render_html,
    render_summary,
    render_violation,
    to_junit,
    write_all,
)
from conformance.results import RunReport
from conformance.rules import CATALOGUE
from conformance.violation import Verdict, Violation


def test_report_content(run_report: RunReport):
    slow = next(u for n, u in run_report.units.items() if n.endswith("piraya0"))
    good = next(u for n, u in run_report.units.items() if n.endswith("dji0"))
    assert slow.rules["HB-003"].verdict is Verdict.FAIL
    assert good.rules["HB-003"].verdict is Verdict.PASS
    assert good.rules["REBOOT-001"].verdict is Verdict.COULD_NOT_TEST
    assert "(unattributed)" in run_report.units
    assert run_report.broker == "mqtts://alice@127.0.0.1:8883"
    assert conclude(run_report).exit_code == 1
    counts = run_report.verdict_counts()
    assert set(counts) == {v.value for v in Verdict} and counts["fail"] >= 2


def test_json_round_trip(run_report: RunReport, tmp_path):
    paths = write_all(run_report, tmp_path, "run")
    again = read_json(paths["json"])
    assert again.to_dict() == run_report.to_dict()
    assert again == RunReport.from_dict(orjson.loads(paths["json"].read_bytes()))
    assert "s3cret" not in paths["json"].read_text()


def test_junit_has_a_suite_per_unit_and_a_case_per_rule(run_report: RunReport, tmp_path):
    path = write_all(run_report, tmp_path, "run", junit=True)["junit"]
    root = ET.parse(path).getroot()
    suites = root.findall("testsuite")
    assert [s.get("name") for s in suites] == list(run_report.units)
    slow_name = next(n for n in run_report.units if n.endswith("piraya0"))
    slow = next(s for s in suites if s.get("name") == slow_name)
    props = {p.get("name"): p.get("value") for p in slow.iter("property")}
    assert props["unit"] == slow_name and props["profile"] == "default"
    assert props["agent-uuid"] == run_report.units[slow_name].agent_uuids[0]
    assert {"suite-version", "schemas-hash"} <= set(props)
    cases = {c.get("name").split()[0]: c for c in slow.iter("testcase")}
    assert len(cases) == len(run_report.units[slow_name].rules)
    assert cases["HB-003"].find("failure") is not None
    assert "Hz" in cases["HB-003"].find("failure").get("message")
    assert cases["EXEC-PING-001"].find("skipped") is not None
    assert cases["TOPIC-001"].find("failure") is None and cases["TOPIC-001"].find("skipped") is None
    assert "s3cret" not in path.read_text()


def test_html_escapes_hostile_payloads(run_report: RunReport):
    page = render_html(run_report)
    assert "<script" not in page and "<img" not in page and "\x00" not in page
    assert "&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt;" in page
    assert "\\x00" in page and "\\x1b" in page  # control characters made visible
    assert "&amp;amp;" in page  # an entity in the payload is shown, not interpreted
    assert "http://" not in page.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "<svg" in page and "HB-003" in page


def test_write_all_is_atomic_and_repeatable(run_report: RunReport, tmp_path, monkeypatch):
    first = write_all(run_report, tmp_path, "run")
    before = first["html"].read_bytes()
    write_all(run_report, tmp_path, "run")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.html", "run.json"]

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(files_mod.os, "replace", interrupted)
    run_report.meta = RunMeta(source="changed")
    with pytest.raises(KeyboardInterrupt):
        write_all(run_report, tmp_path, "run")
    assert first["html"].read_bytes() == before  # the old report survives whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.html", "run.json"]
    # mkstemp's 0600 is replaced by the umask's mode, as for any file the user writes
    assert os.stat(first["json"]).st_mode & 0o777 == 0o666 & ~files_mod._UMASK


def test_render_violation_reads_like_the_style_guide():
    v = Violation.of("HB-003", expected="1.00 Hz +-20% (declared in heartbeat.rate)",
                     observed="0.61 Hz over 12 intervals (min 1.58 s, max 1.71 s)",
                     topic="waraps/unit/air/simulation/dji0/heartbeat")
    text = render_violation("HB-003", v, "waraps/unit/air/simulation/dji0")
    lines = text.splitlines()
    assert lines[0].startswith("HB-003 heartbeat rate matches its declared rate")
    assert lines[0].endswith("[fail]")
    assert lines[1:] == [
        "  expected  1.00 Hz +-20% (declared in heartbeat.rate)",
        "  observed  0.61 Hz over 12 intervals (min 1.58 s, max 1.71 s)",
        "  topic     waraps/unit/air/simulation/dji0/heartbeat",
        "  spec      5.1 General Heartbeat Message",
        # What the rule stands on: the spec's words, or this suite's decision.
        f"  basis     {printable(shorten(CATALOGUE['HB-003'].basis_text()))}",
        "  rerun     pytest --unit waraps/unit/air/simulation/dji0 -k HB-003",
    ]
    warn = render_violation("HB-010", Violation.of("HB-010", expected="a", observed="b\x07"),
                            rerun_hint="")
    assert warn.splitlines()[0].endswith("[warn]") and "\\x07" in warn and "rerun" not in warn


def test_rerun_line_says_how_to_repeat_a_lint_or_a_certification():
    unit = "waraps/unit/air/simulation/dji0"
    v = Violation.of("HB-003", expected="1.00 Hz", observed="0.61 Hz", topic=f"{unit}/heartbeat")

    def rerun(report: RunReport) -> str:
        lines = [ln for ln in render_violation("HB-003", v, unit, report=report).splitlines()
                 if ln.startswith("  rerun")]
        assert len(lines) == 1
        return lines[0].split(None, 1)[1]

    recorded = RunReport(kind="lint", started=0.0, finished=1.0,
                         meta=RunMeta(source="rec/fleet day.jsonl", recording_lines="10"))
    assert rerun(recorded) == f"waraps-conformance lint --from 'rec/fleet day.jsonl' --unit {unit}"
    piped = RunReport(kind="lint", started=0.0, finished=1.0,
                      meta=RunMeta(source="<stdin>", recording_lines="10"))
    assert rerun(piped) == f"waraps-conformance lint --from '<recording>' --unit {unit}"
    live = RunReport(kind="lint", started=0.0, finished=1.0,
                     broker="mqtts://alice:s3cret@broker.example:8883",
                     meta=RunMeta(source="live waraps/#"))
    assert rerun(live) == (f"waraps-conformance lint --broker mqtts://alice@broker.example:8883 "
                           f"--unit {unit}")
    tls = BrokerURL.parse("mqtts://127.0.0.1:8883").with_tls_files(
        "certs/my ca.pem", None, None, insecure=True).tls_arguments()
    assert tls == ["--ca-file='certs/my ca.pem'", "--tls-insecure"]
    live_tls = RunReport(kind="lint", started=0.0, finished=1.0, broker="mqtts://127.0.0.1:8883",
                         meta=RunMeta(source="live waraps/#", tls_options=" ".join(tls)))
    assert rerun(live_tls) == ("waraps-conformance lint --broker mqtts://127.0.0.1:8883 "
                               f"--ca-file='certs/my ca.pem' --tls-insecure --unit {unit}")
    certification = RunReport(kind="certification", started=0.0, finished=1.0)
    assert rerun(certification) == f"pytest --unit {unit} -k HB-003"


def test_junit_of_a_lint_says_to_rerun_the_lint(run_report: RunReport):
    from conformance.reporting.junitreport import to_junit

    text = to_junit(run_report)  # a live lint (it has a broker and no recording)
    assert "waraps-conformance lint --broker mqtts://alice@127.0.0.1:8883 --unit" in text
    assert "rerun     pytest" not in text  # (skips of active rules do point to pytest)


def test_summary_names_failing_rules(run_report: RunReport):
    text = render_summary(run_report)
    assert "HB-003" in text and "fail" in text


def test_rate_plot_clips_a_burst_and_says_so():
    from conformance.reporting.htmlreport import rate_plot
    from conformance.results import RateStat

    stat = RateStat(unit="u", kind="heartbeat", topic="t", declared_hz=1.0, measured_hz=500.0,
                    intervals=3, mean_interval=0.002, min_interval=0.001, max_interval=1.0,
                    verdict=Verdict.FAIL, series=[(0.0, 1.0), (1.0, 1000.0), (2.0, 1.0)],
                    rule="HB-003", start=0.0, end=2.0, tolerance=0.2)
    svg = rate_plot(stat, 0)
    assert "clipped at 4 Hz" in svg and "declared 1.00 Hz" in svg


def test_html_opens_with_verdict_levels_and_failing_rules(run_report: RunReport):
    page = render_html(run_report)
    summary = page.index('<table class="summary">')
    assert summary < page.index('<table class="head">')  # before the header facts
    head = page[summary:page.index('<details class="fold">')]  # before the folded rule table
    assert "fail</span>" in head and "What failed" in head
    assert "HB-003" in head  # the failing rule, with its evidence
    # Each unit as lint observed it, never a certificate (conformance.conclusion).
    assert "rule(s) failed in 49 s observed, never commanded" in head
    # dji0 stops at 14 s with no command before it (HB-012's decided 'no-command')
    assert "never commanded; its heartbeat stopped at" in head
    assert "certified" not in head.replace("not certified", "")
    slow = next(n for n in run_report.units if n.endswith("piraya0"))
    assert f'id="u-{slow.replace("/", "-")}-HB-003"' in page


def test_html_header_facts_once_each_in_words(run_report: RunReport):
    run_report.meta = RunMeta(unit="waraps/unit/air/simulation/dji0", timing_scale="1",
                              rerun="pytest --unit x --seed 1", exit_status="1")
    page = render_html(run_report)
    head = page[page.index('<table class="head">'):page.index("</table>",
                                                                 page.index('class="head"'))]
    assert "timing scale" in head and "timing_scale" not in head
    assert "repeat this run" in head
    assert head.count(">broker<") == 1 and head.count(">started<") == 1
    assert ">unit<" not in head and head.count(">exit status<") == 1


def test_html_footer_names_the_files_written_with_it(run_report: RunReport, tmp_path):
    page = write_all(run_report, tmp_path, "run")["html"].read_text()
    assert "written together with run.json, from the same results" in page
    assert "JUnit" not in page.split("</table>")[-1]
    assert "run.xml" in write_all(run_report, tmp_path, "run", junit=True)["html"].read_text()
    assert "written on its own" in render_html(run_report)


@pytest.mark.parametrize(("facts", "verdict"), [
    ({"error": "cannot reach the broker at mqtt://127.0.0.1:1"}, "not certified"),
    ({"broker_lost": 1700000006.0}, "not certified"),
    ({"interrupted": True, "cut_short": "--max-duration 60 s reached"}, "interrupted"),
    ({"selection": "-k 'HB-003 or HB-012'"}, "fail")])
def test_a_run_that_did_not_complete_never_reads_as_a_pass(run_report: RunReport, facts: dict,
                                                          verdict: str, tmp_path):
    """The verdict comes from the run's facts (conformance.conclusion), in every output."""
    run_report.kind = "certification"
    run_report.facts = RunFacts(**facts)
    page = render_html(run_report)
    title = page[page.index("<h1>"):page.index("</h1>")]
    assert verdict in title and "pass" not in title
    assert "— certified" not in page  # no level reads certified
    data = orjson.loads(write_all(run_report, tmp_path, "run")["json"].read_bytes())
    assert data["verdict"] == verdict and data["partial"] is True
    assert data["conclusion"]["why"]
    props = to_junit(run_report)
    assert f'name="verdict" value="{verdict}"' in props
    assert 'name="partial" value="true"' in props


def test_every_writer_writes_a_topic_holding_a_lone_surrogate(tmp_path):
    """Found by fuzz/message_path: a topic with a lone surrogate (TOPIC-008's case) failed the
    JSON report (orjson refuses it); it is written with the surrogate as a backslash escape."""
    import json as json_module

    from conformance.checks import Monitor
    from conformance.message import Message
    from conformance.reporting import write_html, write_json, write_junit

    monitor = Monitor(kind="lint")
    topic = "waraps/unit/air/simulation/dj\udff5/heartbeat"
    monitor.feed(Message(1_763_700_000.0, topic, b"{}"))
    monitor.finish(1_763_700_001.0)
    report = monitor.report(broker="", started=1_763_700_000.0, finished=1_763_700_001.0)
    write_html(report, tmp_path / "r.html")
    write_junit(report, tmp_path / "r.xml")
    text = write_json(report, tmp_path / "r.json").read_text()
    assert "dj\\\\udff5" in text and json_module.loads(text)["units"]


def test_the_html_report_plots_a_rate_whose_messages_came_at_one_instant(tmp_path):
    """Found by fuzz/message_path: heartbeats all at one instant made the rate plot's time axis
    zero wide (a ZeroDivisionError writing the HTML report)."""
    import orjson

    from conformance.checks import Monitor
    from conformance.message import Message
    from conformance.reporting import write_html

    monitor = Monitor(kind="lint")
    t = 1_763_700_000.0
    heartbeat = orjson.dumps({"agent-type": "air", "agent-uuid": "u", "levels": ["sensor"],
                              "name": "dji0", "rate": 1.0, "stamp": t, "type": "HeartBeat"})
    for _ in range(6):
        monitor.feed(Message(t, "waraps/unit/air/simulation/dji0/heartbeat", heartbeat))
    monitor.finish(t)
    report = monitor.report(broker="", started=t, finished=t)
    assert "<svg" in write_html(report, tmp_path / "r.html").read_text()


def test_the_html_names_the_unit_first_and_each_failure_has_its_rerun_and_grouped_evidence():
    """A certification of one unit: the first screen names the unit and its verdict; a
    failure shows the rerun line the terminal printed; violations alike (each unanswered
    ping, twenty heartbeats with the same wrong type) are one group, the rest folded."""
    from conformance.results import UnitReport
    from conformance.violation import RuleResult

    unit = "waraps/unit/air/simulation/dji0"
    pings = [Violation("EXEC-PING-001", f"an answer to ping (com-uuid {u}) within 1.5 s",
                       "no answer", topic=f"{unit}/exec/command", time=1_700_000_000.0 + i)
             for i, u in enumerate(["584546bd-edf6-4580-92b2-f522d5e3c180",
                                    "50834474-345d-4b86-bc46-085a4ede3876",
                                    "16f7426a-7539-4007-96f2-7fb1d3fdb010"])]
    other = Violation("EXEC-PING-001", "a response 'pong' within 1.5 s", "no response",
                      topic=f"{unit}/exec/response", time=1_700_000_005.0)
    rules = {"EXEC-PING-001": RuleResult("EXEC-PING-001", Verdict.FAIL, "", [other, *pings])}
    report = RunReport("certification", 1_700_000_000.0, 1_700_000_010.0, units={unit: UnitReport(
        unit, "air", "simulation", "dji0", levels=["sensor"], rules=rules)})
    rerun = f"pytest --unit {unit} --broker mqtt://127.0.0.1:1883 --seed 3 -k EXEC-PING-001"
    report.meta = RunMeta(unit=unit, rerun_of={"EXEC-PING-001": rerun})
    page = render_html(report)
    first = page[:page.index("What failed")]
    assert f'<span class="mono">{unit}</span>' in first and "fail</span>" in first
    failure = page[page.index('id="u-waraps-unit-air-simulation-dji0-EXEC-PING-001"'):]
    assert f"<b>rerun</b> <code>{rerun}</code>" in failure
    assert failure.count('<table class="violation">') == 4  # each kept, none lost
    assert "2 more like it, the last at 2023-11-14T22:13:22.000+00:00" in failure
    assert "rerun " + "EXEC-PING-001" not in page[page.index('<table class="head">'):]

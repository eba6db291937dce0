"""The certification HTML as a person reads it: the verdict and each level, then
what failed with its evidence and basis, then what could not be tested and the option that
would test it; the rule table and the run's facts folded below. Screenshots of a failing, a
could-not-test and a passing run are kept in ``reports/test-artefacts/`` (look at them)."""

from __future__ import annotations

import os
import shutil
import uuid
from pathlib import Path

import orjson
import pytest

from conformance.checks import Monitor
from conformance.client import Message
from conformance.facts import RunFacts
from conformance.judge import judge
from conformance.reporting.htmlreport import render_html
from conformance.results import RunReport
from conformance.topics import UnitAddress
from conformance.violation import Observed

T0 = 1_700_000_000.0
REBOOT_REASON = ("no way to reboot the unit: pass --reboot-cmd 'COMMAND' (a shell command "
                 "that restarts it)")
ARTEFACTS = Path(os.environ.get("WARAPS_TEST_ARTEFACTS",
                                Path(__file__).parents[2] / "reports" / "test-artefacts"))


def certification(prefix: str, *, period: float, reboot: bool, gap: bool = False) -> RunReport:
    """A judged certification of one sensor unit publishing heartbeats (and its four
    mandatory sensors) every ``period`` s (it declares 1 Hz); without ``reboot`` the REBOOT
    rules could not be tested."""
    unit = UnitAddress(prefix, "air", "simulation", "dji0")
    m = Monitor(kind="certification")
    agent = str(uuid.uuid4())
    for i in range(20):
        t = T0 + i * period
        m.feed(Message(t, unit.topic("heartbeat"), orjson.dumps({
            "agent-type": "air", "agent-uuid": agent, "levels": ["sensor"], "name": "dji0",
            "rate": 1.0, "stamp": t, "type": "HeartBeat"})))
        # 6.1's four mandatory sensors, which a unit of the sensor level publishes (SI-004)
        m.feed(Message(t + 0.01, unit.topic("sensor/position"), orjson.dumps(
            {"latitude": 58.4, "longitude": 15.6, "altitude": 10.0})))
        for k, name in enumerate(("heading", "course", "speed")):
            m.feed(Message(t + 0.02 + 0.01 * k, unit.topic(f"sensor/{name}"), b"1.0"))
    for rule in ("REBOOT-001", "REBOOT-002"):
        m.record(unit, rule, seen=Observed.EXAMINED if reboot else Observed.UNTESTABLE,
                 reason="rebooted" if reboot else REBOOT_REASON)
    m.finish()
    report = m.report()
    if gap:
        report.gaps = [(T0 + 3.0, T0 + 3.0), (T0 + 5.0, T0 + 7.5)]
    return judge(report, RunFacts(kind="certification", unit=str(unit)))


def opening(page: str) -> str:
    """What is shown before the folded rule table."""
    return page[:page.index('<details class="fold">')]


def test_a_failing_run_opens_with_the_failing_rule_its_evidence_and_basis(prefix: str) -> None:
    page = render_html(certification(prefix, period=3.5, reboot=True))
    top = opening(page)
    assert "What failed" in top and "HB-003" in top
    assert "expected" in top and "observed" in top  # the evidence itself, not a link to it
    assert '<div class="basis"><b>stated</b>' in top  # and its basis
    assert "Could not be tested" not in top
    assert 'aria-label="heartbeat rate"' in top  # the rate over time, with its evidence
    assert page.index("What failed") < page.index('<table class="head">')  # metadata below


def test_a_could_not_test_run_names_the_rules_the_reason_and_the_option(prefix: str) -> None:
    page = render_html(certification(prefix, period=1.0, reboot=False))
    top = opening(page)
    assert "What failed" not in top
    section = top[top.index("Could not be tested"):]
    assert "REBOOT-001, REBOOT-002" in section and "--reboot-cmd" in section
    assert "not certified" in top


def test_a_rate_rule_shows_its_intervals_as_a_small_plot(prefix: str) -> None:
    page = render_html(certification(prefix, period=1.0, reboot=True))
    row = page[page.index('<td class="mono">HB-003</td>'):]
    row = row[:row.index("</tr>")]
    assert '<svg class="spark"' in row and "examined" not in row, row
    assert "1.00 Hz over 19 intervals, declared 1.00 Hz" in row


def test_a_zero_length_observer_gap_is_not_shown(prefix: str) -> None:
    page = render_html(certification(prefix, period=1.0, reboot=True, gap=True))
    head = page[page.index('<table class="head">'):]
    assert "(2.5 s)" in head  # the real gap
    assert "(0.0 s)" not in head


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="needs chromium: apt-get install -y chromium")
def test_screenshots_of_a_failing_a_could_not_test_and_a_passing_run(
        prefix: str, tmp_path: Path) -> None:
    """Rendered by headless Chromium as a person would see them, kept as artefacts."""
    from test_html_browser import chromium  # rootdir-relative import (rootdir conftest)

    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    runs = {"failing": certification(prefix, period=3.5, reboot=True),
            "could-not-test": certification(prefix, period=1.0, reboot=False),
            "passing": certification(prefix, period=1.0, reboot=True)}
    for name, report in runs.items():
        page = tmp_path / f"{name}.html"
        page.write_text(render_html(report))
        png = ARTEFACTS / f"certification-{name}.png"
        png.unlink(missing_ok=True)
        chromium(tmp_path, "--window-size=1100,900", f"--screenshot={png}", page.as_uri())
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        dom = chromium(tmp_path, "--dump-dom", page.as_uri())
        verdict = {"failing": "fail", "could-not-test": "not certified",
                   "passing": "certified"}[name]
        assert verdict in dom

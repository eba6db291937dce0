"""The HTML report as a person sees it: rendered by headless Chromium, no network, no script.

Chromium: `apt-get install -y chromium` (Debian 12). Skipped with that hint when missing.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from conformance.reporting import write_all
from conformance.results import RunReport

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None,
                                reason="needs chromium: apt-get install -y chromium")

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-extensions"]


def chromium(tmp_path, *args: str) -> str:
    profile = tmp_path / "chrome-profile"
    done = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def visible_text(dom: str) -> str:
    dom = re.sub(r"<style>.*?</style>", "", dom, flags=re.S)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", dom))


def test_a_person_sees_verdicts_rates_and_escaped_evidence(run_report: RunReport, tmp_path):
    html = write_all(run_report, tmp_path / "out", "run")["html"]
    dom = chromium(tmp_path, "--dump-dom", html.as_uri())
    # The DOM Chromium built has no element that came from the payload.
    assert "<script" not in dom and "<img" not in dom
    text = visible_text(dom)
    slow = next(n for n in run_report.units if n.endswith("piraya0"))
    for seen in ("WARA-PS conformance lint report", slow, "mqtts://alice@127.0.0.1:8883",
                 "heartbeat rate matches its declared rate", "5.1 General Heartbeat Message",
                 "could-not-test", "no reboot command", "declared 1.00 Hz", "What failed"):
        assert seen in text, seen
    assert "s3cret" not in dom
    # The hostile payload is shown as text, as it was on the wire.
    assert '&lt;script&gt;alert("x")&lt;/script&gt;' in dom
    assert dom.count("<svg") >= 2  # one rate plot per unit


def test_screenshot_renders(run_report: RunReport, tmp_path):
    html = write_all(run_report, tmp_path / "out", "run")["html"]
    png = tmp_path / "shot.png"
    chromium(tmp_path, "--window-size=1200,1600", f"--screenshot={png}", html.as_uri())
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


# Each would change the page's title if it ran: in text, in an attribute, closing a <pre>.
PWN = "document.title='PWNED'"
HOSTILE = (f"<script>{PWN}</script>", f'"><img src=x onerror="{PWN}">',
           f"</pre><svg onload=\"{PWN}\"></svg>", f"'><iframe srcdoc='<script>{PWN}</script>'>")


def hostile_report() -> RunReport:
    """A report whose wire-borne fields all hold markup: the unit name, a topic, a rule detail,
    a payload excerpt, a reason, a rate's kind (in an attribute), and a run fact."""
    from conformance.report_meta import RunMeta, UnitFacts
    from conformance.results import RateStat, UnitReport
    from conformance.violation import RuleResult, Verdict, Violation

    every = " ".join(HOSTILE)
    name = f"waraps/unit/air/simulation/{HOSTILE[1]}"
    violation = Violation("HB-002", expected="HeartBeat", observed=every,
                          topic=f"{name}/heartbeat", path=f"$.{HOSTILE[0]}",
                          excerpt=every, detail=every, time=1_700_000_000.0)
    unit = UnitReport(name, agent_type=HOSTILE[2], role=HOSTILE[3], name=HOSTILE[0],
                      agent_uuids=[HOSTILE[1]], levels=[HOSTILE[2]], message_count=3,
                      rules={"HB-002": RuleResult("HB-002", Verdict.FAIL, every, [violation]),
                             "HB-003": RuleResult("HB-003", Verdict.WARN, every, [])},
                      rates=[RateStat(unit=name, kind=f"sensor/{HOSTILE[1]}", topic=name,
                                      declared_hz=1.0, measured_hz=0.5, intervals=12,
                                      mean_interval=2.0, min_interval=1.9, max_interval=2.1,
                                      verdict=Verdict.FAIL, series=[(0.0, 0.5), (2.0, 0.5)],
                                      rule="HB-003", reason=every, start=0.0, end=2.0)],
                      facts=UnitFacts(sensors_listed=HOSTILE))
    return RunReport(kind="lint", started=1_700_000_000.0, finished=1_700_000_010.0,
                     units={name: unit}, meta=RunMeta(rerun=every, source=every, unit=name,
                                                      rerun_of={"HB-002": every}))


def page_title(dom: str) -> str:
    found = re.search(r"<title>(.*?)</title>", dom, flags=re.S)
    assert found, dom[:500]
    return found.group(1)


def test_hostile_markup_is_shown_as_text_and_never_runs(tmp_path):
    report = hostile_report()
    html = write_all(report, tmp_path / "out", "run")["html"]
    dom = chromium(tmp_path, "--virtual-time-budget=2000", "--dump-dom", html.as_uri())
    assert page_title(dom) == "WARA-PS conformance lint report"  # no script changed it
    for element in ("<script", "<img", "<iframe", "<svg onload"):
        assert element not in dom, element
    text = visible_text(dom).replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&")
    for shown in HOSTILE:  # as it was on the wire, in the unit name, evidence and rate caption
        assert text.count(shown) >= 5, shown
    # the rate plot (with HB-003's evidence and in the unit's rates) and HB-003's small plot
    # in its scorecard row, the hostile kind in their aria-labels
    assert dom.count("<svg") == 3


def test_the_probe_sees_a_script_that_runs(tmp_path):
    """The same Chromium and probe catch markup that was not escaped (the test above can fail)."""
    page = tmp_path / "raw.html"
    page.write_text("<!DOCTYPE html><html><head><title>WARA-PS conformance lint report</title>"
                    "</head><body><pre>" + HOSTILE[1] + "</pre></body></html>")
    dom = chromium(tmp_path, "--virtual-time-budget=2000", "--dump-dom", page.as_uri())
    assert page_title(dom) == "PWNED" and "<img" in dom

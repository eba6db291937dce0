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
                 "could-not-test", "no reboot command", "declared 1.00 Hz", "Evidence"):
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

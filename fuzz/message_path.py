"""Fuzz target: the message path itself: topics and payloads (a few messages of one or two
units, at fuzzed times) through ``Monitor.feed``, then the run report and every report writer
(JSON, HTML, JUnit, the text summary and verdicts), as a lint run writes them.

Invariant: the Monitor judges every message without raising; every writer writes without
raising; the reports stay proportional to the input (a name is stored once, not once per rule);
time proportional to the input.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

import atheris

from conformance.checks import Monitor
from conformance.message import Message
from conformance.reporting import write_html, write_json, write_junit
from conformance.reporting.text import render_summary, render_verdicts
from fuzz.harness import proportional, within_time
from fuzz.recorded import T0, payload, topic

OUT = Path(tempfile.mkdtemp(prefix="fuzz-reports-"))
atexit.register(shutil.rmtree, OUT, True)
REPORT_BASE = 4 << 20
"""The reports of one unit that sent nothing odd: every rule's row (~1 MB of HTML)."""


def prepare() -> None:
    """Render the templates once, instrumented."""
    _write(Monitor(kind="lint"))


def _write(monitor: Monitor) -> int:
    report = monitor.report(broker="", started=T0, finished=T0 + 60)
    size = 0
    for write, name in ((write_json, "r.json"), (write_html, "r.html"), (write_junit, "r.xml")):
        size += Path(write(report, OUT / name)).stat().st_size
    return size + len(render_summary(report)) + len(render_verdicts(report))


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    with within_time(len(data)):
        monitor = Monitor(kind="lint")
        t = T0
        for _ in range(fdp.ConsumeIntInRange(1, 12)):
            t += fdp.ConsumeFloatInRange(0.0, 5.0)
            monitor.feed(Message(t, topic(fdp), payload(fdp)))
        monitor.finish(t + 1.0)
        size = _write(monitor)
    proportional(size, len(data), factor=4096, base=REPORT_BASE, what="the reports")

"""Reports of a run, all fed by the same ``RunReport``: JSON, one self-contained HTML file,
JUnit XML, and text for people. Every file is written atomically (temp file + rename)."""

from __future__ import annotations

import os
from pathlib import Path

from conformance.reporting.files import atomic_write
from conformance.reporting.htmlreport import render_html, write_html
from conformance.reporting.jsonreport import read_json, write_json
from conformance.reporting.junitreport import to_junit, write_junit
from conformance.reporting.text import render_summary, render_violation
from conformance.results import RunReport

__all__ = ["atomic_write", "read_json", "render_html", "render_summary", "render_violation",
           "to_junit", "write_all", "write_html", "write_json", "write_junit"]


def write_all(report: RunReport, directory: str | os.PathLike[str], stem: str,
              junit: bool = False) -> dict[str, Path]:
    """Write ``<stem>.json`` and ``<stem>.html`` (and ``<stem>.xml`` JUnit when asked) into
    ``directory``; the paths by format. Cheap and safe to call repeatedly (each file is
    replaced atomically, so a reader never sees half a report)."""
    directory = Path(directory)
    others = [f"{stem}.json"] + ([f"{stem}.xml"] if junit else [])
    paths = {"json": write_json(report, directory / f"{stem}.json"),
             "html": write_html(report, directory / f"{stem}.html", others)}
    if junit:
        paths["junit"] = write_junit(report, directory / f"{stem}.xml")
    return paths

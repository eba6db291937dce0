"""The JSON report: ``RunReport.to_dict()`` as a file, and back."""

from __future__ import annotations

import os
from pathlib import Path

import orjson

from conformance.conclusion import conclude
from conformance.reporting.files import atomic_write
from conformance.results import RunReport


def dumps(report: RunReport) -> bytes:
    # Non-finite floats become null in orjson; wire strings are stored as they are (JSON-escaped).
    data = report.to_dict()
    # The one verdict model (conformance.conclusion): the run's verdict, whether it is
    # partial and why, each unit's status and levels, the counts every output shows.
    conclusion = conclude(report)
    data["verdict"] = conclusion.verdict
    data["partial"] = conclusion.partial
    data["conclusion"] = conclusion.to_dict()
    return orjson.dumps(data, option=orjson.OPT_INDENT_2 | orjson.OPT_SORT_KEYS
                        | orjson.OPT_NON_STR_KEYS) + b"\n"


def write_json(report: RunReport, path: str | os.PathLike[str]) -> Path:
    """Write the report as JSON (atomically); the path written."""
    return atomic_write(path, dumps(report))


def read_json(path: str | os.PathLike[str]) -> RunReport:
    """Read a report written by ``write_json``."""
    return RunReport.from_dict(orjson.loads(Path(path).read_bytes()))

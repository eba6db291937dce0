"""The JSON report: ``RunReport.to_dict()`` as a file, and back."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import orjson

from conformance.conclusion import of as conclusion_of
from conformance.display import SHORT_CHARS, shorten
from conformance.reporting.bounds import bounded
from conformance.reporting.files import atomic_write
from conformance.results import RunReport


def dumps(report: RunReport) -> bytes:
    """The report as JSON, at most ``bounds.MAX_REPORT_BYTES`` (``bounds.bounded``)."""
    return bounded(_dumps, report)


def _shortened(value: Any) -> Any:
    """``value`` with every string in it (keys too) excerpted by ``display.shorten``."""
    if isinstance(value, str):
        return value if len(value) <= SHORT_CHARS else shorten(value)
    if isinstance(value, dict):
        out: dict[Any, Any] = {}
        for k, v in value.items():
            if isinstance(k, str) and len(k) > SHORT_CHARS:
                k = shorten(k)
                while k in out:  # two long keys alike in their first characters
                    k += "'"
            out[k] = _shortened(v)
        return out
    if isinstance(value, (list, tuple)):
        return [_shortened(v) for v in value]
    return value


def _dumps(report: RunReport) -> bytes:
    # Non-finite floats become null in orjson; wire strings are excerpted (display.shorten),
    # control characters JSON-escaped.
    data = _shortened(report.to_dict())
    # The one verdict model (conformance.conclusion): the run's verdict, whether it is
    # partial and why, each unit's status and levels, the counts every output shows.
    conclusion = conclusion_of(report)
    data["verdict"] = conclusion.verdict
    data["partial"] = conclusion.partial
    data["conclusion"] = _shortened(conclusion.to_dict())
    option = orjson.OPT_INDENT_2 | orjson.OPT_SORT_KEYS | orjson.OPT_NON_STR_KEYS
    try:
        return orjson.dumps(data, option=option) + b"\n"
    except orjson.JSONEncodeError:  # a lone surrogate in a string from the wire (TOPIC-008)
        return orjson.dumps(_utf8(data), option=option) + b"\n"


def _utf8(value: Any) -> Any:
    """``value`` with every string UTF-8 can carry as it is and the rest's lone surrogates
    as backslash escapes (found by fuzz/message_path: a topic of one failed the report).
    Iterative: no recursion over a report's depth."""
    def fixed(x: Any) -> Any:
        if isinstance(x, str):
            try:
                x.encode("utf-8")
            except UnicodeEncodeError:
                return x.encode("utf-8", "backslashreplace").decode("utf-8")
        return x

    root: list[Any] = [value]
    stack: list[tuple[Any, Any]] = [(root, 0)]
    while stack:
        parent, key = stack.pop()
        item = parent[key]
        if isinstance(item, dict):
            item = parent[key] = {fixed(k): v for k, v in item.items()}
            stack.extend((item, k) for k in item)
        elif isinstance(item, (list, tuple)):
            item = parent[key] = list(item)
            stack.extend((item, i) for i in range(len(item)))
        else:
            parent[key] = fixed(item)
    return root[0]


def write_json(report: RunReport, path: str | os.PathLike[str]) -> Path:
    """Write the report as JSON (atomically); the path written."""
    return atomic_write(path, dumps(report))


def read_json(path: str | os.PathLike[str]) -> RunReport:
    """Read a report written by ``write_json``."""
    return RunReport.from_dict(orjson.loads(Path(path).read_bytes()))

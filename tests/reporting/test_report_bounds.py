"""Reports are bounded whatever the input: every string excerpted with a visible
ellipsis and its full length, every file under ``bounds.MAX_REPORT_BYTES`` (past it, a note in
the file says what was left out, and the file stays whole), and writing thousands of units
stays linear (figures: bench/bench_memory.py)."""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET

import orjson
import pytest

from conformance.checks import Monitor
from conformance.display import SHORT_CHARS
from conformance.message import Message
from conformance.reporting import bounds, write_all
from conformance.reporting.bounds import TRUNCATED
from conformance.topics import UnitAddress

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parents[1] / "lint"))
from lint_helpers import T0, unit_traffic  # noqa: E402

MIB = 1 << 20


def _files(paths) -> dict[str, bytes]:
    return {kind: path.read_bytes() for kind, path in paths.items()}


def _whole(files: dict[str, bytes]) -> None:
    """Each file parses: never a broken file."""
    json.loads(files["json"])
    ET.fromstring(files["junit"])
    assert files["html"].rstrip().endswith(b"</html>")


def test_a_1_mib_unit_name_is_excerpted_in_every_report(tmp_path, prefix):
    name = "dji0" + "X" * MIB
    m = Monitor(kind="lint")
    for msg in unit_traffic(prefix, name, seconds=2):
        m.feed(msg)
    m.feed(Message(T0 + 1.5, f"{prefix}/unit/air/simulation/dji0/sensor/" + "Y" * MIB, b"1"))
    m.finish(T0 + 2)
    files = _files(write_all(m.report(), tmp_path, "run", junit=True))
    _whole(files)
    full = len(f"{prefix}/unit/air/simulation/{name}")
    for kind, data in files.items():
        assert len(data) < 2 * MIB, (kind, len(data))  # was 48 MB HTML, 168 MB JUnit
        assert f"… ({full} chars)".encode() in data, kind  # visible ellipsis, full length
        assert b"X" * (SHORT_CHARS + 1) not in data and b"Y" * (SHORT_CHARS + 1) not in data, kind


@pytest.fixture
def fleet_report(prefix):
    m = Monitor(kind="lint")
    msgs = []
    for i in range(60):
        msgs += unit_traffic(prefix, f"u{i:02d}" if i != 7 else "bad7", seconds=12)
    for msg in sorted(msgs, key=lambda x: x.time):
        m.feed(msg)
    bad = UnitAddress(prefix, "air", "simulation", "bad7")
    for k in range(50):  # bad7 fails TOPIC-002 50 times: evidence to cut
        m.feed(Message(T0 + 11 + k / 100, bad.topic("Bad"), orjson.dumps({"k": k})))
    m.finish(T0 + 12)
    return m.report()


def test_past_the_bound_a_report_says_what_it_left_out_and_stays_whole(
        fleet_report, tmp_path, monkeypatch):
    whole = _files(write_all(fleet_report, tmp_path / "whole", "run", junit=True))
    limit = min(len(b) for b in whole.values()) // 3
    monkeypatch.setattr(bounds, "MAX_REPORT_BYTES", limit)
    files = _files(write_all(fleet_report, tmp_path / "bounded", "run", junit=True))
    _whole(files)
    bad = f"{fleet_report.units and next(n for n in fleet_report.units if n.endswith('bad7'))}"
    for kind, data in files.items():
        assert len(data) <= limit, (kind, len(data), limit)
        text = data.decode()
        assert "units left out to stay under" in text, kind  # a clear note, in the file
        assert bad in text, kind  # the failing unit is kept: the worst first
    note = json.loads(files["json"])["meta"][TRUNCATED]
    assert "each rule shows its first violation only" in note
    kept = json.loads(files["json"])["units"]
    assert 0 < len(kept) < len(fleet_report.units)
    assert kept[bad]["rules"]["TOPIC-002"]["verdict"] == "fail"
    assert len(kept[bad]["rules"]["TOPIC-002"]["violations"]) == 1  # the evidence, cut
    assert kept[bad]["violation_counts"]["TOPIC-002"] == 50  # the count, whole
    assert json.loads(files["json"])["verdict"] == "fail"


def test_under_the_bound_nothing_is_left_out(fleet_report, tmp_path):
    files = _files(write_all(fleet_report, tmp_path, "run", junit=True))
    assert TRUNCATED not in json.loads(files["json"])["meta"]
    assert len(json.loads(files["json"])["units"]) == len(fleet_report.units)
    assert b"left out" not in files["html"] and b"left out" not in files["junit"]

"""What could not be examined is never clean: a message past MSG-004's bounds, a malformed
line, a line marked as UTF-8 by a byte order mark, a declared rate that is no rate."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import orjson
import pytest
from lint_helpers import failed_rules, run_lint, unit_traffic, verdicts, write_recording

from conformance.checks.base import usable_rate
from conformance.cli.lint import main as lint_main
from conformance.client import Message
from conformance.lint import EXIT_FAIL, EXIT_PARTIAL, EXIT_PASS
from conformance.recording import RecordingReader


def _deep(levels: int) -> Any:
    value: Any = 1
    for _ in range(levels):
        value = [value]
    return value


def _with(messages: list[Message], sub: str, **fields: Any) -> list[Message]:
    """``messages`` with ``fields`` set in every payload of topic ``.../sub``."""
    out = []
    for m in messages:
        if m.topic.endswith("/" + sub):
            payload = {**orjson.loads(m.payload), **fields}
            m = Message(m.time, m.topic, orjson.dumps(payload))
        out.append(m)
    return out


def _unit(prefix: str) -> str:
    return f"{prefix}/unit/air/simulation/u0"


def test_a_field_nested_past_the_bound_hides_no_fault(tmp_path: Path, reports_dir: Path,
                                                      prefix: str) -> None:
    # Every second heartbeat missing (HB-003), each carrying one field 65 levels deep: the
    # heartbeats are judged on their other top-level fields, and the rate fails.
    traffic = _with(unit_traffic(prefix, "u0", seconds=30, heartbeat_every=2), "heartbeat",
                    extra=_deep(65))
    run = run_lint(["--from", str(write_recording(tmp_path / "deep.jsonl", traffic))],
                   reports_dir)
    assert run.code == EXIT_FAIL, run.out
    assert run.report is not None
    assert "HB-003" in failed_rules(run.report, _unit(prefix))
    assert run.report["units"][_unit(prefix)]["violation_counts"]["MSG-004"] == 15


def test_a_conformant_unit_with_a_field_past_the_bound_is_partial_never_clean(
        tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    traffic = _with(unit_traffic(prefix, "u0", seconds=30), "heartbeat", extra=_deep(65))
    run = run_lint(["--from", str(write_recording(tmp_path / "deep.jsonl", traffic))],
                   reports_dir)
    assert run.code == EXIT_PARTIAL, run.out
    assert run.report is not None
    conclusion = run.report["conclusion"]
    assert conclusion["verdict"] == "partial" and conclusion["partial"]
    assert conclusion["units"][_unit(prefix)]["verdict"] == "could-not-test"
    assert "could not be examined whole" in conclusion["units"][_unit(prefix)]["summary"]
    assert "PARTIAL:" in run.out and "CLEAN" not in run.out
    # What was read of them still passed: their rate, judged on the top-level fields.
    assert verdicts(run.report, _unit(prefix))["HB-003"] == "pass"
    # Its schema was not examined on them: no pass of HB-001 from a part of a message.
    assert run.report["units"][_unit(prefix)]["rules"]["MSG-004"]["verdict"] == "warn"


def test_malformed_lines_make_the_run_partial(tmp_path: Path, reports_dir: Path,
                                              prefix: str) -> None:
    rec = write_recording(tmp_path / "damaged.jsonl", unit_traffic(prefix, "u0", seconds=30))
    rec.write_bytes(rec.read_bytes() + b"{not json\n" * 3)
    run = run_lint(["--from", str(rec)], reports_dir)
    assert run.code == EXIT_PARTIAL, run.out
    assert run.report is not None and run.report["conclusion"]["verdict"] == "partial"
    assert "3 line(s) of the recording could not be read" in run.out


@pytest.mark.parametrize("faulty", [False, True], ids=["conformant", "faulty"])
def test_a_byte_order_mark_on_every_line_hides_no_unit(tmp_path: Path, reports_dir: Path,
                                                       prefix: str, faulty: bool) -> None:
    rec = write_recording(tmp_path / "plain.jsonl", unit_traffic(
        prefix, "u0", seconds=30, heartbeat_every=2 if faulty else 1))
    marked = tmp_path / "bom.jsonl"
    marked.write_bytes(b"".join(b"\xef\xbb\xbf" + line
                                for line in rec.read_bytes().splitlines(keepends=True)))
    run = run_lint(["--from", str(marked)], reports_dir)
    assert run.code == (EXIT_FAIL if faulty else EXIT_PASS), run.out
    assert run.report is not None and _unit(prefix) in run.report["units"]
    assert "began with a UTF-8 byte order mark" in run.out
    assert ("HB-003" in failed_rules(run.report, _unit(prefix))) is faulty


def test_a_declared_rate_whose_period_is_infinite_is_refused(tmp_path: Path,
                                                             reports_dir: Path,
                                                             prefix: str) -> None:
    traffic = _with(unit_traffic(prefix, "u0", seconds=30), "heartbeat", rate=1e-310)
    run = run_lint(["--from", str(write_recording(tmp_path / "tiny.jsonl", traffic))],
                   reports_dir)
    assert run.code == EXIT_FAIL, run.out
    assert run.report is not None and "HB-003" in failed_rules(run.report, _unit(prefix))
    assert "whose period (1/rate) is a finite number of seconds" in run.out


@pytest.mark.parametrize("rate", [0, -1, 1e-310, 5e-324, float("inf"), float("nan"), True,
                                  10 ** 400, "1"])
def test_usable_rate_refuses_what_has_no_finite_period(rate: Any) -> None:
    assert usable_rate(rate) is None


@pytest.mark.parametrize("rate", [1, 0.5, 1e-300, 1e300])
def test_usable_rate_keeps_rates(rate: float) -> None:
    assert usable_rate(rate) == float(rate)


def test_an_event_detail_nested_1000_deep_is_read(tmp_path: Path) -> None:
    line = (b'{"ts": 1763700000.0, "event": "start", "detail": ' + b"[" * 1000 + b"]" * 1000
            + b"}\n")
    reader = RecordingReader((tmp_path / "x").open("w+b"))
    reader.stream.write(line)
    reader.stream.seek(0)
    events = list(reader)
    assert not reader.problems and len(events) == 1
    assert events[0].detail.startswith("[[[[")


UNWRITABLE = "/proc"
"""A folder that exists and takes no file, whoever runs the tests (root too)."""


def test_a_reports_folder_that_takes_no_file_is_refused_before_the_run(
        tmp_path: Path, prefix: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Once 'verdict: clean', then a traceback, exit 1: now said before anything runs."""
    rec = write_recording(tmp_path / "r.jsonl", unit_traffic(prefix, "u0", seconds=5))
    run = run_lint(["--from", str(rec)], Path(UNWRITABLE))
    err = capsys.readouterr().err
    assert run.code == 2, run.out
    assert f"--reports-dir '{UNWRITABLE}': cannot write a report into it" in err
    assert "verdict:" not in run.out and "Traceback" not in err


def test_reports_that_cannot_be_written_at_the_end_keep_the_run_s_status(
        tmp_path: Path, reports_dir: Path, prefix: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    rec = write_recording(tmp_path / "r.jsonl", unit_traffic(prefix, "u0", seconds=30,
                                                             heartbeat_every=2))
    (reports_dir / "lint-r.json").mkdir(parents=True)  # a folder where the report goes
    out = io.StringIO()
    code = lint_main(["--from", str(rec), "--plain", "--reports-dir", str(reports_dir)],
                     stdout=out)
    err = capsys.readouterr().err
    assert code == EXIT_FAIL, out.getvalue()  # the unit's HB-003: the run's own status
    assert f"could not write the reports into {reports_dir}" in err, err
    assert "Traceback" not in err

"""The hostile corpus: each case run as the console script in a
subprocess under an address-space cap (``hostile.ADDRESS_SPACE``), and for each: no traceback,
an exit status from the documented table, the message that names what and which bound, time
and peak memory within ``hostile.MAX_SECONDS`` and ``hostile.MAX_PEAK_MB``.

The inputs are generated into ``tmp_path`` (``hostile.py``); nothing large is committed.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
from hostile import (
    BAG_DRIVER,
    COMMAND_CASES,
    EXIT_TABLE,
    MAX_PEAK_MB,
    MAX_SECONDS,
    RECORDING_CASES,
    UNIT,
    Case,
    Run,
    bag_codes,
    damaged_bags,
    fleet,
    run_bounded,
    write_case,
)
from machine import deadline

from conformance.lint import EXIT_FAIL, EXIT_NOT_RUN, EXIT_PASS


def _bounded(run: Run, command: str = "lint") -> None:
    assert not run.killed, f"{run.name}: still running after {run.seconds:.0f} s (a hang)"
    assert not run.traceback, f"{run.name}: a traceback\n{run.err[-2000:]}"
    assert run.code in EXIT_TABLE[command], f"{run.name}: exit {run.code}\n{run.err[-2000:]}"
    assert run.peak_mb <= MAX_PEAK_MB, f"{run.name}: peak {run.peak_mb:.0f} MB"


def _check(case: Case, tmp_path: Path) -> Run:
    args, stdin = write_case(case, tmp_path)
    run = run_bounded(case.name, args, tmp_path, stdin=stdin)
    _bounded(run, args[0])
    assert run.code in case.codes, f"{case.name}: exit {run.code}\n{run.out[-2000:]}{run.err}"
    for text in case.says:
        assert text in run.out + run.err, f"{case.name}: {text!r} not said\n{run.out}{run.err}"
    return run


@pytest.mark.parametrize("case", RECORDING_CASES, ids=lambda c: c.name)
def test_a_hostile_recording_line_is_a_finding_and_the_run_goes_on(
        case: Case, tmp_path: Path) -> None:
    run = _check(case, tmp_path)
    if case.codes != {EXIT_NOT_RUN}:  # the good lines around it were judged, a report written
        report = json.loads((tmp_path / "reports" / f"lint-{case.name}.json").read_text())
        assert report["units"][UNIT]["message_count"] >= 20, run.out


@pytest.mark.parametrize("case", COMMAND_CASES, ids=lambda c: c.name)
def test_a_hostile_source_is_refused_or_read_within_its_bounds(
        case: Case, tmp_path: Path) -> None:
    _check(case, tmp_path)


def test_a_mosquitto_v_capture_is_judged_except_what_needs_times(tmp_path: Path) -> None:
    """The format is told from the content and named; the rate rules are
    could-not-test 'no timestamps' (HB-003 would fail with times: every second heartbeat is
    missing), the rest is judged (HB-002 fails, HB-001 passes)."""
    case = next(c for c in COMMAND_CASES if c.name == "mosquitto-v-capture")
    _check(case, tmp_path)
    report = json.loads((tmp_path / "reports" / "lint-capture.json").read_text())
    rules = report["units"][UNIT]["rules"]
    assert report["meta"]["recording_formats"] == "mosquitto_sub -v"
    for rule in ("HB-003", "MSG-005", "HB-012"):
        assert rules[rule]["verdict"] == "could-not-test", rules[rule]
        assert rules[rule]["reason"].startswith("not judged: no timestamps")
    assert rules["HB-002"]["verdict"] == "fail" and rules["HB-001"]["verdict"] == "pass"
    assert "malformed" not in (tmp_path / "mosquitto-v-capture.out").read_text()


def test_a_mosquitto_v_capture_says_it_has_no_times_first_and_shows_no_rate(
        tmp_path: Path) -> None:
    """The note comes before the verdicts; no rate, no 'clean for 0 s', no
    'in 0 s observed', no time of a finding (the reading's times are not the traffic's)."""
    case = next(c for c in COMMAND_CASES if c.name == "mosquitto-v-capture")
    case = dataclasses.replace(case, args=(*case.args[:-1], "json,html"))
    out = _check(case, tmp_path).out
    lines = out.splitlines()
    note = next(i for i, ln in enumerate(lines) if ln.startswith("note: a mosquitto_sub -v"))
    verdict = next(i for i, ln in enumerate(lines) if ln.startswith("verdict: "))
    assert note < verdict, out
    assert sum(ln.startswith("note: a mosquitto_sub -v") for ln in lines) == 1, out
    assert " 0 s" not in out and "msg/s" not in out.lower().replace("msg/s last", ""), out
    assert "1 rule(s) failed (no times in the capture), never commanded" in out
    row = next(ln for ln in lines if ln.startswith(UNIT + " ") and "FAIL" in ln)
    assert row.split()[:5] == [UNIT, "air", "simulation", "sensor", "FAIL"], row
    assert "HB-002 heartbeat type is 'HeartBeat': 1x\n" in out + "\n", out
    html = (tmp_path / "reports" / "lint-capture.html").read_text()
    assert "<th>seen</th><td>no times in the capture</td>" in html
    assert "clean for" not in html and "0 s observed" not in html


def test_a_recording_with_times_is_not_untimed_by_one_line_that_looks_like_v(
        tmp_path: Path) -> None:
    case = next(c for c in RECORDING_CASES if c.name == "ts-1e17")
    odd = Case("odd-v-line", case.data.replace(
        b"\n", b"\n" + f"{UNIT}/heartbeat {{}}".encode() + b"\n", 1),
        says=("malformed line 2: a mosquitto_sub -v line (TOPIC PAYLOAD) among lines with "
              "times",))
    _check(odd, tmp_path)
    report = json.loads((tmp_path / "reports" / "lint-odd-v-line.json").read_text())
    assert report["meta"]["recording_formats"] == "jsonl"
    assert report["units"][UNIT]["rules"]["MSG-005"]["verdict"] == "pass"


@pytest.mark.slow
def test_a_fleet_past_the_unit_bound_fails_naming_what_was_not_judged(tmp_path: Path) -> None:
    """100k units (a generated recording), every unit the linter judges conformant and the
    last one faulty: never a pass. Reports are not written here (their size is bounded
    elsewhere)."""
    path = fleet(tmp_path)
    run = run_bounded("fleet", ["lint", "--from", str(path), "--plain", "--format", "none"],
                      tmp_path)
    _bounded(run)
    assert run.code == EXIT_FAIL
    assert ("FAIL: not judged: 95904 messages of units past the 4096 units lint judges at "
            "once (waraps/unit/air/simulation/u4096, ") in run.out
    assert "lint them apart with --unit ADDRESS or --topic FILTER" in run.out
    assert "FAIL: waraps" not in run.out  # the units judged all pass: the bound alone fails


def test_a_fleet_within_the_unit_bound_is_judged_whole(tmp_path: Path) -> None:
    """The same fleet, smaller: its last unit's fault is found, the others pass."""
    path = fleet(tmp_path, 50)
    run = run_bounded("fleet", ["lint", "--from", str(path), "--plain", "--format", "none"],
                      tmp_path)
    _bounded(run)
    assert run.code == EXIT_FAIL and "not judged" not in run.out
    assert "FAIL: waraps/unit/air/simulation/u49\n" in run.out


@pytest.mark.parametrize("storage", ["ros1", "sqlite3", "mcap"])
def test_a_damaged_bag_never_yields_a_verdict_on_part_of_it(storage: str,
                                                             tmp_path: Path) -> None:
    """A failing bag damaged at 16 offsets, cut off, or (ROS 2) with a
    metadata.yaml that claims more than was stored: each fails on what it holds (exit 1) or
    is refused (exit 3), never passes; a short read says so and how to fix it."""
    src, copies = damaged_bags(tmp_path, storage, 16)
    whole = run_bounded(f"{storage}-whole", [str(src)], tmp_path, script=BAG_DRIVER)
    _bounded(whole)
    assert bag_codes(whole)[0][1] == EXIT_FAIL, whole.out
    run = run_bounded(f"{storage}-damaged", [str(p) for p in copies], tmp_path,
                      script=BAG_DRIVER)
    _bounded(run)
    codes = bag_codes(run)
    assert len(codes) == len(copies)
    for bag, code, err in codes:
        assert code in (EXIT_FAIL, EXIT_NOT_RUN), f"{bag}: {code} {err}"
        assert code != EXIT_PASS
        if code == EXIT_NOT_RUN:
            assert "Fix:" in err, err  # what, where (the bag's path) and how to fix it
    if storage != "ros1":
        bag, code, err = codes[-1]  # the metadata.yaml that claims 3 more messages
        assert code == EXIT_NOT_RUN and "nothing was judged" in err, err


def test_every_bound_is_named_in_help() -> None:
    from conformance import bounds
    from conformance.cli.lint import build_parser

    text = " ".join(build_parser().format_help().split())
    for said in (f"line up to {bounds.MAX_LINE_BYTES >> 20} MiB",
                 f"as declared (payloadlen) up to {bounds.MAX_PAYLOAD_BYTES >> 20} MiB",
                 f"{bounds.MAX_NESTING} levels", "times from 1970 to 2100",
                 f"At most {bounds.MAX_UNITS} units are judged", "-v",
                 "read whole or refused (exit 3)"):
        assert said in text, said
    assert f"at most {bounds.MAX_VALIDATE_BYTES >> 20} MiB are read" in bounds.bounds_help(
        validate=True)


def test_the_untimed_rules_are_rules_of_the_catalogue() -> None:
    from conformance.recording import UNTIMED_RULES
    from conformance.rules import CATALOGUE

    assert set(UNTIMED_RULES) <= set(CATALOGUE)
    assert {"HB-003", "SI-002", "DEI-002", "TEI-002"} <= set(UNTIMED_RULES)  # every rate rule


def test_an_endless_stream_on_standard_input_is_read_in_bounded_memory(tmp_path: Path) -> None:
    """``lint --from -`` is a stream (a live mosquitto_sub pipe): /dev/zero, one endless line,
    is read without holding it (the line bound), until Ctrl-C; then nothing was judged."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from hostile import PEAK_WRAPPER, _cap

    peak = tmp_path / "peak"
    with open("/dev/zero", "rb") as zero:
        proc = subprocess.Popen([sys.executable, "-c", PEAK_WRAPPER, str(peak), "", "lint",
                                 "--from", "-", "--plain", "--format", "none"], stdin=zero,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                preexec_fn=_cap, cwd=tmp_path)
    try:
        hung = time.monotonic() + deadline(MAX_SECONDS)
        read = 0
        while read < 3 * (64 << 20):  # three times the line bound: the line is not held
            assert proc.poll() is None and time.monotonic() < hung, read
            with open(f"/proc/{proc.pid}/io") as io:
                read = int(next(ln for ln in io if ln.startswith("rchar")).split()[1])
            time.sleep(0.05)  # polling a condition (with a deadline), not waiting a duration
        os.kill(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=deadline(MAX_SECONDS))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert b"Traceback" not in err, err.decode()
    assert proc.returncode == EXIT_NOT_RUN and b"no messages were read" in err
    assert float(peak.read_text()) / 1024 <= MAX_PEAK_MB


def test_random_damage_to_a_recording_is_never_a_traceback(tmp_path: Path) -> None:
    """120 recordings damaged at random (bytes overwritten, deleted, inserted: quotes,
    backslashes, lone surrogates, bytes that are not UTF-8, NUL, huge numbers), each linted
    with every report written: an exit status from the table, never a traceback (a topic of
    bytes that are not UTF-8 once crashed the JSON report)."""
    from hostile import MUTATION_DRIVER

    run = run_bounded("mutations", [str(Path(__file__).parent), "19", "120"], tmp_path,
                      script=MUTATION_DRIVER)
    _bounded(run)
    codes = bag_codes(run)
    assert len(codes) == 120
    bad = [(path, code) for path, code, _ in codes if code not in EXIT_TABLE["lint"]]
    assert not bad, bad[:3]


def test_formats_are_told_per_line(tmp_path: Path) -> None:
    """One ``-F %J`` line before a conformant unit's ``-F %j`` lines: each line is
    read in its own format, so the heartbeats are objects (no MSG-003) and the unit is clean."""
    from hostile import mixed_j_and_jj

    case = Case("mixed-j-and-jj", args=("lint", "--from", "{file}", "--plain", "--format",
                                        "json"), make=mixed_j_and_jj, codes=frozenset({0}))
    _check(case, tmp_path)
    report = json.loads((tmp_path / "reports" / "lint-mixed.json").read_text())
    assert report["meta"]["recording_formats"] == "mosquitto_sub -F %J, mosquitto_sub -F %j"
    assert report["units"][UNIT]["rules"]["MSG-003"]["verdict"] == "pass"


def test_a_hostile_metadata_yaml_is_refused_in_one_line(tmp_path: Path) -> None:
    """A ROS 2 bag whose metadata.yaml holds 'message_count: lots' (once a
    TypeError), a 1 KB billion laughs (once a hang) or 10,000 levels of nesting: each refused
    (exit 3) with one line naming the file and how to fix it, within the bounds."""
    from hostile import metadata_bags

    bags = metadata_bags(tmp_path)
    run = run_bounded("metadata", [str(p) for p in bags], tmp_path, script=BAG_DRIVER)
    _bounded(run)
    codes = bag_codes(run)
    assert len(codes) == len(bags)
    for bag, code, err in codes:
        assert code == EXIT_NOT_RUN, f"{bag}: {code} {err}"
        assert err.count("\n") == 1 and "nothing was judged" in err and "Fix:" in err, err
    assert "is 'lots', not a whole number" in codes[0][2] and "'lots'" in codes[1][2]
    assert "anchors or aliases" in codes[2][2] and "deeper than 32 levels" in codes[3][2]


def test_long_unit_names_are_stored_once(tmp_path: Path) -> None:
    """100 units with 100 KB names (20 MB): every report written within the memory
    bound (527 MB before: each rule's reason repeated the name) and about the input's size."""
    from hostile import long_names

    path = long_names(tmp_path)
    run = run_bounded("long-names", ["lint", "--from", str(path), "--plain"], tmp_path)
    _bounded(run)
    for report in (tmp_path / "reports").iterdir():
        assert report.stat().st_size < 2 * path.stat().st_size, report

"""Hostile option values: each is one line saying what is wrong, with the
documented exit status, and never a traceback; a reader that leaves (``| head -n 1``) changes
neither the reports nor the exit status. Run as the console script, as a person runs it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conformance.display import shown
from conformance.reporting.bounds import file_stem

LONG = "d" * 300
"""A unit name longer than a file name may be (255 bytes)."""
CLI = [sys.executable, "-m", "conformance.cli"]
LIVE = ["--broker", "mqtt://127.0.0.1:1", "--duration", "1s"]  # refused before connecting


def _run(args: list[str], cwd: Path, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def _main(args: list[str], cwd: Path, monkeypatch: pytest.MonkeyPatch,
          capsys: pytest.CaptureFixture[str]) -> subprocess.CompletedProcess[str]:
    """The console script in process (a second each saved): an exception fails the test."""
    from conformance.cli import main

    monkeypatch.chdir(cwd)
    try:
        status = main(args)
    except SystemExit as e:  # argparse's own errors
        status = int(e.code or 0)
    out = capsys.readouterr()
    return subprocess.CompletedProcess(args, status, out.out, out.err)


def _one_line_error(done: subprocess.CompletedProcess[str], status: int, says: str) -> None:
    out = done.stdout + done.stderr
    assert "Traceback" not in out and done.returncode == status, out
    errors = [line for line in done.stderr.splitlines()
              if line.startswith("waraps-conformance ") and ": " in line]
    assert len(errors) == 1 and says in errors[0], out


CASES = {
    # unit addresses holding a wildcard (or another character no topic holds)
    "unit #": (["lint", "--unit", "waraps/unit/air/real/a#b", *LIVE], 2, "wildcards"),
    "unit +": (["lint", "--unit", "waraps/unit/air/real/a+b", *LIVE], 2, "wildcards"),
    "unit NUL": (["record", "--unit", "waraps/unit/air/real/a\x00b", *LIVE, "-o", "x"], 2,
                 "U+0000"),
    "unit undecodable": (["lint", "--unit", "waraps/unit/air/real/a\udc80b", *LIVE], 2,
                         "U+DC80"),
    "profile unit": (["profile", "--unit", "waraps/unit/air/real/+", "--broker",
                      "mqtt://127.0.0.1:1"], 2, "wildcards"),
    "sim unit": (["sim", "--unit", "waraps/unit/air/real/a#b"], 2, "wildcards"),
    "demo unit": (["demo", "--unit", "waraps/unit/air/real/a#b"], 2, "wildcards"),
    # subscription filters
    "topic +x": (["lint", "--topic", "a/+x/b", *LIVE], 2, "'+' only as a whole level"),
    "topic #x": (["record", "--topic", "a/#/b", *LIVE, "-o", "x"], 2, "'#' only as"),
    "topic empty": (["lint", "--topic", "", *LIVE], 2, "empty"),
    # broker hosts
    "host a..b": (["lint", "--broker", "mqtt://a..b:1883", "--duration", "1s"], 2,
                  "'a..b' is not a host name"),
    "host space": (["record", "--broker", "mqtt://a b:1883", "-o", "x"], 2,
                   "is not a host name"),
    "host label": (["lint", "--broker", f"mqtt://{'x' * 64}.example:1883"], 2,
                   "is not a host name"),
    # rates
    **{f"rate {rate}": (["sim", "--rate", rate], 2, "is not a rate")
       for rate in ("inf", "nan", "0", "-1", "1e9")},
    "demo rate": (["demo", "--rate", "inf"], 2, "is not a rate"),
    # durations: 400 digits are infinity as a float
    "duration inf": (["lint", "--broker", "mqtt://127.0.0.1:1", "--duration", "9" * 400], 2,
                     "is not a positive time"),
    # where the output goes
    "reports-dir a file": (["lint", "--from", "x.jsonl", "--reports-dir", "a-file"], 2,
                           "is not a folder"),
    "reports-dir under a file": (["lint", "--from", "x.jsonl", "--reports-dir", "a-file/r"], 2,
                                 "is not a folder"),
    "reports-dir not creatable": (["lint", "--from", "x.jsonl", "--reports-dir", "/proc/x"], 2,
                                  "cannot create it"),  # /proc: not even root makes a folder
    "record -o nowhere": (["record", *LIVE, "-o", "no/such/dir/x.jsonl"], 2, "cannot write"),
    "profile -o nowhere": (["profile", "--unit", "waraps/unit/air/real/dji0", "--broker",
                            "mqtt://127.0.0.1:1", "-o", "no/such/dir/x.yaml"], 2,
                           "cannot write"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_hostile_option_is_one_line_with_its_exit_status(
        case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    args, status, says = CASES[case]
    (tmp_path / "a-file").write_text("")
    (tmp_path / "x.jsonl").write_text("")
    _one_line_error(_main(args, tmp_path, monkeypatch, capsys), status, says)


def test_a_full_disk_while_recording_is_one_line(
        tmp_path: Path, mosquitto: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    done = _main(["record", "--broker", mosquitto, "--duration", "1s", "-o", "/dev/full"],
                 tmp_path, monkeypatch, capsys)
    _one_line_error(done, 3, "cannot write /dev/full: No space left on device")


PYTEST_CASES = {
    "unit #": (["--unit", "waraps/unit/air/simulation/a#b", "--broker", "embedded"],
               "wildcards"),
    "host a..b": (["--unit", "waraps/unit/air/simulation/dji0", "--broker",
                   "mqtt://a..b:1883"], "'a..b' is not a host name"),
    "reports-dir a file": (["--unit", "waraps/unit/air/simulation/dji0", "--broker", "embedded",
                            "--reports-dir=a-file"], "is not a folder"),
    "observe inf": (["--unit", "waraps/unit/air/simulation/dji0", "--broker", "embedded",
                     "--observe", "9" * 400], "a positive duration is needed"),
    "reports-dir not creatable": (["--unit", "waraps/unit/air/simulation/dji0", "--broker",
                                   "embedded", "--reports-dir=/proc/x"], "cannot create it"),
    "invisible fault name": (["--unit", "waraps/unit/air/simulation/dji0", "--broker", "embedded",
                              "--sim-fault", "x\u3164"], "'x\\u3164' is not a fault"),
    "sim-rate inf": (["--unit", "waraps/unit/air/simulation/dji0", "--broker", "embedded",
                      "--sim-rate", "inf"], "is not a rate"),
}


@pytest.mark.parametrize("case", sorted(PYTEST_CASES))
def test_a_hostile_option_of_the_certification_is_a_usage_error(
        case: str, pytester: pytest.Pytester) -> None:
    args, says = PYTEST_CASES[case]
    pytester.makefile("", **{"a-file": ""})
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", *args)
    out = result.stdout.str() + result.stderr.str()
    assert result.ret == pytest.ExitCode.USAGE_ERROR and "Traceback" not in out, out
    assert says in out and "INTERNALERROR" not in out


def test_report_file_names_are_bounded_and_never_shared() -> None:
    assert file_stem("dji0") == "dji0"  # a usual name stays as it is
    long = file_stem(LONG)
    assert len(long) < 100 and long != file_stem(LONG + "x")
    assert file_stem("a/../b") != file_stem("a_.._b") and "/" not in file_stem("a/../b")
    assert file_stem("无人机").isascii() and file_stem(".hidden")[0] != "."


@pytest.mark.slow
def test_a_300_character_unit_name_is_certified_and_reported(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "--unit", f"waraps/unit/air/simulation/{LONG}",
        "--broker", "virtual", "--sim-rate", "3", "-k", "HB-001", "--reports-dir=reports")
    out = result.stdout.str() + result.stderr.str()
    assert result.ret == pytest.ExitCode.OK and "Traceback" not in out, out
    assert {p.suffix for p in (pytester.path / "reports").iterdir()} == {".json", ".html"}


def _failing_recording(path: Path) -> Path:
    """A conformant unit's 12 s and one heartbeat without its fields (MSG-*: exit 1)."""
    sys.path.insert(0, str(Path(__file__).parents[1] / "lint"))
    from lint_helpers import T0, unit_traffic, write_recording

    from conformance.message import Message

    messages = unit_traffic("pipe", "dji0", seconds=12)
    messages.append(Message(T0 + 5.5, "pipe/unit/air/simulation/dji0/heartbeat",
                            b'{"type": "HeartBeat"}'))
    return write_recording(path, sorted(messages, key=lambda m: m.time))


def test_a_reader_that_leaves_changes_neither_reports_nor_exit_status(tmp_path: Path) -> None:
    """``lint --from failing.jsonl | head -n 1``: the lint goes on without its reader."""
    recording = _failing_recording(tmp_path / "failing.jsonl")
    whole = _run(["lint", "--from", str(recording), "--reports-dir", "whole"], tmp_path)
    assert whole.returncode == 1, whole.stdout + whole.stderr
    proc = subprocess.Popen([*CLI, "lint", "--from", str(recording), "--reports-dir", "cut"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()  # what `head -n 1` reads before it leaves
    proc.stdout.close()
    status = proc.wait(60)
    err = proc.stderr.read()
    proc.stderr.close()
    assert first.startswith("read ") and "Traceback" not in err, err
    assert status == 1, err
    for name in ("lint-failing.json", "lint-failing.html", "lint-failing.xml"):
        assert (tmp_path / "cut" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()


def test_shown_is_escaped_and_masked() -> None:
    assert shown("mqtt://u:p w@h\x1b[2J") == "mqtt://u:***@h\\x1b[2J"

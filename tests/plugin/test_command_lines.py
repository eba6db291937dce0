"""Every printed command line is shell-quoted: each is pasted into a shell, which
must run it with exactly the arguments meant and nothing else, for crafted unit names."""

from __future__ import annotations

import shlex
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest

from conformance.report_meta import RunMeta
from conformance.reporting.text import rerun_command as report_rerun
from conformance.results import skip_reason
from conformance.rules import get
from conformance.suite.settings import read

ACTIVE = "DEI-004"
CRAFTED = [
    "x;touch PWNED",
    "$(touch PWNED)",
    "`touch PWNED`",
    "a&&touch PWNED ||",  # (no "#": a wildcard, refused in a unit address)
    "it's|touch PWNED",
    "x\ntouch PWNED",
    "*",
]


def pasted(line: str, cwd: Path) -> list[str]:
    """The arguments a shell gives the line's command when the line is pasted (the command
    itself replaced by printf, so nothing runs but the shell); fails if the shell ran more."""
    words = shlex.split(line)
    assert words
    done = subprocess.run(["bash", "-c", "printf '%s\\0' " + line.split(" ", 1)[1]
                           if line.startswith(("pytest ", "waraps-conformance ")) else line],
                          cwd=cwd, capture_output=True, timeout=30)
    assert done.returncode == 0, done.stderr
    assert not (cwd / "PWNED").exists(), f"pasting ran a command: {line!r}"
    args = done.stdout.decode().split("\0")[:-1]
    assert args == words[1:], (line, args)
    return args


@pytest.mark.parametrize("name", CRAFTED)
def test_the_certifications_repeat_line_pastes_safely(pytester, tmp_path, name):
    unit = f"waraps/unit/air/simulation/{name}"
    settings = read(pytester.parseconfig("-p", "no:cacheprovider", "--unit", unit,
                                         "--broker", "embedded", "--seed", "5",
                                         "--tst-command-topic",
                                         f"waraps/unit/ground/real/op{name}"))
    for line in (settings.rerun_command(), settings.rerun_command("HB-003", observe=3)):
        args = pasted(line, tmp_path)
        assert args[args.index("--unit") + 1] == unit
        assert args[args.index("--tst-command-topic") + 1].endswith(f"/op{name}/tst/command")


@pytest.mark.parametrize("name", CRAFTED)
def test_the_reports_rerun_lines_paste_safely(tmp_path, name):
    unit = f"waraps/unit/air/simulation/{name}"
    certification = SimpleNamespace(kind="certification", meta=RunMeta(), broker="")
    args = pasted(report_rerun(certification, unit, "HB-003"), tmp_path)
    assert args == ["--unit", unit, "-k", "HB-003"]
    recording = SimpleNamespace(kind="lint", broker="",
                                meta=RunMeta(source=f"field {name}.jsonl", recording_lines="3"))
    args = pasted(report_rerun(recording, unit, "HB-003"), tmp_path)
    assert args == ["lint", "--from", f"field {name}.jsonl", "--unit", unit]
    piped = SimpleNamespace(kind="lint", broker="", meta=RunMeta(source="-", recording_lines="3"))
    assert pasted(report_rerun(piped, unit, "HB-003"), tmp_path)[:3] == [
        "lint", "--from", "<recording>"]
    live = SimpleNamespace(kind="lint", broker=f"mqtt://{name}:1883",
                           meta=RunMeta(tls_options="--ca-file='my ca.pem'"))
    args = pasted(report_rerun(live, unit, "HB-003"), tmp_path)
    assert args == ["lint", "--broker", f"mqtt://{name}:1883", "--ca-file=my ca.pem",
                    "--unit", unit]


@pytest.mark.parametrize("name", CRAFTED)
def test_reasons_that_name_a_command_quote_the_unit(tmp_path, name):
    unit = f"waraps/unit/air/simulation/{name}"
    for rule in (ACTIVE, "EXEC-PING-001"):
        reason = skip_reason(get(rule), kind="lint", unit=unit, levels=None)
        line = reason[reason.index("pytest --unit"):].removesuffix(" sends them)")
        assert pasted(line, tmp_path) == ["--unit", unit]


def test_a_unit_too_long_to_repeat_is_not_repeated_in_each_reason():
    """Names stored once; a reason names a long unit by a stand-in."""
    unit = "waraps/unit/air/simulation/" + "n" * 100_000
    reason = skip_reason(get(ACTIVE), kind="lint", unit=unit, levels=None)
    assert "nnnn" not in reason and "pytest --unit ADDRESS (this unit's)" in reason

"""Certification on a real terminal: a pseudo-terminal, read back as a person sees it (the
wait line is redrawn in place and erased; pytest's result letters are never left standing
alone at the right edge where a wait line ended)."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest
from certify_helpers import FAST

COLUMNS = 100
CSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def screen(raw: str) -> list[str]:
    """The lines a terminal shows for ``raw``: a carriage return goes back to column 0, text
    overwrites, ESC[K erases to the end of the line; colours are dropped."""
    lines: list[list[str]] = [[]]
    col = 0
    for token in re.split(r"(\x1b\[[0-9;?]*[A-Za-z]|\r|\n)", raw):
        if token == "\n":
            lines.append([])
            col = 0
        elif token == "\r":
            col = 0
        elif token == "\x1b[K":
            del lines[-1][col:]
        elif token and not CSI.fullmatch(token):
            line = lines[-1]
            for ch in token:
                if col >= COLUMNS:  # the terminal wraps
                    lines.append([])
                    line, col = lines[-1], 0
                line[col:col + 1] = [ch]
                col += 1
    return ["".join(line).rstrip() for line in lines]


def run_on_a_terminal(args: list[str], cwd: Path, budget: float) -> str:
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, COLUMNS, 0, 0))
    env = {**os.environ, "COLUMNS": str(COLUMNS), "TERM": "xterm"}
    proc = subprocess.Popen([sys.executable, "-m", "pytest", *args], stdin=slave,
                            stdout=slave, stderr=slave, cwd=cwd, env=env, close_fds=True)
    os.close(slave)
    out = bytearray()
    deadline = time.monotonic() + budget
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # the child closed the terminal
                    break
                if not chunk:
                    break
                out += chunk
            elif proc.poll() is not None:
                break
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)
        os.close(master)
    return out.decode("utf-8", "replace")


@pytest.mark.slow
def test_waits_are_drawn_in_place_and_result_letters_stay_on_their_lines(tmp_path: Path) -> None:
    # pong-missing: the ping scenario waits out its response deadline (a wait worth drawing)
    raw = run_on_a_terminal(
        ["-p", "no:cacheprovider", "-o", "addopts=", "--unit", "waraps/unit/air/simulation/dji0",
         "--broker", "embedded", "--sim-rate", "3", "--sim-fault", "pong-missing",
         f"--profile={FAST}", f"--reports-dir={tmp_path / 'reports'}",
         # the ping scenario's rules and a few passive ones: a wait, then more letters after it
         "-k", "EXEC-PING or EXEC-START or HB-00"], tmp_path, budget=100)
    assert "waiting for exec/response of dji0: 1 s of 2 s" in raw  # drawn while it lasted
    shown = screen(raw)
    assert not any("waiting for" in line for line in shown), "a wait line was left behind"
    letters = r"[.sFE]+( +\[ *\d+%\])?"
    lonely = [line for line in shown if re.fullmatch(r"\s+" + letters, line)]
    assert not lonely, "result letters alone on a line:\n" + "\n".join(lonely)
    # a file's line of letters, and pytest's own continuation lines (past the right edge)
    results = [line for line in shown
               if re.fullmatch(r"(test_\w+\.py( " + letters + ")?)|" + letters, line)]
    assert sum(line.count("F") for line in results) >= 1  # the ping failure is among them
    # every test's letter is shown once: a letter per test selected
    collected = int(re.search(r"(\d+) selected", raw).group(1))  # type: ignore[union-attr]
    assert sum(len(re.sub(r"^test_\w+\.py|\[.*\]|\s", "", line)) for line in results) \
        == collected

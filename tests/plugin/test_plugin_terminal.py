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
    """The lines a terminal shows for ``raw`` (pyte, a VT100 emulator: cursor movements,
    erasing, wrapping; colours dropped), the lines scrolled off the top first."""
    import pyte

    term = pyte.HistoryScreen(COLUMNS, 40, history=5000)
    pyte.Stream(term).feed(raw)
    rows = [row for row in term.history.top] + [term.buffer[y] for y in range(term.lines)]
    return ["".join(row[x].data for x in range(COLUMNS)).rstrip() for row in rows]


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
    # A stretch of short waits (each task's answers) is shown too: every second says what it
    # waits for, not only waits that last a second.
    assert re.search(r"waiting for [^\x1b]*: 0 s of \d+ s", raw), raw[:3000]
    shown = screen(raw)
    # pytest's line of result letters is never split by a wait line
    assert sum(line.startswith("test_execution.py") for line in shown) == 1, "\n".join(shown)
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


@pytest.mark.slow
def test_exploration_shows_its_progress_and_leaves_nothing_behind(tmp_path: Path) -> None:
    """Elapsed of budget, examples, steps and what it does, redrawn in place."""
    raw = run_on_a_terminal(
        ["-p", "no:cacheprovider", "-o", "addopts=", "--unit", "waraps/unit/air/simulation/dji0",
         "--broker", "embedded", "--sim-rate", "3", f"--profile={FAST}",
         f"--reports-dir={tmp_path / 'reports'}", "--explore=10s", "-k", "test_explore"],
        tmp_path, budget=90)
    # 10 s: on a loaded machine (-n 4 on 2 cores) a 6 s budget drew one line (10 steps)
    drawn = re.findall(r"exploring: (\d+) s of 10 s, (\d+) examples?, (\d+) steps?; ([^\x1b]+)",
                       raw)
    assert len(drawn) >= 3, raw[-3000:]
    assert int(drawn[-1][0]) >= 2 and int(drawn[-1][2]) > int(drawn[0][2])  # it moves on
    assert any(what.startswith(("start-task", "signal-task", "ping", "query-status", "wait"))
               for *_, what in drawn), drawn
    shown = screen(raw)
    assert not any("exploring: " in line for line in shown), "\n".join(shown)
    assert sum(line.startswith("test_explore.py") for line in shown) == 1, "\n".join(shown)
    # the suite's counts and pytest's agree: the rules, and the exploration apart
    summary = next(line for line in shown if line.startswith("waraps/unit/air/simulation/dji0:"))
    assert "; exploration: pass (" in " ".join(shown[shown.index(summary):][:3]), summary

"""Progress while the suite waits on the unit: redrawn on a terminal, plain lines every 10 s
otherwise, nothing under -q; -v shows each step (suite/progress.py, without a broker)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from conformance.scenarios.traffic import Wait
from conformance.suite.progress import LINE_EVERY, Progress


class Reporter:
    """Records what Progress draws (the part of pytest's TerminalReporter it uses)."""

    def __init__(self, tty: bool) -> None:
        self.tty = tty
        self.calls: list[tuple[str, str]] = []
        self.currentfspath: object = Path("/run/test_execution.py")
        self.startpath = Path("/run")

    def isatty(self) -> bool:
        return self.tty

    def rewrite(self, line: str, **markup: Any) -> None:
        self.calls.append(("rewrite", line))

    def write(self, text: str) -> None:
        self.calls.append(("write", text))

    def write_line(self, line: str) -> None:
        self.calls.append(("line", line))

    def ensure_newline(self) -> None:
        pass


class Config:
    def __init__(self, reporter: Reporter, verbosity: int) -> None:
        self.reporter, self.verbosity = reporter, verbosity
        self.pluginmanager = self

    def get_verbosity(self) -> int:
        return self.verbosity

    def get_plugin(self, name: str) -> Any:
        return self.reporter if name == "terminalreporter" else None

    getplugin = get_plugin


def waited(seconds: float, timeout: float = 30.0) -> Wait:
    return Wait("the final feedback of move-to 3f2a1b0c", time.monotonic() - seconds, timeout)


class Writer:
    """The part of pytest's TerminalWriter Progress uses: the text of its current line."""

    def __init__(self, reporter: Reporter, line: str, width: int = 80) -> None:
        self.reporter, self._current_line, self.fullwidth = reporter, line, width

    def write_raw(self, text: str, flush: bool = False) -> None:
        self.reporter.calls.append(("raw", text))


@pytest.mark.parametrize("verbosity", [0, 1])
def test_on_a_terminal_a_wait_is_drawn_below_pytests_line_and_erased(verbosity: int) -> None:
    """Pytest's line of result letters is never rewritten or split: the wait is
    drawn on the line below, the cursor put back after the last letter, then erased."""
    tr = Reporter(tty=True)
    tr._tw = Writer(tr, "test_execution.py ..")  # type: ignore[attr-defined]
    progress = Progress(Config(tr, verbosity))  # type: ignore[arg-type]
    wait = waited(12)
    progress.tick(wait)
    progress.tick(wait)
    text = "waiting for the final feedback of move-to 3f2a1b0c: 12 s of 30 s"
    back = "\x1b[K\x1b[1A\x1b[21G"  # erase the rest, up to pytest's line, after its letters
    assert tr.calls == [("raw", f"\n\r{text}{back}"), ("raw", f"\x1b[1B\r{text}{back}")]
    progress.end(wait)
    assert tr.calls[2:] == [("raw", f"\x1b[1B\r{back}")]  # erased, the cursor back
    progress.end(wait)
    assert len(tr.calls) == 3  # erased once


def test_a_short_wait_stays_drawn_until_the_next_draws_or_the_test_ends() -> None:
    """A stretch of short waits does not flicker: its line is erased when the test ends."""
    tr = Reporter(tty=True)
    tr._tw = Writer(tr, "test_execution.py .")  # type: ignore[attr-defined]
    progress = Progress(Config(tr, 0))  # type: ignore[arg-type]
    short = waited(0.2)
    progress.tick(short)
    progress.end(short)
    assert len(tr.calls) == 1
    progress.clear()
    assert tr.calls[-1] == ("raw", "\x1b[1B\r\x1b[K\x1b[1A\x1b[20G")


def test_a_status_is_shown_and_a_wait_during_it_says_both() -> None:
    tr = Reporter(tty=True)
    tr._tw = Writer(tr, "test_explore.py ", width=200)  # type: ignore[attr-defined]
    progress = Progress(Config(tr, 0))  # type: ignore[arg-type]
    progress.show_status("exploring: 3 s of 50 s, 1 example, 4 steps; ping")
    progress.tick(waited(2, 6))
    assert tr.calls[-1][1].startswith("\x1b[1B\rexploring: 3 s of 50 s, 1 example, 4 steps; "
                                      "ping; waiting for the final feedback")
    progress.show_status("")
    assert tr.calls[-1] == ("raw", "\x1b[1B\r\x1b[K\x1b[1A\x1b[17G")


def test_off_a_terminal_a_plain_line_every_ten_seconds() -> None:
    tr = Reporter(tty=False)
    progress = Progress(Config(tr, 0))  # type: ignore[arg-type]
    wait = waited(LINE_EVERY + 1)
    progress.tick(wait)
    progress.tick(wait)  # one line per 10 s of a wait, not one per tick
    assert tr.calls == [("line", "waiting for the final feedback of move-to 3f2a1b0c: "
                                 "11 s of 30 s")]
    later = Wait(wait.what, wait.started - LINE_EVERY, wait.timeout)
    progress.tick(later)
    assert tr.calls[-1] == ("line", "waiting for the final feedback of move-to 3f2a1b0c: "
                                    "21 s of 30 s")
    tr.calls.clear()
    progress.tick(waited(3))
    assert tr.calls == []  # a short wait is not worth a line


def test_quiet_shows_nothing_and_steps_need_verbose() -> None:
    tr = Reporter(tty=True)
    Progress(Config(tr, -1)).tick(waited(12))  # type: ignore[arg-type]
    Progress(Config(tr, 0)).step("sent ping")  # type: ignore[arg-type]
    assert tr.calls == []
    Progress(Config(tr, 1)).step("sent ping")  # type: ignore[arg-type]
    assert tr.calls == [("line", "sent ping")]

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


@pytest.mark.parametrize("verbosity", [0, 1])
def test_on_a_terminal_a_wait_is_redrawn_and_erased(verbosity: int) -> None:
    tr = Reporter(tty=True)
    progress = Progress(Config(tr, verbosity))  # type: ignore[arg-type]
    wait = waited(12)
    progress.tick(wait)
    progress.tick(wait)
    assert tr.calls == [("rewrite", "waiting for the final feedback of move-to 3f2a1b0c: "
                                    "12 s of 30 s")] * 2
    progress.end(wait)
    # erased, back at column 0, and pytest's result letters go on after the file's name
    assert tr.calls[2:] == [("rewrite", ""), ("write", "\r"), ("write", "test_execution.py ")]
    assert tr.currentfspath == Path("/run/test_execution.py")


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

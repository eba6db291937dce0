"""What the suite is doing while it waits on the unit, for the person at the terminal.

A wait that lasts shows what it is for and for how long (``waiting for the final feedback of
move-to 3f2a1b0c: 12 s of 30 s``), and the exploration its progress (``exploring: 12 s of
50 s, 3 examples, 41 steps; signal-task $pause to T1``): on a terminal it is drawn on the
line below pytest's line of result letters, the cursor put back where pytest left it, and
erased when it is over, so pytest's line is never split; a plain line every
``LINE_EVERY`` seconds otherwise (CI logs). ``-v`` also shows each scenario step (every
command sent and its answer) and each deviation the scenarios adapt to; ``-q`` shows none of
it. Nothing here changes pytest's own output (``-rA``, ``--junitxml``).
"""

from __future__ import annotations

import time
from typing import Any

import pytest

from conformance.display import printable
from conformance.scenarios.traffic import TICK, Wait

LINE_EVERY = 10.0
"""Seconds between two plain progress lines of one wait (not on a terminal)."""
STATUS_EVERY = 1.0
"""Seconds between two redraws of a status (the exploration's progress) on a terminal."""

# ECMA-48 cursor movements: down a line, up a line, to a column (1-based), erase to the end.
DOWN, UP, ERASE = "\x1b[1B", "\x1b[1A", "\x1b[K"


def _writer(tr: Any) -> Any:
    """pytest's TerminalWriter behind the reporter (None when it is not one)."""
    tw = getattr(tr, "_tw", None)
    return tw if tw is not None and hasattr(tw, "write_raw") else None


def _width(tw: Any) -> int:
    return max(20, int(getattr(tw, "fullwidth", 80)))


def _back(tw: Any) -> str:
    """The cursor to the end of pytest's line: the column its writer keeps (it has no
    public way to be asked for the text of its current line)."""
    return f"\x1b[{len(getattr(tw, '_current_line', '')) % _width(tw) + 1}G"


class Progress:
    """Shows waits and steps through pytest's terminal reporter, capture suspended."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.verbosity = config.get_verbosity()
        self._drawn = False
        self._shown: tuple[Wait | None, int] = (None, 0)
        """(the wait, how many LINE_EVERY periods of it were shown) off a terminal."""
        self.status = ""
        """What a long activity is doing (the exploration's progress), shown before a wait."""
        self._status_drawn = 0.0

    @property
    def _reporter(self) -> Any:
        return self.config.pluginmanager.get_plugin("terminalreporter")

    def _tty(self) -> bool:
        tr = self._reporter
        return tr is not None and bool(tr.isatty())

    def _write(self, draw: Any) -> None:
        tr = self._reporter
        if tr is None:
            return
        capman = self.config.pluginmanager.getplugin("capturemanager")
        if capman is not None:
            with capman.global_and_fixture_disabled():
                draw(tr)
        else:
            draw(tr)

    def tick(self, wait: Wait) -> None:
        """A wait still going on (called about once a second by the waiting thread)."""
        if self.verbosity < 0:
            return
        text = f"waiting for {wait.what}: {wait.elapsed:.0f} s of {wait.timeout:.0f} s"
        if self.status:
            text = f"{self.status}; {text}"
        if self._tty():
            self._draw(text)
            return
        periods = int(wait.elapsed // LINE_EVERY)
        shown = self._shown[1] if self._shown[0] is wait else 0
        if periods > shown:
            self._shown = (wait, periods)
            self.line(text)

    def show_status(self, text: str, *, force: bool = False) -> None:
        """What a long activity is doing now (``text``; '' when it is over): drawn at most
        once a ``STATUS_EVERY`` on a terminal, a plain line every ``LINE_EVERY`` off one."""
        self.status = text
        if self.verbosity < 0:
            return
        now = time.monotonic()
        if not self._tty():  # a plain line every LINE_EVERY (CI logs)
            if text and now - self._status_drawn >= LINE_EVERY:
                self._status_drawn = now
                self.line(text)
            return
        if not text:
            self.clear()
            return
        if force or now - self._status_drawn >= STATUS_EVERY:
            self._status_drawn = now
            self._draw(text)

    def _draw(self, text: str) -> None:
        """``text`` on the line below pytest's, the cursor back at the end of pytest's."""
        first = not self._drawn

        def draw(tr: Any) -> None:
            tw = _writer(tr)
            if tw is None:  # not pytest's writer: a line of its own
                tr.ensure_newline()
                tr.write_line(printable(text))
                return
            shown = printable(text)[:_width(tw) - 1]  # never wraps: one line below, always
            go = "\n\r" if first else f"{DOWN}\r"
            tw.write_raw(f"{go}{shown}{ERASE}{UP}{_back(tw)}", flush=True)
        self._write(draw)
        self._drawn = True

    def end(self, wait: Wait | None) -> None:
        """A wait is over. A long one's line is erased (or the status it interrupted shown
        again); a short one's stays until the next wait redraws it or the test ends
        (``clear``): a stretch of short waits does not flicker."""
        if not self._drawn or (wait is not None and wait.elapsed < TICK):
            return
        if self.status:
            self._draw(self.status)
            return
        self.clear()

    def clear(self) -> None:
        """Erase our line below pytest's (before pytest writes a result, and at the end)."""
        if not self._drawn:
            return
        self._drawn = False

        def erase(tr: Any) -> None:
            tw = _writer(tr)
            if tw is not None:
                tw.write_raw(f"{DOWN}\r{ERASE}{UP}{_back(tw)}", flush=True)
        self._write(erase)

    def step(self, text: str) -> None:
        """A scenario step (``-v``): a command sent, its answer, a deviation adapted to."""
        if self.verbosity < 1:
            return
        self.line(text)

    def line(self, text: str) -> None:
        status = self.status
        self.clear()  # the line below is ours: erase it, and write there

        def draw(tr: Any) -> None:
            tr.ensure_newline()
            tr.write_line(printable(text))
            tr.currentfspath = None
        self._write(draw)
        if status and self._tty():
            self.show_status(status, force=True)

"""What the suite is doing while it waits on the unit, for the person at the terminal.

A wait that lasts shows what it is for and for how long (``waiting for the final feedback of
move-to 3f2a1b0c: 12 s of 30 s``): redrawn in place on a terminal, a plain line every
``LINE_EVERY`` seconds otherwise (CI logs). ``-v`` also shows each scenario step (every
command sent and its answer) and each deviation the scenarios adapt to; ``-q`` shows none of
it. Nothing here changes pytest's own output (``-rA``, ``--junitxml``).
"""

from __future__ import annotations

from typing import Any

import pytest

from conformance.display import printable
from conformance.scenarios.traffic import Wait

try:  # pytest's own relative-path helper, as its result lines use it
    from _pytest.pathlib import bestrelpath
except ImportError:  # pragma: no cover - a future pytest without it
    def bestrelpath(directory: Any, dest: Any) -> str:
        return str(dest)

LINE_EVERY = 10.0
"""Seconds between two plain progress lines of one wait (not on a terminal)."""


class Progress:
    """Shows waits and steps through pytest's terminal reporter, capture suspended."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.verbosity = config.get_verbosity()
        self._drawn = False
        self._fspath: Any = None
        self._shown: tuple[Wait | None, int] = (None, 0)
        """(the wait, how many LINE_EVERY periods of it were shown) off a terminal."""

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
        if self._tty():
            first = not self._drawn  # (was read inside draw, after it was set: never true)

            def draw(tr: Any) -> None:
                if first:  # keep pytest's line of result letters; draw on a line of our own
                    self._fspath = tr.currentfspath
                    tr.ensure_newline()
                tr.rewrite(printable(text), erase=True)
            self._drawn = True
            self._write(draw)
            return
        periods = int(wait.elapsed // LINE_EVERY)
        shown = self._shown[1] if self._shown[0] is wait else 0
        if periods > shown:
            self._shown = (wait, periods)
            self.line(text)

    def end(self, wait: Wait) -> None:
        """A wait that was shown is over: erase its line (on a terminal)."""
        if not self._drawn:
            return
        self._drawn = False

        def erase(tr: Any) -> None:
            tr.rewrite("", erase=True)
            _back_to_column_0(tr)
            if self._fspath is not None:
                # pytest goes on writing result letters on this line: give it the test
                # file's name first, as pytest does at the start of a line of results, so
                # no letter stands alone at the right edge where the wait text ended.
                tr.write(f"{bestrelpath(tr.startpath, self._fspath)} ")
            tr.currentfspath = self._fspath
        self._write(erase)

    def step(self, text: str) -> None:
        """A scenario step (``-v``): a command sent, its answer, a deviation adapted to."""
        if self.verbosity < 1:
            return
        self.line(text)

    def line(self, text: str) -> None:
        def draw(tr: Any) -> None:
            if self._drawn:
                tr.rewrite("", erase=True)
                self._drawn = False
            tr.ensure_newline()
            tr.write_line(printable(text))
            tr.currentfspath = None
        self._write(draw)


def _back_to_column_0(tr: Any) -> None:
    """After an erase the cursor stands at the line's end: put it at column 0, and tell
    pytest's writer the line is empty (it measures the line to right-align its [ NN%]
    progress; it has no public way to be told, so its line is reset where it exists)."""
    tr.write("\r")
    tw = getattr(tr, "_tw", None)
    if tw is not None and hasattr(tw, "_current_line"):
        tw._current_line = ""

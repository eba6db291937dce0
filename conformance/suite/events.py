"""What happened to the connection and the unit during a certification, for the terminal
summary (``pytest_terminal_summary``): one line each, most stamped with the wall-clock time."""

from __future__ import annotations

from conformance.violation import clock  # one clock: UTC, as findings and reports say times


class Events(list[str]):
    """The run's events, oldest first (a list of lines)."""

    def at(self, t: float, text: str) -> str:
        """Add ``text`` as happened at ``t`` (Unix seconds); returns the line added."""
        line = f"{clock(t)} {text}"
        self.append(line)
        return line

"""Wire text made fit to show (issue 19 §4, §5): ``printable`` for a terminal (and any report),
control characters shown escaped, and ``shorten`` for a report, a long string excerpted with a
visible ellipsis and its full length. Every writer of a terminal line or a report uses these."""

from __future__ import annotations

import re

_CONTROL = re.compile(
    "[\x00-\x1f\x7f-\x9f"                  # C0 (line breaks and tabs too), DEL, C1 (CSI, OSC)
    "\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069"  # bidirectional controls (text that reorders)
    "\u2028\u2029\ud800-\udfff\ufffe\uffff]")  # line separators, lone surrogates, non-characters


def _escaped(m: re.Match[str]) -> str:
    c = ord(m.group())
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}"


def printable(text: object) -> str:
    """``text`` as one line safe for a terminal: every control character (escape sequences
    such as OSC 0 window titles, OSC 52 clipboard writes, CSI; line breaks; bidirectional
    overrides) shown as ``\\xNN`` or ``\\uNNNN``. Wire data may hold anything."""
    s = text if isinstance(text, str) else str(text)
    if s.isascii() and s.isprintable():  # the usual case: nothing to do
        return s
    return _CONTROL.sub(_escaped, s)


SHORT_CHARS = 4096
"""The longest string a report shows in full (an excerpt of it beyond)."""
LINE_CHARS = 4000
"""The longest line written to a terminal (an excerpt of it beyond)."""
NAME_CHARS = 200
"""The longest name (a unit's, from its topic) shown whole in a terminal line."""


def printable_lines(text: object, limit: int = LINE_CHARS) -> str:
    """Text of several lines (ours, joined with '\\n') with each line made ``printable``
    and excerpted past ``limit`` characters."""
    return "\n".join(printable(shorten(line, limit)) for line in str(text).split("\n"))


def shorten(text: object, limit: int = SHORT_CHARS) -> str:
    """``text`` whole when it has at most ``limit`` characters, else its first ``limit`` and
    a visible ellipsis with its full length: ``abc… (1048576 chars)``."""
    s = text if isinstance(text, str) else str(text)
    if len(s) <= limit:
        return s
    return f"{s[:limit]}… ({len(s)} chars)"

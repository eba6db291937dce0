"""Wire text made fit to show: ``printable`` for a terminal
(and any report), every character a person cannot see or that moves the cursor shown escaped,
and ``shorten`` for a report, a long string excerpted with a visible ellipsis and its full
length. Every writer of a terminal line or a report uses these: the one escape."""

from __future__ import annotations

import re

from conformance.masking import mask_password

_NOT_PLAIN = re.compile("[^\x20-\x7e]")
"""A character that is not printable ASCII: the only ones worth a look (ASCII text is shown
as it is)."""

_INVISIBLE_CLASS = ("[\u034f\u115f\u1160\u17b4\u17b5\u3164\uffa0"  # grapheme joiner, fillers
                    "\u180b-\u180f"       # Mongolian variation selectors and vowel separator
                    "\ufe00-\ufe0f"       # variation selectors
                    "\U000e0100-\U000e01ef]")  # variation selectors supplement
_INVISIBLE = re.compile(_INVISIBLE_CLASS)
"""Characters Unicode counts as letters or marks that nevertheless show nothing: two names
differing only by them would print alike."""


def _escape(c: str) -> str:
    """``c`` as itself when a person sees it as it is, else as ``\\xNN``, ``\\uNNNN`` or
    ``\\UNNNNNNNN`` (always that many digits, so that no escape reads as another).

    Escaped: what ``str.isprintable`` refuses, that is Unicode's 'Other' (Cc: C0, DEL, C1
    such as CSI and NEL; Cf: bidirectional controls, zero-width characters, U+FEFF, tag
    characters; Cs, Co: surrogates, private use; Cn: unassigned) and 'Separator' (Zl, Zp:
    U+2028, U+2029; Zs: spaces other than ' ', which look like it), and the invisible
    letters and marks above."""
    n = ord(c)
    if c.isprintable() and not _INVISIBLE.match(c):
        return c
    return f"\\x{n:02x}" if n < 0x100 else f"\\u{n:04x}" if n < 0x10000 else f"\\U{n:08x}"


def printable(text: object) -> str:
    """``text`` as one line safe for a terminal: every control character (escape sequences
    such as OSC 0 window titles, OSC 52 clipboard writes, CSI; line breaks; bidirectional
    overrides) and every invisible one (zero-width, tag characters) shown as ``\\xNN``,
    ``\\uNNNN`` or ``\\UNNNNNNNN``. Wire data may hold anything; ASCII text is unchanged."""
    s = text if isinstance(text, str) else str(text)
    if s.isprintable() and (s.isascii() or not _INVISIBLE.search(s)):  # nothing to do
        return s
    return _NOT_PLAIN.sub(lambda m: _escape(m.group()), s)


def shown(text: object) -> str:
    """``text`` (ours, holding user or wire text: a URL, a command line, an error) fit for a
    terminal: one line, escaped, never a password (§5)."""
    return printable(mask_password(str(text)))


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

"""The one escape: ``display.printable`` shows every character a person cannot
see, or that moves the cursor or reorders text, as a visible escape; ASCII text is unchanged;
two different names never print alike."""

from __future__ import annotations

import unicodedata

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conformance.display import printable, printable_lines

HIDDEN = (
    [chr(c) for c in range(0x20)] + ["\x7f"] + [chr(c) for c in range(0x80, 0xA0)]  # C0, DEL, C1
    + list("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")  # bidi
    + list("\u200b\u200c\u200d\u2060\ufeff")  # zero-width
    + [chr(c) for c in range(0xE0000, 0xE0080)]  # tag characters
    + list("\u2028\u2029\u0085\u00ad\u00a0\u3000\ue000\U000f0000\ufffe\U0001fffe")
    + list("\u034f\ufe0f\U000e0100\u3164\u180e")  # invisible although letters or marks
)
"""Control (C0, C1, DEL), bidirectional controls, zero-width, tag characters, line and
paragraph separators, other format characters, spaces that look like ' ', private use,
non-characters, and letters or marks that show nothing."""


def _hidden(c: str) -> bool:
    return c in HIDDEN or unicodedata.category(c)[0] in "CZ" and c != " "


@pytest.mark.parametrize("c", HIDDEN)
def test_every_hidden_character_is_shown_as_an_escape(c):
    shown = printable(f"a{c}b")
    assert shown.isascii() and shown.isprintable(), repr(shown)
    assert shown.startswith("a\\") and shown.endswith("b")


def test_ascii_and_visible_text_is_unchanged():
    text = "".join(chr(c) for c in range(0x20, 0x7f))
    assert printable(text) == text
    assert printable("é ü 无人机 🚁 Ωmega") == "é ü 无人机 🚁 Ωmega"
    assert printable_lines("ours\nand ours") == "ours\nand ours"  # our own line breaks stay


def test_a_tag_character_is_not_read_as_another_escape():
    # \\U with 8 digits: U+E0041 is not U+E004 followed by '1'
    assert printable("\U000e0041") == "\\U000e0041"
    assert printable("\ue004" + "1") == "\\ue0041"


_NAMES = st.text(st.one_of(st.sampled_from(HIDDEN), st.characters(exclude_characters="\\")),
                 max_size=12)


@settings(settings.get_profile("ci"))
@given(_NAMES)
def test_printable_shows_nothing_hidden(name):
    shown = printable(name)
    assert not any(_hidden(c) for c in shown), repr(shown)


@settings(settings.get_profile("ci"))
@given(_NAMES, _NAMES)
def test_two_names_never_print_alike(a, b):
    """Injective on text without a backslash (a backslash is ASCII, shown as it is: a name
    may spell an escape out, and is then told apart by the reports' JSON)."""
    if a != b:
        assert printable(a) != printable(b)

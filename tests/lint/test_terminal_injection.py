"""Nothing from the wire drives the terminal: unit names, topics, payloads, sender
names and event details holding escape sequences (OSC 0 window title, OSC 52 clipboard, CSI)
are shown escaped by ``display.printable``, in the plain output and on a terminal alike."""

from __future__ import annotations

import io
import re

import orjson
import pytest
from lint_helpers import T0, run_lint, unit_traffic, write_recording

from conformance.display import printable, printable_lines, shorten
from conformance.message import Message
from conformance.recording import Event
from conformance.reporting.text import render_violation
from conformance.violation import Violation

ESCAPES = "\x1b]0;PWNED-TITLE\x07\x1b]52;c;cHduZWQ=\x07\x1b[2J\x1b[31mRED\x9b1m\u202eevil"
"""OSC 0 (window title), OSC 52 (clipboard), CSI (clear, colour), C1 CSI, a bidi override."""
DANGEROUS = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")
"""What must never reach the terminal from the wire (our own '\\n' and '\\t' aside)."""


@pytest.mark.parametrize(("text", "shown"), [
    ("dji0", "dji0"),
    ("é ü 无人机", "é ü 无人机"),
    ("a\x1b[2Jb", "a\\x1b[2Jb"),
    ("a\nFAKE LINE", "a\\x0aFAKE LINE"),
    ("\x07\x7f\x9b", "\\x07\\x7f\\x9b"),
    ("\u202eevil", "\\u202eevil"),
])
def test_printable(text, shown):
    assert printable(text) == shown
    if "\n" not in text:
        assert printable_lines(f"{text}\n{text}") == f"{shown}\n{shown}"


def test_shorten_shows_an_ellipsis_and_the_full_length():
    assert shorten("abc", 5) == "abc"
    assert shorten("x" * 1_048_576, 10) == "x" * 10 + "… (1048576 chars)"


def _hostile_recording(path, prefix):
    name = "dji" + ESCAPES
    msgs = unit_traffic(prefix, name, seconds=4)
    base = f"{prefix}/unit/air/simulation/{name}"
    msgs.append(Message(T0 + 2.2, f"{base}/exec/command", orjson.dumps(
        {"command": "ping", "com-uuid": "c" + ESCAPES, "sender": "op" + ESCAPES})))
    msgs.append(Message(T0 + 2.3, f"{base}/sensor/x{ESCAPES}", b"1" + ESCAPES.encode()))
    return write_recording(path, [*msgs, Event(T0 + 3.0, "disconnected", "lost " + ESCAPES)])


def test_lint_output_escapes_what_the_wire_sent(tmp_path, prefix):
    recording = _hostile_recording(tmp_path / "hostile.jsonl", prefix)
    run = run_lint(["--from", str(recording)], tmp_path / "reports")
    assert run.code == 1  # judged (TOPIC-008 and others fail)
    assert "PWNED-TITLE" in run.out and "\\x1b]0;PWNED-TITLE\\x07" in run.out
    assert not DANGEROUS.search(run.out), repr(DANGEROUS.search(run.out))


def test_a_violation_rendered_for_a_person_cannot_forge_lines():
    v = Violation.of("HB-003", expected="1 Hz", observed="x\n  rerun     rm -rf ~" + ESCAPES,
                     topic="waraps/unit/air/simulation/dji0/heartbeat", payload=ESCAPES)
    text = render_violation("HB-003", v, "waraps/unit/air/simulation/dji0")
    assert not DANGEROUS.search(text)
    assert [ln for ln in text.splitlines() if ln.strip().startswith("rerun")] == [
        "  rerun     pytest --unit waraps/unit/air/simulation/dji0 -k HB-003"]


def test_the_plain_and_terminal_scorecards_escape_unit_names(prefix):
    from conformance.checks import Monitor
    from conformance.lint.linter import Linter
    from conformance.lint.scorecard import Scorecard
    from conformance.profile import Profile

    name = "dji" + ESCAPES
    monitor = Monitor(Profile(), kind="lint")
    linter = Linter(monitor, Profile())
    linter.feed(unit_traffic(prefix, name, seconds=3))
    plain = io.StringIO()
    Scorecard(plain, tty=False).update(linter, force=True)
    assert "\\x1b]0;PWNED" in plain.getvalue() and not DANGEROUS.search(plain.getvalue())
    term = io.StringIO()
    card = Scorecard(term, tty=True)
    card.update(linter, force=True)
    card.close()
    drawn = term.getvalue()
    assert "\\u202eevil" in drawn  # the name's end, escaped (the column shows its end)
    # rich's own CSI (colour, cursor) only: no OSC, no bell, no clear screen, no C1.
    assert "\x1b]" not in drawn and "\x07" not in drawn and "\x1b[2J" not in drawn
    assert not re.search("[\x80-\x9f\u202a-\u202e]", drawn)

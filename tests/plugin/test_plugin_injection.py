"""Nothing a unit publishes drives the certifier's terminal: a level name
holding an OSC 52 clipboard write, a screen clear, a bidi override, a carriage return and a
forged ``PASSED`` line is shown escaped in the header and the summary's per-level lines."""

from __future__ import annotations

import re

import pytest
from certify_helpers import FAST, SilentUnit, certify

from conformance.topics import UnitAddress

LEVEL = "\x1b]52;c;cHduZWQ=\x07\x1b[2J\u202e\r\nPASSED \x9b1m\u200b\ufeff\U000e0041"
RAW = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\u200b\ufeff"
                 "\U000e0000-\U000e007f]")
"""What must never reach the terminal from the wire (our own line breaks aside)."""
REBOOT = "curl -X POST https://admin:p@ss w0rd#1@robot.local/reboot; echo \x1b[2J done"
"""A reboot command holding a password (with '@', ' ', '#') and an escape sequence."""


def test_a_hostile_level_name_is_escaped_in_the_header_and_summary(
        pytester: pytest.Pytester, mosquitto: str, unit_address: UnitAddress) -> None:
    with SilentUnit(str(unit_address), mosquitto, levels=("sensor", LEVEL)):
        run = certify(pytester, "--unit", str(unit_address), "--broker", mosquitto,
                      f"--profile={FAST}", "-k", "HB-001", f"--reboot-cmd={REBOOT}")
    text = run.text
    assert not RAW.search(text), repr(RAW.search(text))
    escaped = "\\x1b]52;c;cHduZWQ=\\x07\\x1b[2J\\u202e\\x0d\\x0aPASSED \\x9b1m\\u200b\\ufeff" \
              "\\U000e0041"
    header = [line for line in run.result.outlines if "levels:" in line]
    assert header and escaped in header[0], header
    summary = text[text.index("waraps-conformance ==="):]
    per_level = [line for line in summary.splitlines() if escaped in line]
    assert per_level and per_level[0].startswith("  "), summary  # the level's own line
    assert not any(line.startswith("PASSED") for line in text.splitlines())
    # The reboot command as the shell word it was given as, its password masked, escaped.
    shown = "--reboot-cmd 'curl -X POST https://admin:***@robot.local/reboot; echo \\x1b[2J done'"
    assert any(line.startswith("  reboot:") and shown in line for line in run.result.outlines)
    assert "w0rd" not in text and "p@ss" not in text


def test_the_not_alive_message_keeps_its_lines_and_escapes_the_wire(
        pytester: pytest.Pytester, mosquitto: str, prefix: str) -> None:
    """Our own line breaks print as line breaks; the address a unit publishes at (the wire's
    words) is escaped (it was the other way round: '...(broker ...).\\x0aA unit publishes')."""
    close = f"{prefix}/unit/air/simulation/dji0\u202e\u200b"  # Mosquitto refuses C0 and C1
    with SilentUnit(close, mosquitto):
        run = certify(pytester, "--unit", f"{prefix}/unit/air/simulation/dji0", "--broker",
                      mosquitto, f"--profile={FAST}")
    lines = run.text.splitlines()
    assert not RAW.search(run.text), repr(RAW.search(run.text))
    shown = f"{prefix}/unit/air/simulation/dji0\\u202e\\u200b"
    assert f"A unit publishes at {shown}: did you mean --unit {shown}?" in lines, run.text
    assert "\\x0a" not in run.text

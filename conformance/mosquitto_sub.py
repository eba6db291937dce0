"""What ``mosquitto_sub`` prints that a recording reader must undo (``conformance.recording``):
its ``tst`` times (local time, a stray 'Z', then the offset) and, with ``-F %j``, payloads cut
at their first NUL byte (measured with mosquitto_sub 2.0.11, ``tests/lint/test_recording.py``).
"""

from __future__ import annotations

import re
from datetime import datetime

MAX_EXAMINED_BYTES = 1 << 20
"""A payload is examined up to this (``validator.MAX_PAYLOAD_BYTES``, MSG-004)."""

# mosquitto_sub's tst: local time, a stray 'Z', then the offset ("...33.546275Z+0100").
_TST = re.compile(r"^(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d{1,9})?)Z?([+-]\d\d:?\d\d)?$")


def parse_tst(text: str) -> float:
    """Unix seconds of a mosquitto_sub ``tst`` value; ValueError if it is not one."""
    m = _TST.match(text)
    if m is None:
        raise ValueError(f"tst {text!r} is not an ISO 8601 time like 2026-11-21T06:26:33.546275Z+0000")
    stamp, offset = m.groups()
    if "." in stamp:  # fromisoformat takes 3 or 6 fraction digits only
        whole, frac = stamp.split(".")
        stamp = f"{whole}.{(frac + '000000')[:6]}"
    if offset is None:
        offset = "+00:00"
    elif ":" not in offset:
        offset = f"{offset[:3]}:{offset[3:]}"
    return datetime.fromisoformat(stamp + offset).timestamp()


def cut_at_nul(raw: bytes, length: int) -> bytes:
    """The payload ``mosquitto_sub -F %j`` cut at a NUL byte: what is known of it, then one NUL
    (which JSON text never holds: MSG-002 fails on it, as on the payload itself). A payload
    declared longer than a message is examined (MSG-004) is padded to one byte past that
    bound, no further: the declared length is never materialised (issue 26 §4)."""
    if length > MAX_EXAMINED_BYTES:
        return raw + bytes(MAX_EXAMINED_BYTES + 1 - len(raw)) if len(raw) <= MAX_EXAMINED_BYTES \
            else raw
    return raw + b"\x00"

"""The bounds of every input the tool reads: one place, named in the errors, in
``--help`` (``bounds_help``) and in the README's "Bounds" table.

A bound is never a silent cut: what lies past it is a finding on that line (a recording), a
refusal that names the bound (``validate``, a bag), or a failing finding that names what was
not judged (units past the fleet cap), never a pass.
"""

from __future__ import annotations

import hashlib
from typing import Any

MAX_LINE_BYTES = 64 << 20
"""A recording line longer than this is skipped as a problem of that line (a message is at
most 1 MiB examined, MSG-004; a base64 or escaped 10 MB payload still fits)."""
MAX_PAYLOAD_BYTES = MAX_LINE_BYTES
"""A payload as received (inside a line) or as declared (``mosquitto_sub -F %j``'s
``payloadlen``) larger than this is a problem of its line: nothing of that size is allocated."""
MAX_NESTING = 1024
"""JSON nesting of a recording line (orjson's own limit; deeper is a problem of the line). A
payload deeper than 64 levels is MSG-004's violation (``validator.MAX_DEPTH``)."""
MAX_LINE_VALUES = 1 << 20
"""A recording line over 1 MiB is read only if it holds at most this many JSON values (its
',', '[' and '{' bytes, counted before parsing): a 64 MiB line ``[{},{},...]`` would take
~2 GB as Python objects. Past it the line is a problem, as past the others."""
MIN_TIME = 0.0
MAX_TIME = 4_102_444_800.0
"""Recorded times (Unix seconds) from 1970-01-01 to 2100-01-01; a time outside is a problem
of its line (1e17 or 1e308 overflow every date conversion), and the run goes on."""
MAX_VALIDATE_BYTES = 16 << 20
"""What ``validate`` reads of a file or standard input; past it (``/dev/zero``) it stops and
says so (a message is examined up to 1 MiB, MSG-004)."""
MAX_UNITS = 4096
"""Units judged at once by lint (``checks.routes.MAX_UNITS``); the messages of further units
are not judged, and the run fails naming them."""
MAX_TOPICS_CACHED = 65536
"""Topics whose route is cached; further topics are still judged (looked up each time)."""
MAX_COMMANDERS = 256
"""Commanders with a row of their own; the commands of further ones share one row."""


def check_time(ts: float, what: str = "ts") -> float:
    """``ts`` if it is a time within the bounds (1970..2100), else ValueError naming them."""
    if not MIN_TIME <= ts <= MAX_TIME:  # NaN fails too
        raise ValueError(f"'{what}' {ts!r} is outside the times a recording may hold "
                         f"({MIN_TIME:.0f}..{MAX_TIME:.0f} Unix seconds, 1970 to 2100)")
    return ts


def _size(n: int) -> str:
    return f"{n >> 20} MiB" if n >= 1 << 20 and not n & ((1 << 20) - 1) else f"{n} bytes"


def bounds_help(*, validate: bool = False) -> str:
    """The bounds as one paragraph for ``--help``."""
    if validate:
        return (f"Bounds: at most {_size(MAX_VALIDATE_BYTES)} are read (more is refused, exit "
                f"2); a payload is examined up to 1 MiB and 64 levels of nesting (MSG-004).")
    return (f"Bounds: a recording line up to {_size(MAX_LINE_BYTES)}; a payload as received and "
            f"as declared (payloadlen) up to {_size(MAX_PAYLOAD_BYTES)}; JSON nesting of a line "
            f"up to {MAX_NESTING} levels (of a payload 64, MSG-004) and, in a line over 1 MiB, up "
            f"to {MAX_LINE_VALUES} values; times from 1970 to 2100 "
            f"({MIN_TIME:.0f}..{MAX_TIME:.0f} Unix seconds). A line past a bound is reported "
            f"as malformed and the run goes on. At most {MAX_UNITS} units are judged (past "
            f"that the run fails, naming what was not judged: narrow it with --unit or "
            f"--topic); {MAX_COMMANDERS} commanders have rows of their own; any number of topics "
            f"(the first {MAX_TOPICS_CACHED} cached); a ROS bag is read whole or refused "
            f"(exit 3).")

ID_CHARS = 1024
"""An identifier longer than this (a com-uuid, task-uuid, agent-uuid, ...) is kept as a
stand-in: its head, length and digest (``bound_ids``)."""
ID_KEYS = frozenset({"com-uuid", "task-uuid", "response-to", "agent-uuid", "node-uuid",
                     "root-uuid", "sender", "uuid"})
"""The fields the checks keep as keys of their histories (commands, tasks, trees, lives)."""


def bound_ids(m: Any, depth: int = 0) -> None:
    """Replace in ``m`` (a decoded message, in place) every identifier longer than ``ID_CHARS``
    by a stand-in of bounded size that still tells identifiers apart: the checks keep
    identifiers as keys (1024 commands per unit), and a 1 MiB com-uuid would be kept whole.
    The same identifier always gets the same stand-in, so answers still match commands."""
    if depth > 64:  # the validator refuses deeper payloads (MSG-004)
        return
    if isinstance(m, dict):
        for key, value in m.items():
            if isinstance(value, str):
                if len(value) > ID_CHARS and key in ID_KEYS:
                    digest = hashlib.blake2b(value.encode("utf-8", "surrogatepass"),
                                             digest_size=12).hexdigest()
                    m[key] = f"{value[:64]}… ({len(value)} chars, blake2b {digest})"
            elif isinstance(value, (dict, list)):
                bound_ids(value, depth + 1)
    elif isinstance(m, list):
        for value in m:
            if isinstance(value, (dict, list)):
                bound_ids(value, depth + 1)

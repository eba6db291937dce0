"""The conformance suite's own commands, as traffic shows them: its ``sender``, and the
deliberate probes it sends to test a unit's robustness (12.1: a unit must survive any command).

A recording made during a certification holds them. They are the suite's, never a commander's
fault (docs/ARCHITECTURE.md 'Whose fault it is'): the Monitor still lets the unit's
conversations learn of them (how the unit answers is the unit's), but judges no commander on
them, so lint of such a recording shows the unit's findings only.
"""

from __future__ import annotations

import re
from typing import Any

from conformance.checks.base import UnitState
from conformance.checks.rows import UNATTRIBUTED, Row
from conformance.checks.stash import StashKey
from conformance.results import Party
from conformance.topics import UnitAddress

SENDER = "waraps-conformance"
"""The ``sender`` of every command the suite publishes (``scenarios/sender.py``)."""

UNREADABLE: tuple[tuple[str, bytes], ...] = (
    ("invalid JSON", b'{"command": "ping", "com-uuid": '),
    ("not UTF-8", b"\xff\xfe\xfd{}"),
    ("a JSON array", b'[{"command": "ping"}]'),
    ("a JSON string", b'"ping"'),
    ("JSON null", b"null"),
    ("NaN, not JSON", b'{"command": "ping", "sender": NaN}'),
)
"""Probes with no readable com-uuid or sender (``scenarios/robust.py``): no answer is
expected; the unit must survive them. Known by their exact bytes."""

_PROBES = frozenset(payload for _, payload in UNREADABLE)
_SENDER = re.compile(rb'"sender"\s*:\s*"' + re.escape(SENDER.encode()) + rb'"')
SEEN: StashKey[bool] = StashKey("suite-commands")
"""The suite has commanded this unit (its sender was seen)."""
LABEL = "the conformance suite (deliberate probes)"
SUITE_ROW: StashKey[Row] = StashKey("suite-row")
"""The row the suite's commands to this unit are judged on (never reported)."""


def sent_by_suite(m: Any, payload: Any, unit: UnitState) -> bool:
    """Whether a command to ``unit`` (decoded ``m``, raw ``payload``) is the suite's: its
    ``sender`` (read from the JSON, or from the bytes of a malformed one), or, once the suite
    was seen commanding this unit, one of the suite's unreadable probes, byte for byte."""
    if isinstance(m, dict):
        ours = m.get("sender") == SENDER
    elif m is None and isinstance(payload, (bytes, bytearray)):
        ours = _SENDER.search(payload, 0, 65536) is not None
    else:
        ours = False
    if ours:
        unit.stash[SEEN] = True
        return True
    return unit.stash.get(SEEN, False) and isinstance(payload, (bytes, bytearray)) \
        and bytes(payload) in _PROBES


def suite_row(unit: UnitState, m: Any, payload: Any) -> Row | None:
    """The row the suite's command to ``unit`` is judged on (``sent_by_suite``), else None.
    The row is the unit's own and never reported: the Monitor reports only the commanders it
    keeps, so no commander is charged with the suite's probes."""
    if not sent_by_suite(m, payload, unit):
        return None
    row = unit.stash.get(SUITE_ROW)
    if row is None:
        row = unit.stash[SUITE_ROW] = Row(UnitState(UnitAddress(UNATTRIBUTED, "", "", LABEL)),
                                          Party.COMMANDER, LABEL)
    return row

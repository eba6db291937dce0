"""How busy this machine is, for the tests' deadlines: a deadline says when a run is hung or
lost, never how fast it should be, so it grows with the load the run shares the cores with
(CI's 2 cores ran the tests beside other jobs at a load of 6 to 13)."""

from __future__ import annotations

import os

MAX_SLACK = 8.0
"""A deadline grows at most this much: past it, a run that has not ended is hung."""


def slack() -> float:
    """1 on an idle machine; the load per core (the 1-minute mean) where that is higher."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        return 1.0
    return min(MAX_SLACK, max(1.0, load / (os.cpu_count() or 1)))


def deadline(seconds: float, at_least: float = 1.0) -> float:
    """``seconds`` on an idle machine, more on a busy one (``slack``, or ``at_least`` times
    where the load is yet to come)."""
    return seconds * max(at_least, slack())

"""The reference unit: a spec-conformant simulated WARA-PS unit with a switch for every fault
the suite detects (``waraps-conformance sim``): each check passes on it and fails on its fault.

``SimUnit`` runs one unit, ``Fleet`` N units on one connection; ``FAULTS`` lists the fault
switches and the rule ids each one breaks.
"""

from __future__ import annotations

from conformance.sim.faults import FAULTS, NOT_UNIT_BREAKABLE, Fault
from conformance.sim.fleet import Fleet, SimUnit

__all__ = ["FAULTS", "NOT_UNIT_BREAKABLE", "Fault", "Fleet", "SimUnit"]

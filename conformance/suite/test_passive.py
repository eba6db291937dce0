"""Rules no scenario drives: one test per rule, judged from everything the unit published during
the run by the same checks as the linter (the ``Monitor``), conversations included. They run
last, once the observation window is long enough for the declared rates (the profile's
``min_intervals``)."""

from __future__ import annotations

import pytest

from conformance.rules import CATALOGUE
from conformance.scenarios import RULE_SCENARIO
from conformance.suite.session import Certification
from conformance.suite.verdict import enact

PASSIVE = [pytest.param(r.id, id=r.id, marks=pytest.mark.waraps_rule(r.id))
           for r in CATALOGUE.values() if r.id not in RULE_SCENARIO]


@pytest.mark.parametrize("rule", PASSIVE)
def test_rule(certification: Certification, rule: str, request: pytest.FixtureRequest) -> None:
    """The verdict of one passive rule over the whole observation (after the scenarios whose
    traffic is its evidence: they have run already, unless this rule was selected alone)."""
    certification.run_evidence(rule)
    certification.wait_passive_window()
    enact(certification, rule, request.node)

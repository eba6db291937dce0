"""Active scenarios (spec 12, and 14's TST): one test per rule, each test id carrying its rule id.

A scenario runs once, the first time one of its rules is asked for; each of its tests then
reports the verdict of its own rule (so ``-k EXEC-PING-002`` runs ping and judges only that).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from conformance.scenarios import RULE_SCENARIO, SCENARIOS
from conformance.suite.session import Certification
from conformance.suite.verdict import enact


def scenario_test(scenario: str, doc: str) -> Callable[..., None]:
    """The test of ``scenario``: one item per rule it judges (``test_ping[EXEC-PING-001]``),
    each running the scenario (once in all) and enacting the verdict of its own rule."""

    @pytest.mark.parametrize("rule", [
        pytest.param(rule, id=rule, marks=pytest.mark.waraps_rule(rule))
        for rule in SCENARIOS[scenario].rules])
    def test(certification: Certification, rule: str, request: pytest.FixtureRequest) -> None:
        certification.run_scenario(RULE_SCENARIO[rule])
        enact(certification, rule, request.node)

    test.__doc__ = doc
    return test


test_ping = scenario_test(
    "ping", "12.2.1: ping is answered with a pong whose response-to is the ping's com-uuid.")
test_start_task = scenario_test(
    "start", "12.2.3: every task the profile allows runs, reports feedback and shows in 5.3's "
    "tasks-executing; a task-uuid left out is generated.")
test_signal_task = scenario_test(
    "signal", "12.2.2: every signal the unit lists is answered, with the feedback it implies.")
test_query_status = scenario_test(
    "query", "12.1: query-status over the whole history; 'unknown' for a task never seen.")
test_resend = scenario_test(
    "resend", "2, 12.1: a command resent with the same com-uuid is answered again, run once.")
test_tst = scenario_test(
    "tst", "14: trees run, report every node to a final status, take signals at node, tree and "
    "unit level; trees the unit cannot run are refused; a resent start-tst starts once.")
# After the scenarios whose evidence a death would destroy: its invalid parameters may kill
# a unit (scenarios/__init__.py).
test_start_task_refused = scenario_test(
    "refuse", "12.1: invalid parameters and tasks not in tasks-available are refused with a "
    "reason.")
test_robustness = scenario_test(
    "robust", "12.1: malformed and unknown commands do not stop the unit.")
test_reboot = scenario_test(
    "reboot", "5, 12.1: a reboot gives a new agent-uuid, and with it the history is gone.")

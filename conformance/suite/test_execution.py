"""Active scenarios (spec 12, and 14's TST): one test per rule, each test id carrying its rule id.

A scenario runs once, the first time one of its rules is asked for; each of its tests then
reports the verdict of its own rule (so ``-k EXEC-PING-002`` runs ping and judges only that).
"""

from __future__ import annotations

import pytest

from conformance.scenarios import SCENARIOS
from conformance.suite.session import Certification
from conformance.suite.verdict import enact


def rules_of(scenario: str) -> list:
    return [pytest.param(rule, id=rule, marks=pytest.mark.waraps_rule(rule))
            for rule in SCENARIOS[scenario].rules]


def judge(certification: Certification, rule: str, request: pytest.FixtureRequest) -> None:
    from conformance.scenarios import RULE_SCENARIO

    certification.run_scenario(RULE_SCENARIO[rule])
    enact(certification, rule, request.node)


@pytest.mark.parametrize("rule", rules_of("ping"))
def test_ping(certification: Certification, rule: str, request: pytest.FixtureRequest) -> None:
    """12.2.1: ping is answered with a pong whose response-to is the ping's com-uuid."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("start"))
def test_start_task(certification: Certification, rule: str,
                    request: pytest.FixtureRequest) -> None:
    """12.2.3: every task the profile allows runs, reports feedback and shows in 5.3's
    tasks-executing; a task-uuid left out is generated."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("refuse"))
def test_start_task_refused(certification: Certification, rule: str,
                            request: pytest.FixtureRequest) -> None:
    """12.1: invalid parameters and tasks not in tasks-available are refused with a reason."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("signal"))
def test_signal_task(certification: Certification, rule: str,
                     request: pytest.FixtureRequest) -> None:
    """12.2.2: every signal the unit lists is answered, with the feedback it implies."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("query"))
def test_query_status(certification: Certification, rule: str,
                      request: pytest.FixtureRequest) -> None:
    """12.1: query-status over the whole history; 'unknown' for a task never seen."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("resend"))
def test_resend(certification: Certification, rule: str,
                request: pytest.FixtureRequest) -> None:
    """2, 12.1: a command resent with the same com-uuid is answered again, run once."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("tst"))
def test_tst(certification: Certification, rule: str, request: pytest.FixtureRequest) -> None:
    """14: trees run, report every node to a final status, take signals at node, tree and
    unit level; trees the unit cannot run are refused; a resent start-tst starts once."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("robust"))
def test_robustness(certification: Certification, rule: str,
                    request: pytest.FixtureRequest) -> None:
    """12.1: malformed and unknown commands do not stop the unit."""
    judge(certification, rule, request)


@pytest.mark.parametrize("rule", rules_of("reboot"))
def test_reboot(certification: Certification, rule: str,
                request: pytest.FixtureRequest) -> None:
    """5, 12.1: a reboot gives a new agent-uuid, and with it the history is gone."""
    judge(certification, rule, request)

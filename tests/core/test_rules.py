"""The rule catalogue (conformance.rules) and its command (waraps-conformance rules)."""

from __future__ import annotations

import json
import re

import pytest

from conformance import rules
from conformance.cli import main as cli
from conformance.rules import CATALOGUE, Mode, Severity

ID = re.compile(r"^[A-Z]+(-[A-Z]+)*-\d{3}$")


def test_every_rule_is_complete() -> None:
    for rule in CATALOGUE.values():
        assert ID.match(rule.id), rule.id
        assert rule.title and rule.section, rule.id
        assert isinstance(rule.severity, Severity) and isinstance(rule.mode, Mode)


def test_every_erratum_records_its_decision() -> None:
    errata = [r for r in CATALOGUE.values() if r.is_erratum]
    # The issue names at least these contradictions of the v0.7 text.
    assert {"ERR-001", "ERR-002", "ERR-003", "ERR-004", "ERR-005", "ERR-006", "ERR-007",
            "ERR-008", "ERR-009", "ERR-010"} <= {r.id for r in errata}
    for rule in errata:
        assert len(rule.decision) > 40, f"{rule.id} states no decision"


def test_unknown_rule_id_suggests_close_ones() -> None:
    with pytest.raises(KeyError, match="did you mean HB-003"):
        rules.get("HB003")


def test_rules_command_prints_text_and_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["rules"]) == 0
    text = capsys.readouterr().out
    assert "HB-003" in text and "ERR-006" in text
    assert cli(["rules", "--format", "json", "--profile", "strict"]) == 0
    table = {r["id"]: r for r in json.loads(capsys.readouterr().out)}
    assert set(table) == set(CATALOGUE)
    assert table["ERR-001"]["severity"] == "error"  # strict turns errata into failures
    assert cli(["rules", "--errata"]) == 0
    errata = capsys.readouterr().out
    assert "decision: 5.2 says" in errata and "sensor_info is canonical" in errata
    assert "HB-003" not in errata


def test_unknown_command_says_what_exists(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["rule"]) == 2
    assert "Did you mean 'rules'" in capsys.readouterr().err


def test_headline_verdict_treats_skip_as_not_applicable() -> None:
    from conformance.violation import Verdict as V

    assert V.worst([V.PASS, V.SKIP]) is V.PASS
    assert V.worst([V.SKIP, V.SKIP]) is V.SKIP
    assert V.worst([V.PASS, V.SKIP, V.COULD_NOT_TEST]) is V.COULD_NOT_TEST
    assert V.worst([V.WARN, V.FAIL, V.PASS]) is V.FAIL
    assert V.worst([]) is V.PASS


def test_a_rules_level_is_a_level_of_5_1_or_the_suites_own() -> None:
    from conformance.topics import DIRECT_EXECUTION, LEVELS

    assert {level.value for level in rules.Level} == {*rules.PSEUDO_LEVELS, *LEVELS}
    assert rules.get("EXEC-PING-001").spec_level == DIRECT_EXECUTION
    assert rules.get("TOPIC-001").spec_level is None  # every unit is judged on its topics

"""The spec's own JSON examples (tests/spec/corpus): each valid one judged as expected, each
invalid one a MSG-002 (ERR-002) with its reason, and its evident reading judged too."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from conformance.profile import Profile, load
from conformance.rules import CATALOGUE, Severity
from conformance.validator import Validator
from conformance.violation import Verdict

CORPUS = Path(__file__).parent / "corpus"
INDEX = json.loads((CORPUS / "index.json").read_text("utf-8"))["examples"]
DEFAULT = load("default")


def verdict(rules: list[str], profile: Profile) -> str:
    return Verdict.worst([Verdict.FAIL if profile.severity_of(r) is Severity.ERROR
                          else Verdict.WARN for r in rules]).value


def judge(topic: str, payload: bytes, profile: Profile = DEFAULT) -> tuple[str, list[str]]:
    v = Validator(profile).validate(topic, payload, None)
    rules = sorted({x.rule for x in v.violations})
    return verdict(rules, profile), rules


def _ids(entries: list[dict[str, Any]]) -> list[str]:
    return [e["id"] for e in entries]


VALID = [e for e in INDEX if e["valid-json"]]
INVALID = [e for e in INDEX if not e["valid-json"]]


def test_corpus_covers_every_section_with_examples() -> None:
    sections = {e["section"] for e in INDEX}
    assert {"5.1", "5.2", "5.3", "12.2.1", "12.2.2", "12.3.1", "12.3.3", "12.4", "14.3.1",
            "14.4.4", "14.5"} <= sections
    assert {f"10.1.{i}" for i in range(1, 10)} <= sections
    assert {f"11.1.{i}" for i in range(1, 10)} <= sections
    assert len(VALID) == 28 and len(INVALID) == 10


@pytest.mark.parametrize("entry", VALID, ids=_ids(VALID))
def test_valid_spec_example_is_judged_as_expected(entry: dict[str, Any]) -> None:
    raw = (CORPUS / entry["raw"]).read_bytes()
    json.loads(raw)  # the corpus says it is JSON: prove it
    assert judge(entry["topic"], raw) == (entry["expected"]["verdict"],
                                          entry["expected"]["rules"])


@pytest.mark.parametrize("entry", INVALID, ids=_ids(INVALID))
def test_invalid_spec_example_is_msg_002_with_a_reason(entry: dict[str, Any]) -> None:
    raw = (CORPUS / entry["raw"]).read_bytes()
    with pytest.raises(ValueError):
        json.loads(raw)
    assert entry["invalid-because"] and entry["erratum"] == "ERR-002"
    assert judge(entry["topic"], raw) == ("fail", ["MSG-002"])


@pytest.mark.parametrize("entry", INVALID, ids=_ids(INVALID))
def test_repaired_reading_of_invalid_example_is_judged_as_expected(entry: dict[str, Any]) -> None:
    repaired = entry["repaired"]
    raw = (CORPUS / repaired["file"]).read_bytes()
    assert judge(entry["topic"], raw) == (repaired["expected"]["verdict"],
                                          repaired["expected"]["rules"])


def test_errata_hit_by_examples_are_warnings_by_default_and_fail_when_strict() -> None:
    strict = load("strict")
    hit = {r for e in VALID for r in e["expected"]["rules"]}
    assert hit == {"ERR-003", "ERR-004", "ERR-005", "ERR-012", "ERR-014"}
    for rule in hit:
        assert CATALOGUE[rule].severity is Severity.WARNING
        assert strict.severity_of(rule) is Severity.ERROR
    entry = next(e for e in VALID if e["id"] == "10.1.6")
    raw = (CORPUS / entry["raw"]).read_bytes()
    assert judge(entry["topic"], raw, strict) == ("fail", ["ERR-004"])

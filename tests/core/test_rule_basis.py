"""Every rule of the catalogue says what it stands on: the spec's words (stated), words
it follows from necessarily (implied), or a choice this suite made where the spec is silent or
contradicts itself (decided). Read from ``conformance/rules.toml`` with tomllib, not through
``conformance.rules``, so that the data is judged as written."""

from __future__ import annotations

import re
import tomllib
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CATALOGUE = ROOT / "conformance" / "rules.toml"
SPEC = ROOT / "docs" / "spec" / "waraps-core-api-0.7.txt"

ELISION = " [...] "
"""A quote may join verbatim passages with this mark (the spec itself never contains it)."""

COMMON = {"id", "title", "section", "severity", "level", "mode", "side", "condition"}
BASES: dict[str, tuple[set[str], set[str]]] = {
    # basis: (keys it must have, keys it may have besides COMMON)
    "stated": ({"quote"}, {"note"}),
    "implied": ({"quote", "because"}, {"note"}),
    "decided": ({"decision"}, {"quote"}),
}


def normalise(text: str) -> str:
    """Runs of whitespace (spaces, line breaks) become one space: the spec's text is a PDF's,
    broken into lines and pages."""
    return re.sub(r"\s+", " ", text).strip()


def quote_problems(quote: str, spec: str) -> list[str]:
    """The passages of ``quote`` (joined by ' [...] ') that do not occur verbatim in ``spec``
    (both whitespace-normalised); empty when the quote is verbatim."""
    passages = [normalise(p) for p in quote.split(ELISION)]
    if not all(passages):
        return [f"an empty passage in {quote!r}"]
    return [p for p in passages if p not in spec]


def basis_problems(rule: dict, spec: str) -> list[str]:
    """What is wrong with one catalogue entry's basis (empty when nothing is)."""
    basis = rule.get("basis")
    if basis not in BASES:
        return [f"basis {basis!r} is not one of {', '.join(BASES)}"]
    must, may = BASES[basis]
    problems = [f"{basis} needs {key}" for key in sorted(must)
                if not (isinstance(rule.get(key), str) and rule[key].strip())]
    unknown = set(rule) - COMMON - {"basis"} - must - may
    problems += [f"{key} is not a key of a {basis} rule" for key in sorted(unknown)]
    if isinstance(rule.get("quote"), str):
        problems += [f"not verbatim in the spec: {p!r}" for p in quote_problems(rule["quote"], spec)]
    return problems


@pytest.fixture(scope="module")
def rules() -> list[dict]:
    return tomllib.loads(CATALOGUE.read_text(encoding="utf-8"))["rule"]


@pytest.fixture(scope="module")
def spec() -> str:
    return normalise(SPEC.read_text(encoding="utf-8"))


def test_every_rule_has_a_basis_and_what_it_needs(rules: list[dict], spec: str) -> None:
    problems = {r["id"]: p for r in rules if (p := basis_problems(r, spec))}
    assert not problems, "\n".join(f"{rid}: {'; '.join(p)}" for rid, p in problems.items())


def test_every_condition_has_a_basis_and_what_it_needs(rules: list[dict], spec: str) -> None:
    """A rule's further conditions (``[[rule.condition]]``: a deadline, a tolerance, a closed
    list its words do not give) each stand on a basis of their own, checked as a rule's."""
    problems = {}
    for r in rules:
        for c in r.get("condition", ()):
            keys = {k: v for k, v in c.items() if k not in ("id", "title")}
            found = basis_problems(keys, spec)
            if not (isinstance(c.get("id"), str) and c["id"] and c.get("title")):
                found.append("a condition needs an id and a title")
            if found:
                problems[f"{r['id']}/{c.get('id')}"] = found
    assert not problems, "\n".join(f"{k}: {'; '.join(p)}" for k, p in problems.items())
    assert any(r.get("condition") for r in rules)


def test_every_erratum_is_decided(rules: list[dict]) -> None:
    # The errata are the readings of points where the spec contradicts itself: a choice.
    assert [r["id"] for r in rules if r["id"].startswith("ERR-") and r["basis"] != "decided"] == []


def test_the_issues_false_findings_are_not_stated(rules: list[dict]) -> None:
    # 6.1 says 'heading: float' (no range); v0.7 has no example of sensor/position;
    # 14.5 only lists statuses (no composite's status).
    basis = {r["id"]: r["basis"] for r in rules}
    assert basis["SENS-002"] == basis["ERR-010"] == basis["TST-010"] == "decided"


def test_a_planted_wrong_quote_is_found(rules: list[dict], spec: str) -> None:
    rule = next(r for r in rules if r["id"] == "SENS-002")
    assert basis_problems(rule, spec) == []
    planted = dict(rule, basis="stated", quote="heading : float in degrees [0, 360)")
    planted.pop("decision")
    assert basis_problems(planted, spec) == [
        "not verbatim in the spec: 'heading : float in degrees [0, 360)'"]
    # A verbatim passage joined to one that is not: only the second is named.
    joined = "The following sensors are mandatory: positon, heading, course, speed [...] heading in [0, 360)"
    assert quote_problems(joined, spec) == ["heading in [0, 360)"]
    # Line breaks and indentation in the quote or the spec do not matter; words do.
    assert quote_problems("Topics starts with a name,\n   e.g. waraps/ not /waraps/", spec) == []
    assert quote_problems("Topics start with a name, e.g. waraps/ not /waraps/", spec) != []


def test_a_basis_missing_its_fields_or_with_a_stray_one_is_found(spec: str) -> None:
    base = {"id": "X-001", "title": "t", "section": "5", "severity": "error", "level": "any",
            "mode": "passive"}
    assert basis_problems(dict(base, basis="assumed"), spec) == [
        "basis 'assumed' is not one of stated, implied, decided"]
    assert basis_problems(dict(base, basis="implied", quote="List of tasks currently executing."),
                          spec) == ["implied needs because"]
    assert basis_problems(dict(base, basis="decided", decision="d", because="b"), spec) == [
        "because is not a key of a decided rule"]
    assert basis_problems(dict(base, basis="stated", quote="List of tasks currently executing.",
                               decision="d"), spec) == ["decision is not a key of a stated rule"]


def test_the_readme_counts_rules_by_basis(rules: list[dict]) -> None:
    text = normalise((ROOT / "README.md").read_text(encoding="utf-8"))
    start = text.index("## The rule catalogue")
    section = text[start:text.find(" ## ", start + 1)]
    found = re.search(r"(\d+) are \*stated\*.*?(\d+) \*implied\*.*?(\d+) \*decided\*", section)
    assert found, "the README's rule catalogue section gives no counts by basis"
    counts = Counter(r["basis"] for r in rules)
    assert [int(n) for n in found.groups()] == [
        counts["stated"], counts["implied"], counts["decided"]], (
        f"README counts {found.groups()}; the catalogue has {dict(counts)}")


def test_a_decided_basis_never_reads_as_a_failure_next_to_a_warn_badge() -> None:
    """A decided rule warns unless the arena adopts it: its basis says so, whatever verb its
    decision uses (SENS-003's 'fails a negative value' stood beside a warn badge)."""
    from conformance.rules import CATALOGUE, Basis

    for rule in CATALOGUE.values():
        if rule.basis is Basis.DECIDED:
            assert rule.basis_text().startswith(
                "decided (the spec does not say; a finding warns, and fails only where the "
                "arena adopts it"), rule.id
    assert "flags a negative value" in CATALOGUE["SENS-003"].basis_text()

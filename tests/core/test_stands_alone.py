"""The repository stands alone: what its code, tests and docs cite is in the repository.

A maintainer who takes the project over has its files, not the tracker it was built with nor
the notes beside it: no "issue N", no path out of the repository (``../shared``), no design or
style notes kept beside it (the why said in our own words, or cited from ``docs/``), the
measured facts cited from ``docs/FIELD-NOTES.md`` only, and every heading cited from ``docs/``
there."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SEARCHED = ("conformance", "tests", "docs", "fuzz", "bench", "schemas", "profiles", ".ci",
            "README.md", "pyproject.toml")
FORBIDDEN = {
    "an issue number (say why instead)": re.compile(r"\bissues?\s+#?\d+", re.IGNORECASE),
    "a path out of the repository": re.compile(r"\.\./shared|/work/shared"),
    "FIELD-NOTES outside docs/ (cite docs/FIELD-NOTES.md)": re.compile(
        r"(?<!docs/)FIELD-NOTES"),
    "a design or style note not in the repository (say why, or cite docs/)": re.compile(
        r"\b(?:DESIGN|STYLE)\b"),
}
TEXT = {".py", ".md", ".toml", ".txt", ".yaml", ".yml", ".json", ".j2", ".html", ".css",
        ".js", ".cfg", ".ini", ""}
"""Suffixes read (a file without one: ``.ci/run``); the fuzzers' saved inputs are data."""


def _files() -> list[Path]:
    out = []
    for name in SEARCHED:
        path = ROOT / name
        found = [path] if path.is_file() else sorted(path.rglob("*"))
        out += [p for p in found if p.is_file() and p.suffix in TEXT
                and "__pycache__" not in p.parts and "regressions" not in p.parts
                and p.stat().st_size < 2_000_000]
    return out


def test_nothing_cites_what_a_maintainer_does_not_have() -> None:
    found = []
    for path in _files():
        if path in (ROOT / "docs" / "FIELD-NOTES.md", Path(__file__).resolve()):
            continue  # the notes themselves; this test, which names what it looks for
        text = path.read_text(encoding="utf-8", errors="replace")
        for what, pattern in FORBIDDEN.items():
            for match in pattern.finditer(text):
                line = text.count("\n", 0, match.start()) + 1
                found.append(f"{path.relative_to(ROOT)}:{line}: {what}: {match.group(0)!r}")
    assert found == []


def test_the_headings_cited_from_docs_are_there() -> None:
    """``docs/FIELD-NOTES.md 'Precision'``, ``docs/ARCHITECTURE.md 'Safety'``: a heading of
    that document (any level), so a reader who follows the citation finds it."""
    cited = re.compile(r"docs/([A-Z][A-Z-]*)\.md\s+'([^']+)'")
    missing = []
    for path in _files():
        if path.name == "FIELD-NOTES.md":
            continue  # it shows how to cite one of its headings, with a placeholder
        for m in cited.finditer(path.read_text(encoding="utf-8", errors="replace")):
            doc = ROOT / "docs" / f"{m.group(1)}.md"
            text = doc.read_text(encoding="utf-8") if doc.is_file() else ""
            headings = {line.lstrip("#").strip() for line in text.splitlines()
                        if line.startswith("#")}
            if " ".join(m.group(2).replace("#", " ").split()) not in headings:
                missing.append(f"{path.relative_to(ROOT)}: {m.group(1)}.md {m.group(2)!r}")
    assert missing == []

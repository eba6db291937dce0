"""Extract every JSON example of the spec into raw text files (how the corpus was made).

    python tests/spec/corpus/extract.py docs/spec/waraps-core-api-0.7.txt OUT_DIR

Each example is the text between its section heading and the next, from the first line that is
"{" to the last that ends with "}", with code fences, page-break blank lines and footnotes
removed; a section with several examples (5.2, 12.2.2, 14.5) is split at each "{" in column 0. The raw texts are
then judged by hand in ``index.json`` (topic, expected verdict and rules, erratum). Not run by
the tests: the corpus is committed so the tests do not need the spec file.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

SECTIONS = ["5.1", "5.2", "5.3", *[f"10.1.{i}" for i in range(1, 10)],
            *[f"11.1.{i}" for i in range(1, 10)], "12.2.1", "12.2.2", "12.3.1", "12.3.3",
            "12.4", "14.3.1", "14.3.2", "14.3.3", "14.4.1", "14.4.2", "14.4.3", "14.4.4", "14.5"]
MULTIPLE = {"5.2", "12.2.2", "14.5"}  # sections that show several examples one after another
HEADING = re.compile(r"^(\d+(\.\d+)*)\s+\S")
FOOTNOTE = re.compile(r"^[\u00b9\u00b2\u00b3\u2070-\u2079]+<")


def examples(spec_text: str) -> dict[str, list[str]]:
    lines = spec_text.split("\n")
    starts = {}
    for i, line in enumerate(lines):
        m = HEADING.match(line)
        if m and m.group(1) in SECTIONS and i > 200:  # past the table of contents
            starts[m.group(1)] = i
    ordered = sorted(starts.items(), key=lambda kv: kv[1])
    out: dict[str, list[str]] = {}
    for section, start in ordered:
        end = len(lines)
        for j in range(start + 1, len(lines)):
            if HEADING.match(lines[j]) and not lines[j].startswith(" "):
                end = j
                break
        body = [ln.rstrip() for ln in lines[start + 1:end]
                if not ln.strip().startswith("```") and ln.strip()
                and not FOOTNOTE.match(ln.strip())]
        first = next((k for k, ln in enumerate(body) if ln.strip() == "{"), None)
        if first is None:
            continue
        last = max(k for k, ln in enumerate(body) if ln.strip().endswith("}"))
        body = body[first:last + 1]
        parts: list[list[str]] = []
        for ln in body:
            if ln.strip() == "{" and not ln.startswith(" ") and (
                    not parts or (section in MULTIPLE and parts[-1])):
                parts.append([])
            parts[-1].append(ln)
        out[section] = ["\n".join(p) + "\n" for p in parts]
    return out


def main(argv: list[str]) -> int:
    spec, out_dir = Path(argv[0]), Path(argv[1])
    out_dir.mkdir(parents=True, exist_ok=True)
    for section, texts in examples(spec.read_text("utf-8")).items():
        for k, text in enumerate(texts, 1):
            name = f"{section}" + (f"-{k}" if len(texts) > 1 else "") + ".txt"
            (out_dir / name).write_text(text, "utf-8")
            print(name)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

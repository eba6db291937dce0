"""``python -m fuzz TARGET [libFuzzer options] [CORPUS_DIR ...]``: one target under libFuzzer,
the code under test instrumented for coverage."""

from __future__ import annotations

import importlib
import sys

from fuzz import TARGETS
from fuzz.harness import run


def main(argv: list[str]) -> int:
    if len(argv) < 2 or argv[1] not in TARGETS:
        print(f"usage: python -m fuzz TARGET [libFuzzer options] [CORPUS ...]; "
              f"TARGET is one of {', '.join(TARGETS)}", file=sys.stderr)
        return 2
    import atheris

    with atheris.instrument_imports(include=["conformance"]):
        module = importlib.import_module(f"fuzz.{argv[1]}")
        module.prepare()
    run(module.test_one_input, [argv[0], *argv[2:]])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

"""``waraps-conformance schemas generate [--out DIR] [--check]``: regenerate the JSON Schemas
and TASKS.md from ``schemas/tasks/*.yaml`` (the generator: ``conformance.specgen``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from conformance.cli import options as opts


def build_parser() -> argparse.ArgumentParser:
    parser = opts.parser("schemas",
                         "Generate the JSON Schemas and TASKS.md from schemas/tasks/*.yaml.")
    sub = parser.add_subparsers(dest="action")
    gen = sub.add_parser("generate", help="write schemas/generated/ (deterministic; the default)")
    gen.add_argument("--out", type=Path, default=None,
                     help="output folder (default: schemas/generated of the source tree)")
    gen.add_argument("--check", action="store_true",
                     help="write nothing; exit 1 and list the files that are stale")
    return parser


def main(argv: list[str] | None = None) -> int:
    from conformance.specgen import REGENERATE, default_out_dir, stale_files, write

    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        argv.insert(0, "generate")  # `schemas` alone (or with options) generates
    args = build_parser().parse_args(argv)
    out_dir = args.out or default_out_dir()
    if args.check:
        stale = stale_files(out_dir)
        for rel in stale:
            print(f"stale: {out_dir / rel}")
        if stale:
            print(f"run `{REGENERATE}` and commit schemas/generated/", file=sys.stderr)
        return 1 if stale else 0
    written = write(out_dir)
    print(f"wrote {len(written)} files to {out_dir}")
    return 0

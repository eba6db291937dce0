"""``waraps-conformance demo``: certify the bundled reference unit on the embedded broker, end to
end, in one command (a newcomer sees it work before reading anything); the run is
``conformance.demo.certify``."""

from __future__ import annotations

import argparse
import sys

from conformance.cli import options as opts


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser("demo", "Certify the bundled reference unit on the embedded broker, end to "
                            "end.")
    opts.add_reference_unit_options(p)
    opts.add_profile_option(p, default=None)
    opts.add_reports_dir_option(p)
    p.add_argument("--seed", default=None, metavar="N",
                   help="seed of generated task parameters")
    p.add_argument("-q", "--quiet", action="store_true", help="pytest -q")
    p.add_argument("pytest_args", nargs="*", help="more pytest arguments, after --")
    return p


def main(argv: list[str] | None = None) -> int:
    from conformance.demo import certify
    from conformance.topics import UnitAddress

    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        UnitAddress.parse(args.unit)
    except ValueError as e:
        opts.say("demo", f"--unit: {e}")
        return 2
    return certify(args.unit, rate=args.rate, faults=args.fault, variants=args.variant,
                   profile=args.profile,
                   tst=args.tst, reports_dir=args.reports_dir, seed=args.seed,
                   quiet=args.quiet, pytest_args=args.pytest_args)

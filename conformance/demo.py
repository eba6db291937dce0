"""``waraps-conformance demo``: certify the bundled reference unit on the embedded broker, end to
end, in one command (DESIGN: 'A newcomer sees it work in one command').

It runs ``pytest --unit waraps/unit/air/simulation/dji0 --broker embedded`` in this process:
the plugin starts the embedded amqtt broker on a free loopback port and the reference unit
(``conformance.sim``) on it, runs the packaged suite against them, and writes the reports.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from conformance.topics import UnitAddress

DEFAULT_UNIT = "waraps/unit/air/simulation/dji0"


class _Collector:
    """Remembers where the certification wrote its reports (read after pytest.main)."""

    def __init__(self) -> None:
        self.paths: dict[str, Any] = {}

    def pytest_unconfigure(self, config: Any) -> None:
        from conformance.suite.session import CERTIFICATION

        found = config.stash.get(CERTIFICATION, None)
        if found is not None:
            self.paths = dict(found.report_paths)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="waraps-conformance demo",
        description="Certify the bundled reference unit on the embedded broker, end to end.")
    p.add_argument("--unit", default=DEFAULT_UNIT, help=f"its address (default {DEFAULT_UNIT})")
    p.add_argument("--rate", type=float, default=1.0, help="its heartbeat rate in Hz (default 1)")
    p.add_argument("--fault", action="append", default=[], metavar="FAULT",
                   help="switch on a fault of the reference unit, to see a failure "
                        "(see waraps-conformance sim --list-faults)")
    p.add_argument("--profile", default=None, help="profile name or file (default: default)")
    p.add_argument("--tst", action="store_true",
                   help="the reference unit also declares 'tst execution' (14): certify both")
    p.add_argument("--reports-dir", default="reports", help="where the reports go")
    p.add_argument("--seed", default=None, help="seed of generated task parameters")
    p.add_argument("-q", "--quiet", action="store_true", help="pytest -q")
    p.add_argument("pytest_args", nargs="*", help="more pytest arguments, after --")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        UnitAddress.parse(args.unit)
    except ValueError as e:
        print(f"waraps-conformance demo: --unit: {e}", file=sys.stderr)
        return 2
    import pytest

    # --opt=value for paths: pytest picks its rootdir before it knows plugin options, and a
    # path in its own argument would be taken for a test path there.
    command = ["--unit", args.unit, "--broker", "embedded", f"--reports-dir={args.reports_dir}",
               "-p", "no:cacheprovider", "-o", "addopts=", "-rfEsw"]
    if args.rate != 1.0:
        command += ["--sim-rate", str(args.rate)]
    command += [f"--sim-fault={f}" for f in args.fault]
    if args.tst:
        command.append("--sim-tst")
    if args.profile:
        command += [f"--profile={args.profile}"]
    if args.seed is not None:
        command += ["--seed", str(args.seed)]
    if args.quiet:
        command.append("-q")
    command += args.pytest_args
    print("waraps-conformance demo: pytest " + " ".join(command), flush=True)
    collector = _Collector()
    code = int(pytest.main(command, plugins=[collector]))
    if collector.paths:
        print("\nreports:")
        for kind, path in sorted(collector.paths.items()):
            print(f"  {kind:5} {path}")
    verdict = "passed" if code == 0 else f"did not pass (pytest exit status {code})"
    print(f"\nthe reference unit {args.unit} {verdict}"
          + ("" if code == 0 or args.fault else ": this is a bug, please report it"))
    return code


if __name__ == "__main__":
    sys.exit(main())

"""``waraps-conformance demo``: certify the bundled reference unit on the embedded broker, end to
end, in one command: a newcomer sees it work before reading anything.

``certify`` runs ``pytest --unit waraps/unit/air/simulation/dji0 --broker embedded`` in this
process: the plugin starts the embedded amqtt broker on a free loopback port and the reference unit
(``conformance.sim``) on it, runs the packaged suite against them, and writes the reports.
Its command line is ``conformance.cli.demo``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from conformance.display import shown
from conformance.suite.session import CERTIFICATION


class _Collector:
    """Remembers where the certification wrote its reports (read after pytest.main)."""

    def __init__(self) -> None:
        self.paths: dict[str, Any] = {}

    def pytest_unconfigure(self, config: Any) -> None:
        found = config.stash.get(CERTIFICATION, None)
        if found is not None:
            self.paths = dict(found.reports.paths)


def certify(unit: str, *, rate: float = 1.0, faults: Sequence[str] = (),
            variants: Sequence[str] = (), profile: str | None = None, tst: bool = False, reports_dir: str = "reports",
            seed: str | None = None, quiet: bool = False,
            pytest_args: Sequence[str] = ()) -> int:
    """Certify the reference unit at ``unit`` (rate in Hz, with ``faults`` and ``variants``
    switched on) on the
    embedded broker, in this process; print the command, where the reports went and the
    verdict. Returns pytest's exit status."""
    import pytest

    # --opt=value for paths: pytest picks its rootdir before it knows plugin options, and a
    # path in its own argument would be taken for a test path there.
    command = ["--unit", unit, "--broker", "embedded", f"--reports-dir={reports_dir}",
               "-p", "no:cacheprovider", "-o", "addopts=", "-rfEw"]  # skips: grouped in the summary
    if rate != 1.0:
        command += ["--sim-rate", str(rate)]
    command += [f"--sim-fault={f}" for f in faults]
    command += [f"--sim-variant={v}" for v in variants]
    if tst:
        command.append("--sim-tst")
    if profile:
        command += [f"--profile={profile}"]
    if seed is not None:
        command += ["--seed", str(seed)]
    if quiet:
        command.append("-q")
    command += pytest_args
    print(shown("waraps-conformance demo: pytest " + " ".join(command)), flush=True)
    collector = _Collector()
    code = int(pytest.main(command, plugins=[collector]))
    if collector.paths:
        print("\nreports:")
        for kind, path in sorted(collector.paths.items()):
            print(shown(f"  {kind:5} {path}"))
    verdict = "passed" if code == 0 else f"did not pass (pytest exit status {code})"
    print(f"\nthe reference unit {shown(unit)} {verdict}"
          + ("" if code == 0 or faults else ": this is a bug, please report it"))
    return code

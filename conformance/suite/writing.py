"""A certification's report files: reports/<unit>-<time>.json and .html, written atomically
(``conformance.reporting.write_all``) during the run, at most once a second, so they survive a
Ctrl-C, and once more at the end; where they went, or why they could not be written."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

from conformance.clock import Clock
from conformance.reporting import write_all
from conformance.reporting.bounds import file_stem
from conformance.results import RunReport
from conformance.suite.events import Events
from conformance.topics import UnitAddress
from conformance.violation import Verdict


class Reports:
    """Writes one certification's reports into ``folder``."""

    def __init__(self, unit: UnitAddress, folder: Path, clock: Clock, events: Events,
                 report: Callable[..., RunReport], rerun: Callable[[str], str]) -> None:
        self.unit, self.folder, self.clock, self.events = unit, folder, clock, events
        self._report, self._rerun = report, rerun
        when = time.strftime('%Y%m%dT%H%M%S', time.localtime())
        self.stem = f"{file_stem(unit.name)}-{when}"  # a bounded file name
        self.paths: dict[str, Path] = {}
        self.error = ""
        """Why the last report could not be written ('' when it was)."""
        self._last_write = 0.0

    def write(self, *, force: bool = False, exit_status: str | None = None,
              final: RunReport | None = None) -> dict[str, Path]:
        """Write the reports (at most once a second unless ``force``); ``exit_status`` and
        ``final``: the finished run's status and report (``Judging.conclude``)."""
        now = self.clock.monotonic()
        if not force and now - self._last_write < 1.0:
            return self.paths
        self._last_write = now
        report = final if final is not None else self._report()
        unit = report.units.get(str(self.unit))
        reruns = [r.rule for r in (unit.rules.values() if unit is not None else ())
                  if r.verdict in (Verdict.FAIL, Verdict.WARN)]  # the lines the terminal prints
        report.meta = dataclasses.replace(report.meta, exit_status=exit_status,
                                          rerun_of={r: self._rerun(r) for r in reruns})
        try:
            self.paths = write_all(report, self.folder, self.stem)
        except OSError as e:
            # The next write tries again; the final one says it, and the run keeps its own
            # exit status (a folder removed or filled during the run is no traceback).
            self.error = (f"could not write the reports into {self.folder}: "
                          f"{e.strerror or e}")
            if not force:
                self.events.append(self.error)
        else:
            self.error = ""
        return self.paths

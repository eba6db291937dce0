"""Passive linting of a whole fleet, live or recorded (``waraps-conformance lint``).

Parts: ``capture`` (live subscription, bounded buffer, connection events), ``linter`` (feeds the
shared passive checks, ``conformance.checks.Monitor``, and keeps tallies), ``runner`` (one lint
run: source, scorecard, reports, exit status), ``recorder`` (``waraps-conformance record``),
``scorecard`` (the live per-unit view on the terminal); the recording formats are
``conformance.recording``, the command line ``conformance.cli.lint``. Importing this package loads nothing else.
"""

from __future__ import annotations

from conformance.exits import EXIT_LINT_PARTIAL as EXIT_PARTIAL  # noqa: F401 (its one home)

REPORT_FORMATS = ("json", "html", "junit")
"""What ``lint --report-format`` may name (all three by default)."""

EXIT_PASS, EXIT_FAIL, EXIT_USAGE, EXIT_NOT_RUN = 0, 1, 2, 3
"""Exit status of a lint: no unit (or commander) fails a rule of severity error; one does; bad
usage; nothing could be linted (no broker, no messages); ``EXIT_PARTIAL`` (4): none fails, but
part of the evidence could not be examined (malformed lines, payloads past a bound)."""

"""tests/plugin: ``pytest --unit`` run inside pytest (pytester); helpers in certify_helpers.py."""

from __future__ import annotations

# Imported before any in-process run so they stay loaded across runs: generated task
# parameters are cached per (task, seed) and hypothesis warms up once per worker.
import conformance.scenarios  # noqa: F401
import conformance.suite.session  # noqa: F401

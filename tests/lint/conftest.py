"""Fixtures of the linter's tests; helpers are in ``lint_helpers``."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def reports_dir(tmp_path: Path) -> Path:
    """Where a lint run under test writes its reports."""
    return tmp_path / "reports"

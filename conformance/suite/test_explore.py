"""Exploration: after the scripted scenarios, command orders no script has, drawn
by hypothesis within a budget (``--explore``), every answer judged by the Monitor; a
disagreement fails this test with its story, whose rerun line replays it."""

from __future__ import annotations

import pytest

from conformance.suite import exploration
from conformance.suite.session import Certification


@pytest.mark.waraps_explore
def test_explore(certification: Certification, request: pytest.FixtureRequest) -> None:
    """12: start-task, every built-in signal to any task, query-status, resends, ping and
    waits in orders drawn by hypothesis; the unit answers each as the model says."""
    exploration.run(certification, request.node)

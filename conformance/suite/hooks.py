"""Hooks the certification plugin offers to other plugins and conftest files."""

from __future__ import annotations

import pytest


@pytest.hookspec(firstresult=True)
def pytest_waraps_reboot(config: pytest.Config, unit: str) -> bool | None:
    """Reboot the unit under test (``unit`` is its address), for REBOOT-001 and REBOOT-002.

    Return True once the reboot has been started (the suite then waits for the unit to come
    back, with a deadline), or None to leave it to ``--reboot-cmd``. Example, in a conftest.py
    of a team whose simulator runs in the test process::

        def pytest_waraps_reboot(config, unit):
            my_simulator.restart()
            return True
    """

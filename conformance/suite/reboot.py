"""How a certification reboots the unit under test (REBOOT-001, REBOOT-002): a
``pytest_waraps_reboot`` hook, else ``--reboot-cmd``, else the bundled reference unit's own
reboot under ``--broker embedded``; with none of them the REBOOT-* rules could not be tested."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from conformance.suite.connection import Connection
from conformance.suite.events import Events
from conformance.suite.settings import Settings


@dataclass(eq=False)
class Reboot:
    """Reboots the unit; ``requested(t)`` is told the time first (Unix seconds)."""

    config: pytest.Config
    connection: Connection
    timeout: float
    """Seconds --reboot-cmd may take."""
    requested: Callable[[float], None]
    events: Events

    @property
    def settings(self) -> Settings:
        return self.connection.settings

    def how(self) -> str:
        """The way the unit is rebooted, in the words of the option that says so."""
        if self.settings.reboot_cmd:
            return f"--reboot-cmd {self.settings.reboot_cmd!r}"
        if self.settings.embedded:
            return "the bundled reference unit's reboot"
        return "a pytest_waraps_reboot hook"

    def available(self) -> bool:
        hooks = self.config.pluginmanager.hook.pytest_waraps_reboot.get_hookimpls()
        return bool(self.settings.reboot_cmd or self.settings.embedded or hooks)

    def __call__(self) -> str | None:
        """Reboot the unit; None when done, else what went wrong. The time of the reboot is
        marked as a gap in the observation: a rebooting unit is allowed its silence there
        (REBOOT-001 judges the reboot itself)."""
        now = self.connection.traffic.clock.now()
        self.requested(now)
        self.events.at(now, f"reboot requested ({self.how()})")
        if self.config.pluginmanager.hook.pytest_waraps_reboot(
                config=self.config, unit=str(self.settings.unit)):
            return None
        if self.settings.reboot_cmd:
            try:
                done = subprocess.run(self.settings.reboot_cmd, shell=True, capture_output=True,
                                      text=True, timeout=self.timeout)
            except subprocess.TimeoutExpired:
                return f"did not finish within {self.timeout:.1f} s"
            if done.returncode != 0:
                err = (done.stderr or done.stdout).strip().splitlines()
                return f"exit status {done.returncode}" + (f": {err[-1]}" if err else "")
            return None
        if self.connection.reference is not None:
            self.connection.reference.reboot()
            return None
        return "no way to reboot the unit"

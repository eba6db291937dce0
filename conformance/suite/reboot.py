"""How a certification reboots the unit under test (REBOOT-001, REBOOT-002): a
``pytest_waraps_reboot`` hook, else ``--reboot-cmd``, else the bundled reference unit's own
reboot under ``--broker embedded``; with none of them the REBOOT-* rules could not be tested.
Around the reboot, ``Names`` watches for the unit coming back under another name."""

from __future__ import annotations

import os
import shlex
import subprocess
import threading
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from conformance.client import BrokerError, MqttClient
from conformance.masking import mask_password
from conformance.message import Message
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
            # As a shell word, never with a password; escaped where shown.
            return f"--reboot-cmd {shlex.quote(mask_password(self.settings.reboot_cmd))}"
        if self.settings.embedded:
            return "the bundled reference unit's reboot"
        return "a pytest_waraps_reboot hook"

    def watch_names(self) -> Names:
        """A watch, started now, on the heartbeats of units of the unit's type and role: the
        reboot scenario asks it for a name that appeared after the reboot."""
        return Names(self.connection, self.settings.unit.base).start()

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
                return f"exit status {done.returncode}" + (
                    f": {mask_password(err[-1])}" if err else "")
            return None
        if self.connection.reference is not None:
            self.connection.reference.reboot()
            return None
        return "no way to reboot the unit"


NAMES_KEPT = 64
"""Unit names a ``Names`` watch remembers at most (the rest are not followed)."""


class Names:
    """A read-only watch on ``<prefix>/unit/<type>/<role>/+/heartbeat``: when each unit name
    of the unit's type and role first heartbeated (live, not retained). Some agents add a
    random suffix to their name at every start (docs/FIELD-NOTES.md 'Real agents certified live':
    ``cppl2_9d00``): after the reboot
    the suite requested, a name first heard then is the unit, back under another name."""

    def __init__(self, connection: Connection, base: str) -> None:
        self._connection, self._base = connection, base
        self._own = base.rpartition("/")[2]
        self._first: dict[str, float] = {}
        self._changed = threading.Condition()
        self._client: MqttClient | None = None

    def start(self) -> Names:
        prefix = self._base.rpartition("/")[0]
        if self._connection.settings.virtual:  # the test suite's broker double, its own time
            from conformance.sim.virtual import VirtualReference

            reference = self._connection.reference
            if isinstance(reference, VirtualReference):
                reference.broker.subscribe(f"{prefix}/+/heartbeat", self._seen)
            return self
        try:
            self._client = MqttClient(self._connection.broker_url, on_message=self._seen)
            self._client.connect()
            self._client.subscribe(f"{prefix}/+/heartbeat")
        except BrokerError:
            self._client = None  # the reboot is judged without it, as before
        return self

    def _seen(self, m: Message) -> None:
        name = m.topic.rsplit("/", 2)[-2]
        if m.retain or name == self._own or name in self._first:
            return
        with self._changed:
            if len(self._first) < NAMES_KEPT:
                self._first[name] = m.time
                self._changed.notify_all()

    def heard(self) -> set[str]:
        """The names heard so far (of other units of the same type and role)."""
        with self._changed:
            return set(self._first)

    def new_name(self, known: set[str], since: float, wait: float) -> str | None:
        """A name not in ``known`` first heard at or after ``since`` (Unix seconds), waiting
        up to ``wait`` seconds for one; None when none came. Of several, the one sharing the
        longest beginning with the unit's own name (an agent that adds a random suffix per
        start: cppl2_vvhp back as cppl2_4b3f), then the first heard: another unit of the same
        type and role, slower than the window ``known`` was read in, is not named for it."""
        clock = self._connection.traffic.clock
        deadline = clock.monotonic() + wait
        with self._changed:
            while True:
                found = sorted((-_shared(n, self._own), t, n) for n, t in self._first.items()
                               if n not in known and t >= since)
                left = deadline - clock.monotonic()
                if found or left <= 0:
                    return found[0][2] if found else None
                clock.wait(self._changed, left)

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None


def _shared(name: str, own: str) -> int:
    """How many leading characters ``name`` shares with ``own``."""
    return len(os.path.commonprefix([name, own]))

"""The public face of the reference unit: ``SimUnit`` (one unit) and ``Fleet`` (N units in one
process, on one MQTT connection), each running in a background thread.

>>> with SimUnit(UnitAddress.parse("waraps/unit/air/simulation/dji0"), broker.url) as unit:
...     unit.agent_uuid          # it heartbeats, publishes its sensors and answers commands
...     unit.reboot(wait=True)   # silent for a moment, history lost, a new agent-uuid
"""

from __future__ import annotations

import random
import re
from collections.abc import Iterable, Mapping
from typing import TypeVar

from conformance.client import BrokerURL
from conformance.sim.faults import check_names
from conformance.sim.runtime import Runtime, spread
from conformance.sim.unit import UnitCore
from conformance.sim.variants import check_variants
from conformance.sim.vehicle import LINKOPING, GeoPoint, destination
from conformance.topics import UnitAddress

FLEET_SPACING = 25.0
"""Metres between neighbouring units of a fleet at start (a square grid)."""


def unit_names(name: str, count: int) -> list[str]:
    """``count`` names with a numeric suffix: dji0 -> dji0..dji{N-1}, dji5 -> dji5.., dji ->
    dji0.."""
    m = re.fullmatch(r"(.*?)(\d+)", name)
    stem, first = (m.group(1), int(m.group(2))) if m else (name, 0)
    return [f"{stem}{first + i}" for i in range(count)]


def _address(address: UnitAddress | str) -> UnitAddress:
    return address if isinstance(address, UnitAddress) else UnitAddress.parse(address)


def _rng(seed: int | None, name: str) -> random.Random:
    # Seeded: the same agent-uuids and com-uuids on every run (a repeatable demo).
    return random.Random(f"{seed}:{name}") if seed is not None else random.Random()


_Self = TypeVar("_Self", bound="_Running")


class _Running:
    """What a unit and a fleet share: their runtime (one connection, one thread)."""

    runtime: Runtime

    def start(self: _Self, timeout: float = 10.0) -> _Self:
        """Connect and start; returns once every unit has sent its first heartbeat."""
        self.runtime.start(timeout)
        return self

    def stop(self) -> None:
        """Stop publishing, clear anything retained, disconnect."""
        self.runtime.stop()

    def __enter__(self: _Self) -> _Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def errors(self) -> int:
        """Internal errors so far (a bug; zero in every test)."""
        return self.runtime.errors

    @property
    def dropped(self) -> int:
        """Commands dropped because the inbox was full (a flood)."""
        return self.runtime.dropped


class SimUnit(_Running):
    """One simulated unit on its own MQTT connection.

    ``broker`` is an ``mqtt://host:port`` URL; ``rate`` the declared rate in Hz of heartbeat,
    info messages and sensors; ``faults`` names from ``conformance.sim.faults.FAULTS``;
    ``variants`` names from ``conformance.sim.variants.VARIANTS`` (conformant behaviours);
    ``seed`` makes agent-uuids and com-uuids repeatable; ``position`` defaults to Linköping;
    ``task_seconds`` is about how long a simulated task takes. ``tst_execution`` declares the
    level 'tst execution' and runs TST trees (spec 14, ``conformance.sim.tst``) sent to its own
    ``tst/command`` and, with ``tst_operator`` (an operator's address such as
    ``waraps/unit/ground/real/op0``), to the operator's.
    """

    def __init__(self, address: UnitAddress | str, broker: str | BrokerURL, *,
                 faults: Iterable[str] = (), variants: Iterable[str] = (), rate: float = 1.0,
                 seed: int | None = None, position: GeoPoint | None = None, heading: float = 270.0,
                 task_seconds: float = 3.0, tst_execution: bool = False,
                 tst_operator: UnitAddress | str | None = None) -> None:
        self.address = _address(address)
        self.runtime = Runtime(broker, client_id=f"waraps-sim-{self.address.name}-"
                               f"{random.getrandbits(32):08x}")
        self.core = UnitCore(self.address, self.runtime.publish, faults=check_names(list(faults)),
                             variants=check_variants(list(variants)), rate=rate, rng=_rng(seed, self.address.name), position=position,
                             heading=heading, task_seconds=task_seconds,
                             tst_execution=tst_execution,
                             tst_operator=_address(tst_operator) if tst_operator else None)
        self.runtime.add(self.core)

    def reboot(self, *, wait: bool = False, timeout: float = 30.0) -> None:
        """Reboot: silent for 2.5 periods, history lost, back with a new agent-uuid. With
        ``wait``, return once it is back."""
        self.runtime.reboot(0, wait=wait, timeout=timeout)

    @property
    def agent_uuid(self) -> str:
        return self.core.agent_uuid

    @property
    def faults(self) -> frozenset[str]:
        return self.core.faults

    @property
    def variants(self) -> frozenset[str]:
        return self.core.variants

    @property
    def base(self) -> str:
        """The topic base it publishes under (its address, unless a topic fault moves it)."""
        return self.core.base


class Fleet(_Running):
    """``count`` simulated units named with a numeric suffix (dji0, dji1, ...) on one MQTT
    connection, their publications spread evenly over one period.

    ``faults`` apply to every unit; ``faults_by_index`` adds faults to single units
    (``{3: ["heartbeat-rate-drift"]}``); ``variants`` apply to every unit; ``tst_execution`` and ``tst_operator`` as for
    ``SimUnit``, for every unit.
    """

    def __init__(self, address: UnitAddress | str, broker: str | BrokerURL, count: int, *,
                 faults: Iterable[str] = (),
                 faults_by_index: Mapping[int, Iterable[str]] | None = None,
                 variants: Iterable[str] = (), rate: float = 1.0, seed: int | None = None, task_seconds: float = 3.0,
                 heading: float = 270.0, tst_execution: bool = False,
                 tst_operator: UnitAddress | str | None = None) -> None:
        if count < 1:
            raise ValueError(f"count {count}: a fleet has at least one unit")
        base = _address(address)
        common = check_names(list(faults))
        variant_names = check_variants(list(variants))
        extra = {int(i): check_names(list(f)) for i, f in (faults_by_index or {}).items()}
        if bad := [i for i in extra if not 0 <= i < count]:
            raise ValueError(f"faults_by_index {bad}: indexes run from 0 to {count - 1}")
        self.addresses = [base.with_name(n) for n in unit_names(base.name, count)]
        self.runtime = Runtime(broker, client_id=f"waraps-sim-fleet-{random.getrandbits(32):08x}")
        side = max(1, int(count ** 0.5 + 0.999))
        home = GeoPoint(*LINKOPING, 0.0)
        phases = spread(count, 1.0 / rate)
        operator = _address(tst_operator) if tst_operator else None
        self.cores: list[UnitCore] = []
        for i, a in enumerate(self.addresses):
            row, col = divmod(i, side)
            spot = destination(destination(home, 0.0, row * FLEET_SPACING), 90.0,
                               col * FLEET_SPACING)
            core = UnitCore(a, self.runtime.publish, faults=common | extra.get(i, frozenset()),
                            variants=variant_names,
                            rate=rate, rng=_rng(seed, a.name), position=spot,
                            heading=heading, task_seconds=task_seconds, phase=phases[i],
                            tst_execution=tst_execution, tst_operator=operator)
            self.cores.append(core)
            self.runtime.add(core)

    def __len__(self) -> int:
        return len(self.cores)

    def reboot(self, index: int | None = None, *, wait: bool = False,
               timeout: float = 30.0) -> None:
        """Reboot one unit (by index) or every unit."""
        self.runtime.reboot(index, wait=wait, timeout=timeout)

    def kill(self, index: int) -> None:
        """Kill one unit (by index): silent for good, as a unit whose MQTT thread died, until
        ``reboot(index)`` brings it back."""
        self.runtime.kill(index)

    @property
    def agent_uuids(self) -> list[str]:
        return [c.agent_uuid for c in self.cores]

    def index_of(self, name: str) -> int:
        for i, a in enumerate(self.addresses):
            if a.name == name:
                return i
        raise KeyError(f"no unit named {name!r} in this fleet "
                       f"({self.addresses[0].name}..{self.addresses[-1].name})")

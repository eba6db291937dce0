"""The reference pair: the embedded broker with the bundled reference unit on it, as
``pytest --unit ... --broker embedded`` (and so ``waraps-conformance demo``) certifies it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from conformance.broker import EmbeddedBroker
from conformance.sim.fleet import SimUnit
from conformance.topics import UnitAddress


@dataclass(eq=False)
class ReferenceUnit:
    """The reference unit as a certification asks for it: at ``unit``, ``faults`` and
    ``variants`` switched on, heartbeating at ``rate`` Hz (on the embedded broker:
    ``Reference``; in virtual time: ``conformance.sim.virtual.VirtualReference``)."""

    unit: UnitAddress
    faults: tuple[str, ...] = ()
    variants: tuple[str, ...] = ()
    rate: float = 1.0
    seed: int | None = None
    tst: bool = False
    """It declares 'tst execution' and runs trees (14), also those sent to
    ``tst_operator``'s tst/command (14.1)."""
    tst_operator: UnitAddress | None = None


@dataclass(eq=False)
class Reference(ReferenceUnit):
    """The embedded broker on a free loopback port with the reference unit on it.

    >>> with Reference(UnitAddress.parse("waraps/unit/air/simulation/dji0")) as ref:
    ...     ref.url               # 'mqtt://127.0.0.1:PORT'
    """

    broker: Any = field(default=None, init=False)
    sim: Any = field(default=None, init=False)

    def start(self) -> Reference:
        # Imported here: amqtt and the simulator load only when a reference pair is wanted.

        self.broker = EmbeddedBroker().start()
        try:
            self.sim = SimUnit(self.unit, self.broker.url, faults=self.faults,
                               variants=self.variants, rate=self.rate,
                               seed=self.seed, tst_execution=self.tst,
                               tst_operator=self.tst_operator).start()
        except BaseException:
            self.broker.stop()
            raise
        return self

    @property
    def url(self) -> str:
        return str(self.broker.url)

    def reboot(self) -> None:
        """Reboot the reference unit (silent for a moment, then a new agent-uuid)."""
        self.sim.reboot()

    def stop(self) -> None:
        try:
            if self.sim is not None:
                self.sim.stop()
        finally:
            if self.broker is not None:
                self.broker.stop()

    def __enter__(self) -> Reference:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

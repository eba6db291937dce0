"""An outage of the observer is not a fault of the unit: a broker that drops for
5 s while the suite waits for a started task in tasks-executing (DEI-004) leaves that
judgement could-not-test, never failed."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
from certify_helpers import FAST, PrivateMosquitto, Rebooter, certify

from conformance.sim import SimUnit

pytestmark = pytest.mark.slow
OUTAGE = 5.0  # seconds: the outage is the stimulus


class OutageAfterRunning:
    """Stops the private broker for OUTAGE seconds as soon as the unit answers the suite's
    first start-task 'running', while the suite waits for it in tasks-executing."""

    def __init__(self, broker: PrivateMosquitto) -> None:
        self.broker = broker
        self.dropped = threading.Event()
        self.thread: threading.Thread | None = None

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if self.thread is not None or not item.name.startswith("test_start_task"):
            return
        from conformance.suite.session import CERTIFICATION

        traffic = item.config.stash[CERTIFICATION].traffic
        mark = traffic.mark()

        def drop() -> None:
            running = traffic.wait_for(lambda e: e.get("response") == "running", 60,
                                       after=mark, subtopic="exec/response")
            if running is None:
                return
            self.broker.stop()
            self.dropped.set()
            threading.Event().wait(OUTAGE)
            self.broker.start()

        self.thread = threading.Thread(target=drop, daemon=True)
        self.thread.start()


def test_a_broker_outage_while_waiting_for_tasks_executing_is_not_the_units(
        pytester: pytest.Pytester, tmp_path: Path) -> None:
    broker = PrivateMosquitto(tmp_path).start()
    unit = "waraps/unit/air/simulation/dji0"
    outage = OutageAfterRunning(broker)
    started = time.monotonic()
    try:
        with SimUnit(unit, broker.url, rate=0.5, seed=2) as sim:  # infos 2 s apart
            run = certify(pytester, "--unit", unit, "--broker", broker.url,
                          f"--profile={FAST}", "-k", "start_task",
                          plugins=(Rebooter(sim), outage))
    finally:
        if outage.thread is not None:
            outage.thread.join(OUTAGE + 5)
        broker.stop()
    assert outage.dropped.is_set(), run.text
    assert "broker connection lost" in run.text
    assert run.outcomes.get("DEI-004") != "failed", run.text
    rules = run.unit_rules()
    assert rules["DEI-004"]["verdict"] != "fail", rules["DEI-004"]
    assert time.monotonic() - started < 300

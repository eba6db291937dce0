"""A broker's fault is the broker's (issue 25 §3): the broker killed 18 s into a certification
of the conformant reference unit and restarted 5 s later, or frozen 20 s (SIGSTOP, SIGCONT)
and then delivering what it held in one burst. What the unit published meanwhile is unknown:
the run certifies, or says could-not-test, and never fails a rule."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
from certify_helpers import FAST, PrivateMosquitto, Rebooter, certify

from conformance.sim import SimUnit

pytestmark = pytest.mark.slow
INTO_RUN = 18.0  # seconds into the certification: the measurement
OUTAGE = 5.0  # seconds the killed broker stays down (the issue's)
FREEZE = 20.0  # seconds the broker stays frozen (the issue's)


class BrokerFault:
    """Kills (or freezes) the private broker INTO_RUN seconds after the certification's
    tests are collected (or, ``on_signal``, as soon as the suite sends its first signal-task:
    the final feedback it asks for is then sent while the broker is away), and brings it back
    after ``down`` seconds. The times are the stimulus, not something waited for."""

    def __init__(self, broker: PrivateMosquitto, *, freeze: bool, down: float,
                 on_signal: bool = False) -> None:
        self.broker, self.freeze, self.down = broker, freeze, down
        self.on_signal = on_signal
        self.done = threading.Event()
        self.thread: threading.Thread | None = None

    def pytest_collection_finish(self, session: pytest.Session) -> None:
        if self.thread is None:
            traffic = None
            if self.on_signal:
                from conformance.suite.session import CERTIFICATION

                traffic = session.config.stash[CERTIFICATION].traffic
            self.thread = threading.Thread(target=self._fault, args=(traffic,), daemon=True)
            self.thread.start()

    def _fault(self, traffic) -> None:  # type: ignore[no-untyped-def]
        timer = threading.Event()
        if traffic is None:
            timer.wait(INTO_RUN)
        elif traffic.wait_for(lambda e: e.get("command") == "signal-task", 120, after=0,
                              subtopic="exec/command") is None:
            return
        if self.freeze:
            self.broker.freeze()
        else:
            self.broker.stop()
        timer.wait(self.down)
        if self.freeze:
            self.broker.thaw()
        else:
            self.broker.start()
        self.done.set()

    def join(self) -> None:
        if self.thread is not None:
            self.thread.join(INTO_RUN + self.down + 10)


def certify_through(tmp_path: Path, pytester: pytest.Pytester, *, freeze: bool,
                    down: float, seed: int, on_signal: bool = False):
    broker = PrivateMosquitto(tmp_path).start()
    unit = "waraps/unit/air/simulation/dji0"
    fault = BrokerFault(broker, freeze=freeze, down=down, on_signal=on_signal)
    try:
        with SimUnit(unit, broker.url, rate=1.0, seed=seed) as sim:  # stamps 1 s apart
            run = certify(pytester, "--unit", unit, "--broker", broker.url,
                          f"--profile={FAST}", "--seed", str(seed),
                          plugins=(Rebooter(sim), fault))
    finally:
        fault.join()
        broker.stop()
    assert fault.done.is_set(), f"the run ended before the broker came back\n{run.text}"
    return run


def assert_never_failed(run) -> None:
    assert not run.failed, run.text[-4000:]
    assert run.result.ret in (0, 6), run.text[-4000:]
    verdicts = {r: v["verdict"] for r, v in run.unit_rules().items()}
    assert "fail" not in verdicts.values(), {r: v for r, v in verdicts.items() if v == "fail"}


@pytest.mark.parametrize("on_signal", [False, True], ids=["18s-in", "as-a-signal-is-sent"])
def test_a_broker_killed_and_restarted_mid_run_fails_nothing(
        pytester: pytest.Pytester, tmp_path: Path, on_signal: bool) -> None:
    run = certify_through(tmp_path, pytester, freeze=False, down=OUTAGE, seed=2,
                          on_signal=on_signal)
    assert "broker connection lost" in run.text
    assert_never_failed(run)


def test_a_broker_frozen_mid_run_fails_nothing(
        pytester: pytest.Pytester, tmp_path: Path) -> None:
    started = time.monotonic()
    run = certify_through(tmp_path, pytester, freeze=True, down=FREEZE, seed=3)
    assert_never_failed(run)
    assert "stalled" in run.text, run.text[-3000:]
    assert time.monotonic() - started < 600

"""Shared fixtures: real brokers (the embedded amqtt one and the local Mosquitto) and a topic
prefix of its own for every test, so tests never see each other's traffic."""

from __future__ import annotations

import os
import signal
import uuid
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings
from machine import deadline
from shared_mosquitto import shared_mosquitto

from conformance.broker import EmbeddedBroker
from conformance.topics import UnitAddress

pytest_plugins = ["pytester"]

# Hypothesis: a bounded 'ci' profile (2 cores, CI time), a 'dev' one for deeper local runs.
# Tests take their number of examples from a profile, never from an inline max_examples.
settings.register_profile("ci", max_examples=60, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=300, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

MOSQUITTO = ("127.0.0.1", 1883)
TEST_TIMEOUT = 120
"""Seconds (on an idle machine; more on a busy one, ``machine.deadline``): a hung broker or
unit fails one test instead of the whole run. The slowest test takes about 40 s alone."""


@pytest.hookimpl(trylast=True)  # after hypothesis loaded the profile of --hypothesis-profile
def pytest_configure(config: pytest.Config) -> None:
    # A run started in the background by a script (`nohup ... &`, some CI runners) inherits
    # SIGINT ignored, and so would every lint, record and pytest process these tests start
    # and Ctrl-C: the Ctrl-C would never arrive. Each test process (xdist's workers too)
    # takes Python's own handler back.
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    active = settings.default
    # A property run once per message kind (a dozen tests) takes a sixth of the active
    # profile's examples, so the family costs about what a few tests do: 10 under ci.
    settings.register_profile("share", settings(
        active, max_examples=max(5, active.max_examples // 6)))
    # Each example is costly (a strategy drawn from a JSON Schema, a simulated run): 4 under ci.
    settings.register_profile("expensive", settings(
        active, max_examples=max(2, active.max_examples // 15)))


# optionalhook: `-p no:xdist` (tests/README: --durations) has no such hook to validate.
@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """-n 6 (xdist's default, --dist load) schedules by work stealing: a worker that runs out
    takes half of another's queue, so the slow tests (first, below) are shared out, not
    sent in one consecutive chunk to one worker. Any other --dist is left as asked."""
    if config.getoption("dist") != "load":
        return None
    from xdist.scheduler import WorkStealingScheduling

    return WorkStealingScheduling(config, log)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # Slow tests first (a stable sort: file order otherwise). They mostly wait on units and
    # brokers; started early under -n 6, the many short tests fill in around them instead of
    # one worker running the last long test alone at the end (with work stealing, below).
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
    # pytest-timeout is a test extra; set here, not in the ini, so that `pytest --unit` run from
    # this folder without the extra gets no "unknown config option" warning.
    if config.pluginmanager.hasplugin("timeout"):
        hung = deadline(TEST_TIMEOUT, at_least=2.0)  # the load grows as the workers start
        for item in items:
            if item.get_closest_marker("timeout") is None:
                item.add_marker(pytest.mark.timeout(hung))


@pytest.fixture(scope="session")
def embedded_broker() -> Iterator[EmbeddedBroker]:
    """An amqtt broker on a free loopback port, shared by the session (tests use own prefixes).

    Example: ``MqttClient(BrokerURL.parse(embedded_broker.url)).connect()``
    """
    with EmbeddedBroker() as broker:
        yield broker


@pytest.fixture(scope="session")
def mosquitto() -> Iterator[str]:
    """The local Mosquitto on 127.0.0.1:1883, its URL. Started if it is not running, and then
    stopped by the last test process that used it (xdist workers and other runs share it);
    one that was already running is left alone (``shared_mosquitto``).

    Example: ``MqttClient(BrokerURL.parse(mosquitto)).connect()``
    """
    with shared_mosquitto(*MOSQUITTO) as up:
        if not up:
            pytest.fail("Mosquitto is not listening on 127.0.0.1:1883 and could not be "
                        "started: run `mosquitto -d -c /etc/mosquitto/mosquitto.conf`")
        yield "mqtt://127.0.0.1:1883"


@pytest.fixture(params=["embedded", "mosquitto"])
def broker_url(request: pytest.FixtureRequest) -> str:
    """Each real broker in turn: the embedded amqtt one, then the local Mosquitto."""
    if request.param == "embedded":
        return request.getfixturevalue("embedded_broker").url
    return request.getfixturevalue("mosquitto")


@pytest.fixture
def prefix() -> str:
    """A PREFIX1 of this test's own (spec 3.1: 'can be used to have parallel experiments')."""
    return f"t{uuid.uuid4().hex[:10]}"


@pytest.fixture
def unit_address(prefix: str) -> UnitAddress:
    """``<prefix>/unit/air/simulation/dji0``: a simulated air unit under this test's prefix."""
    return UnitAddress(prefix, "air", "simulation", "dji0")

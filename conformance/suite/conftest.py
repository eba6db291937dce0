"""Fixtures of the packaged conformance suite (only active with ``pytest --unit``)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from conformance.checks import Monitor
from conformance.profile import Profile
from conformance.scenarios import Traffic
from conformance.suite.session import CERTIFICATION, Certification
from conformance.topics import UnitAddress


@pytest.fixture(scope="session")
def certification(pytestconfig: pytest.Config) -> Certification:
    """The running certification: settings, connection, Monitor, scenarios, reports.

    Example: ``certification.result("HB-003").verdict``
    """
    found = pytestconfig.stash.get(CERTIFICATION, None)
    if found is None:
        pytest.skip("the conformance suite certifies a unit: run pytest --unit ADDRESS")
    return found


@pytest.fixture(scope="session")
def unit(certification: Certification) -> UnitAddress:
    """The unit under test. Example: ``unit.topic("heartbeat")``."""
    return certification.unit


@pytest.fixture(scope="session")
def profile(certification: Certification) -> Profile:
    """The profile in force. Example: ``profile.min_intervals``."""
    return certification.profile


@pytest.fixture(scope="session")
def monitor(certification: Certification) -> Monitor:
    """The passive checks over the whole run. Example: ``monitor.state(unit).agent_uuid``."""
    return certification.monitor


@pytest.fixture(scope="session")
def traffic(certification: Certification) -> Traffic:
    """The unit's messages, decoded. Example: ``traffic.latest("heartbeat").body``."""
    return certification.traffic


@pytest.fixture(scope="session", autouse=True)
def certification_properties(certification: Certification,
                             record_testsuite_property) -> Iterator[None]:
    """Unit, agent-uuid, profile, suite version and schemas hash in the JUnit file."""
    yield
    report = certification.report()
    record_testsuite_property("unit", str(certification.unit))
    uuids = report.units.get(str(certification.unit))
    record_testsuite_property("agent-uuid", " ".join(uuids.agent_uuids) if uuids else "")
    record_testsuite_property("profile", f"{certification.profile.name} "
                                         f"({certification.profile.source})")
    record_testsuite_property("suite-version", report.suite_version)
    record_testsuite_property("schemas-hash", report.schemas_hash)
    record_testsuite_property("broker", report.broker)
    record_testsuite_property("seed", str(certification.settings.seed))

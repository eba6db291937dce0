"""Fixtures of the packaged conformance suite (only active with ``pytest --unit``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest

from conformance.conclusion import of as conclusion_of
from conformance.suite.session import CERTIFICATION, Certification


@pytest.fixture(scope="session")
def certification(pytestconfig: pytest.Config) -> Certification:
    """The running certification: settings, connection, Monitor, scenarios, reports.

    Example: ``certification.result("HB-003").verdict``
    """
    found = pytestconfig.stash.get(CERTIFICATION, None)
    if found is None:
        pytest.skip("the conformance suite certifies a unit: run pytest --unit ADDRESS")
    return found


def certification_part(name: str, doc: str) -> Any:
    """A session fixture ``name``: that attribute of the running certification."""
    def part(certification: Certification) -> Any:
        return getattr(certification, name)

    part.__doc__ = doc
    return pytest.fixture(scope="session", name=name)(part)


unit = certification_part(
    "unit", "The unit under test (``UnitAddress``). Example: ``unit.topic(\"heartbeat\")``.")
profile = certification_part(
    "profile", "The profile in force (``Profile``). Example: ``profile.min_intervals``.")
monitor = certification_part(
    "monitor", "The passive checks over the whole run (``Monitor``). Example: "
    "``monitor.state(unit).agent_uuid``.")
traffic = certification_part(
    "traffic", "The unit's messages, decoded (``Traffic``). Example: "
    "``traffic.latest(\"heartbeat\").body``.")


@pytest.fixture(scope="session", autouse=True)
def certification_properties(certification: Certification,
                             record_testsuite_property: Callable[[str, object], None]
                             ) -> Iterator[None]:
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
    # The verdict model's words (conformance.conclusion): the same in every output.
    conclusion = conclusion_of(report)
    record_testsuite_property("verdict", conclusion.verdict)
    record_testsuite_property("partial", str(conclusion.partial).lower())
    status = conclusion.units.get(str(certification.unit))
    record_testsuite_property("levels", "; ".join(map(str, status.levels)) if status else "")

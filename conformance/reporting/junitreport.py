"""The JUnit XML report: one test suite per unit, one test case per rule (CI dashboards).

Verdicts map to JUnit outcomes: fail -> failure, skip and could-not-test -> skipped (with the
reason), pass and warn -> passed (a warn says so in its system-out and its ``status``).
"""

from __future__ import annotations

import os
from pathlib import Path

from junit_xml import TestCase, TestSuite, to_xml_report_string

from conformance.conclusion import conclude
from conformance.reporting.files import atomic_write
from conformance.reporting.text import iso_time, printable, render_violation
from conformance.results import RunReport
from conformance.rules import CATALOGUE
from conformance.violation import Verdict


def to_junit(report: RunReport) -> str:
    suites = []
    conclusion = conclude(report)
    for name, unit in report.units.items():
        status = conclusion.units.get(name)
        cases = []
        for rid, result in unit.rules.items():
            rule = CATALOGUE.get(rid)
            title = rule.title if rule else rid
            case = TestCase(f"{rid} {printable(title)}", classname=printable(name),
                            status=result.verdict.value,
                            timestamp=iso_time(unit.first_seen) or None)
            text = "\n\n".join(render_violation(rid, v, name, verdict=result.verdict,
                                                report=report)
                               for v in result.violations)
            if result.verdict is Verdict.FAIL:
                first = result.violations[0] if result.violations else None
                message = (f"expected {first.expected}; observed {first.observed}"
                           if first else result.reason)
                case.add_failure_info(message=printable(message), output=text or result.reason)
            elif result.verdict in (Verdict.SKIP, Verdict.COULD_NOT_TEST):
                case.add_skipped_info(message=printable(f"{result.verdict.value}: {result.reason}"))
            elif result.verdict is Verdict.WARN:
                case.stdout = f"warn: {printable(result.reason)}\n\n{text}"
            cases.append(case)
        properties = {
            "unit": printable(name),
            "agent-uuid": printable(", ".join(unit.agent_uuids)),
            "profile": report.profile,
            "suite-version": report.suite_version,
            "schemas-hash": report.schemas_hash,
            "kind": report.kind,
            "broker": printable(report.broker),
            # The verdict model's words (conformance.conclusion), as every output says them.
            "verdict": conclusion.verdict,
            "partial": str(conclusion.partial).lower(),
            "why": printable("; ".join(conclusion.why)),
            "status": printable(status.summary if status else ""),
            "levels": printable("; ".join(map(str, status.levels)) if status else ""),
        }
        suites.append(TestSuite(printable(name), cases, properties=properties,
                                timestamp=iso_time(report.started) or None))
    return to_xml_report_string(suites, prettyprint=True, encoding="utf-8")


def write_junit(report: RunReport, path: str | os.PathLike[str]) -> Path:
    """Write the report as JUnit XML (atomically); the path written."""
    return atomic_write(path, to_junit(report))

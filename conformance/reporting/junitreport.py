"""The JUnit XML report: one test suite per unit, one test case per rule (CI dashboards).

Verdicts map to JUnit outcomes: fail -> failure, skip and could-not-test -> skipped (with the
reason), pass and warn -> passed (a warn says so in its system-out and its ``status``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from conformance.conclusion import Conclusion
from conformance.conclusion import of as conclusion_of
from conformance.display import printable, shorten
from conformance.reporting.bounds import bounded
from conformance.reporting.files import atomic_write
from conformance.reporting.text import iso_time, render_violation
from conformance.results import RunReport
from conformance.rules import CATALOGUE
from conformance.violation import RuleResult, Verdict


def _attr(value: object) -> str:
    """An attribute value as XML: excerpted, control characters escaped (XML 1.0 allows
    none of them), quoted."""
    return quoteattr(printable(shorten(value)))


def _text(value: str) -> str:
    """Element text as XML (several lines: each line's control characters escaped)."""
    return escape("\n".join(printable(line) for line in value.split("\n")))


def to_junit(report: RunReport) -> str:
    """The JUnit XML, at most ``bounds.MAX_REPORT_BYTES`` (``bounds.bounded``)."""
    return bounded(_to_junit, report)


def _to_junit(report: RunReport) -> str:
    # Written directly, one string per element (linear): junit_xml's pretty printer parsed
    # the whole document again with minidom, 5 s and 3 GB for 4096 units.
    suites: list[str] = []
    tests = failures_total = 0
    conclusion = conclusion_of(report)
    truncated = report.meta.report_truncated
    for name, unit in report.units.items():
        stamp = iso_time(unit.first_seen)
        at = f" timestamp={_attr(stamp)}" if stamp else ""
        classname = _attr(name)
        cases = [_testcase(report, name, rid, result, at) for rid, result in unit.rules.items()]
        failures = sum(1 for r in unit.rules.values() if r.verdict is Verdict.FAIL)
        skipped = sum(1 for r in unit.rules.values()
                      if r.verdict in (Verdict.SKIP, Verdict.COULD_NOT_TEST))
        properties = _properties(report, name, unit.agent_uuids, conclusion)
        if truncated:
            properties["report-truncated"] = truncated
        started = iso_time(report.started)
        suites.append(
            f"\t<testsuite disabled=\"0\" errors=\"0\" failures=\"{failures}\" "
            f"name={classname} skipped=\"{skipped}\" tests=\"{len(cases)}\" time=\"0\""
            + (f" timestamp={_attr(started)}" if started else "") + ">\n\t\t<properties>\n"
            + "".join(f"\t\t\t<property name={_attr(k)} value={_attr(v)}/>\n"
                      for k, v in properties.items())
            + "\t\t</properties>\n" + "".join(cases) + "\t</testsuite>\n")
        tests += len(cases)
        failures_total += failures
    note = (f"\t<!-- {escape(printable(truncated)).replace('--', '- -')} -->\n"
            if truncated else "")
    return (f'<?xml version="1.0" encoding="utf-8"?>\n<testsuites disabled="0" errors="0" '
            f'failures="{failures_total}" tests="{tests}" time="0.0">\n{note}'
            + "".join(suites) + "</testsuites>\n")


def _testcase(report: RunReport, name: str, rid: str, result: RuleResult, at: str) -> str:
    """One rule of one unit as a testcase: a failure with every violation rendered, a skip
    with its reason, a warning's reason and violations as its output."""
    rule = CATALOGUE.get(rid)
    title = rule.title if rule else rid
    head = (f"\t\t<testcase name={_attr(f'{rid} {title}')}{at} "
            f"classname={_attr(name)} status={_attr(result.verdict.value)}")
    text = "\n\n".join(render_violation(rid, v, name, verdict=result.shown_as(i), report=report)
                       for i, v in enumerate(result.violations))
    if result.verdict is Verdict.FAIL:
        first = result.violations[0] if result.violations else None
        message = (f"expected {first.expected}; observed {first.observed}"
                   if first else result.reason)
        body = (f"\t\t\t<failure type=\"failure\" message={_attr(message)}>"
                f"{_text(text or result.reason)}</failure>\n")
    elif result.verdict in (Verdict.SKIP, Verdict.COULD_NOT_TEST):
        body = (f"\t\t\t<skipped type=\"skipped\" "
                f"message={_attr(f'{result.verdict.value}: {result.reason}')}/>\n")
    elif result.verdict is Verdict.WARN:
        body = (f"\t\t\t<system-out>"
                f"{_text(f'warn: {shorten(result.reason)}' + chr(10) * 2 + text)}"
                f"</system-out>\n")
    else:
        body = ""
    return f"{head}>\n{body}\t\t</testcase>\n" if body else f"{head}/>\n"


def _properties(report: RunReport, name: str, agent_uuids: Iterable[str],
                conclusion: Conclusion) -> dict[str, str]:
    """A unit's testsuite properties: the run, and the verdict model's words
    (conformance.conclusion), as every output says them."""
    status = conclusion.units.get(name)
    return {
        "unit": name,
        "agent-uuid": ", ".join(agent_uuids),
        "profile": report.profile,
        "suite-version": report.suite_version,
        "schemas-hash": report.schemas_hash,
        "kind": report.kind,
        "broker": report.broker,
        "verdict": conclusion.verdict,
        "partial": str(conclusion.partial).lower(),
        "why": "; ".join(conclusion.why),
        "status": status.summary if status else "",
        "levels": "; ".join(map(str, status.levels)) if status else "",
    }


def write_junit(report: RunReport, path: str | os.PathLike[str]) -> Path:
    """Write the report as JUnit XML (atomically); the path written."""
    return atomic_write(path, to_junit(report))

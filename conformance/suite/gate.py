"""The run's last line: its exit status and why, in words a CI log shows (README 'Exit
status'). A gate reads the status; a person reads this line, the last the terminal prints."""

from __future__ import annotations

from conformance.conclusion import Conclusion, UnitStatus
from conformance.display import printable, shorten
from conformance.exits import (
    EXIT_CERTIFIED,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_NOT_CERTIFIED,
    EXIT_UNTESTED,
)
from conformance.results import RunReport
from conformance.rules import CATALOGUE
from conformance.topics import level_name
from conformance.violation import Verdict

LAST_LINE_CHARS = 400
"""A CI log shows the line whole; the reports hold the rest."""

PYTEST_WORDS = {
    EXIT_FAILED: "a test failed without a rule failing (the suite's own error, shown above)",
    3: "internal error",
    4: "usage error",
    5: "no test was selected",
}


def last_line(report: RunReport, conclusion: Conclusion, unit: str, status: int, *,
              error_said: bool = False, failed_then: tuple[str, ...] = ()) -> str:
    """``exit 7: not certified: no rule failed, but 2 could not be tested: REBOOT-001,
    REBOOT-002: no way to reboot the unit: pass --reboot-cmd ...``. ``error_said``: the
    error that kept every rule from running was printed just above (said once).
    ``failed_then``: rules whose test failed when it ran that the whole run does not fail."""
    row = conclusion.units.get(unit)
    if status == EXIT_FAILED and not conclusion.exit_code and failed_then:
        why = (f"{', '.join(failed_then)} failed when its test ran; the whole run's report "
               f"does not fail it (its verdict: {conclusion.verdict}): see the reports")
    elif error_said and status == EXIT_NOT_CERTIFIED:
        why = "not certified: no rule was judged (the error above says why)"
    elif status != conclusion.exit_code:  # pytest's own status (usage, internal, ...)
        why = PYTEST_WORDS.get(status, "see above")
    elif status == EXIT_CERTIFIED:
        why = (f"{conclusion.headline()}: no selected rule failed; no level is certified by "
               f"a partial run" if conclusion.partial else
               row.summary if row is not None else conclusion.verdict)
    elif status == EXIT_FAILED:
        failed = sorted(r.rule for u in report.units.values() for r in u.rules.values()
                        if r.verdict is Verdict.FAIL)
        why = f"a rule failed: {', '.join(failed) or conclusion.headline()}"
    elif status in (EXIT_INTERRUPTED, EXIT_NOT_CERTIFIED):
        why = conclusion.headline()
    elif status == EXIT_UNTESTED:
        why = "not certified: no rule failed, but " + untested_why(report, row, unit)
    else:
        why = conclusion.headline()
    return shorten(printable(f"exit {status}: {why}"), LAST_LINE_CHARS)


def untested_why(report: RunReport, row: UnitStatus | None, unit: str) -> str:
    """Which claimed levels are not certified, and the first reason a rule they need could
    not be tested (its reason names the option that would test it)."""
    if row is None or not row.levels:
        return "the unit declares no level"
    denied = [lv for lv in row.levels if not lv.certified]
    said = "; ".join(f"{lv.level}: {lv.why}" for lv in denied)
    claimed = {lv.level for lv in row.levels}
    found = report.units.get(unit)
    reasons: dict[str, list[str]] = {}
    for r in found.rules.values() if found is not None else ():
        rule = CATALOGUE.get(r.rule)
        level = rule.spec_level if rule is not None else None
        if r.verdict is Verdict.COULD_NOT_TEST and (level is None or level_name(level) in claimed):
            reasons.setdefault(r.reason or "no reason given", []).append(r.rule)
    if not reasons:
        return said
    reason, rules = max(reasons.items(), key=lambda kv: len(kv[1]))
    more = f" (and {len(reasons) - 1} other reason(s): see above)" if len(reasons) > 1 else ""
    return f"{said}; could not test {', '.join(sorted(rules))}: {reason}{more}"

"""The linter's live per-unit scorecard: redrawn in place on a terminal, plain lines in a pipe or
CI log (first violation of each rule per unit, connection events, a summary line now and then).

One row per unit and per commander (what is wrong in a command is its commander's): agent type,
role, declared levels, message rate, last seen, status so far and violations by rule; below it,
live, the latest fleet observations (silence, deaths, two agents under one name, responses to
nothing, reused com-uuids, stale retained state), and at the end every finding once, with its
count and its first and last time.

On a terminal, rich draws it (``rich.live.Live``), refreshed by ``update()`` at most once a
second, never per message: with 200 units a redraw takes 3.1 ms of CPU (0.3 % of the linter's
core; rich's own Table would take 18 ms, so the columns are laid out here). Control characters
in wire text (unit names come from topics) are shown escaped (``display.printable``: ``\x1b``),
on a terminal and in the plain output alike: a topic cannot drive the terminal. The plain output does not use rich and stays as it was (tests/lint compare it).
"""

from __future__ import annotations

import atexit
import os
import sys
import time
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING, Any

from conformance.conclusion import facts_of, triage_rank
from conformance.display import LINE_CHARS, NAME_CHARS, printable, shorten
from conformance.lint.linter import Linter
from conformance.lint.rows import STATUS_ORDER, LintRow, live_rows, report_rows, seen_fields
from conformance.recording import Event
from conformance.rules import CATALOGUE
from conformance.topics import DELEGATION, DIRECT_EXECUTION, SENSOR_LEVEL, TST_EXECUTION
from conformance.violation import Violation

if TYPE_CHECKING:
    from rich.live import Live
    from rich.text import Text

LEVEL_SHORT = {SENSOR_LEVEL: "sensor", DIRECT_EXECUTION: "exec", TST_EXECUTION: "tst",
               DELEGATION: "deleg"}
PLAIN_SUMMARY_EVERY = 10.0
"""Seconds between summary lines in plain mode."""
TTY_REFRESH_EVERY = 1.0
"""Seconds between two redraws on a terminal."""
STATUS_STYLES = {"silent": "bold red", "FAIL": "bold red", "warn": "yellow", "ok": "green"}


@dataclass(frozen=True)
class UnitRow(LintRow):
    """A row as the scorecard shows it: what lint saw (``lint.rows``) and its message rate
    (messages per second)."""

    rate: float | None = None

    @property
    def violations(self) -> tuple[tuple[str, int], ...]:
        """(rule, violations) of each finding: failing rules first, then by count."""
        return tuple((f.rule, f.count) for f in sorted(
            self.findings, key=lambda f: (f.verdict != "fail", -f.count, f.rule)))


def _clock(t: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) if t is not None else "--:--:--"


def _ago(t: float | None, now: float) -> str:
    if t is None:
        return "never"
    d = max(0.0, now - t)
    if d < 1:
        return "now"
    if d < 120:
        return f"{d:.0f}s ago"
    if d < 7200:
        return f"{d / 60:.0f}m ago"
    return f"{d / 3600:.1f}h ago"


def _count(n: float) -> str:
    if n >= 1e6:
        return f"{n / 1e6:.1f}M"
    if n >= 1e4:
        return f"{n / 1e3:.0f}k"
    return f"{n:.0f}"


def violation_line(v: Violation, unit: str, verdict: str, when: float | None = None) -> str:
    """One line for a violation: when it was found (``when``, the arrival of the message that
    showed it; else its own time), verdict, unit, rule, title, expected and observed. A finding
    whose evidence is older than its finding (a command unanswered by its deadline is stamped
    when the command was sent) says when that was, before what a long line may lose: the
    lines stay in time order."""
    rule = CATALOGUE.get(v.rule)
    title = rule.title if rule else ""
    what = (f"expected {shorten(v.expected)}, observed {shorten(v.observed)}"
            if v.expected or v.observed else "")
    where = (f" [{shorten(v.topic, NAME_CHARS)}]" if v.topic and not v.topic.startswith(unit + "/")
             else "")
    t = when if when is not None else v.time
    if v.time is not None and t is not None and v.time < t and _clock(v.time) != _clock(t):
        title += f" (its evidence sent at {_clock(v.time)})"
    return (f"{_clock(t)} {verdict:<4} {shorten(unit, NAME_CHARS)} {v.rule} {title}: "
            f"{what}{where}").rstrip(": ")


def event_line(e: Event, gap_start: float | None = None) -> str:
    if e.kind == "disconnected":
        return (f"{_clock(e.time)} connection lost ({e.detail or 'no reason given'}); "
                f"reconnecting with backoff, rates over the gap will not be judged")
    if e.kind == "connected":
        took = f" after {e.time - gap_start:.1f} s" if gap_start is not None else ""
        return f"{_clock(e.time)} reconnected{took}; linting goes on"
    return (f"{_clock(e.time)} fell behind: {e.count} messages not examined (rates in that "
            f"window are not judged)")


class Scorecard:
    """Shows a ``Linter``'s progress on ``out``.

    ``tty`` None means: redraw in place when ``out`` is a terminal (and TERM is not dumb),
    plain lines otherwise. Call ``update()`` often; it draws at most every second (terminal)
    and prints a summary every 10 s (plain), with violations and events as they come.
    """

    def __init__(self, out: IO[str] | None = None, *, tty: bool | None = None,
                 title: str = "", live: bool = True) -> None:
        self.out = out or sys.stdout
        if tty is None:
            tty = bool(getattr(self.out, "isatty", lambda: False)()) and \
                os.environ.get("TERM", "") not in ("", "dumb")
        self.tty = tty
        self.title = title
        self.live = live
        self._display: Live | None = None
        self._last_draw = 0.0
        self._last_summary = time.monotonic()
        self._prev_counts: dict[str, tuple[int, float]] = {}
        self._gap_start: float | None = None
        self._last_live = 0.0
        self._live_shown: dict[tuple[str, str], Violation] = {}
        """(unit, rule) -> the live finding last printed (plain mode)."""
        self._silent_shown: dict[str, float] = {}
        """Units shown silent (plain mode): their last heartbeat."""

    # --- data -----------------------------------------------------------------------------------
    def rows(self, linter: Linter, *, overall: bool = False) -> list[UnitRow]:
        """Every unit and commander seen, worst first. ``overall``: rates over the whole run,
        not lately (and no live findings)."""
        now = linter.last_time
        rows = []
        for seen in live_rows(linter, live=not overall):
            rate = None
            if seen.party != "unit" or seen.pseudo or getattr(linter.monitor, "untimed", False):
                pass  # a commander's commands come in bursts; a capture without times
            elif overall:
                rate = _overall_rate(seen)
            else:
                prev = self._prev_counts.get(seen.unit)
                if prev is not None and now is not None and now > prev[1]:
                    rate = (seen.messages - prev[0]) / (now - prev[1])
                if now is not None and (prev is None or now - prev[1] >= 5.0):
                    self._prev_counts[seen.unit] = (seen.messages, now)
            rows.append(UnitRow(**seen_fields(seen), rate=rate))
        return sorted(rows, key=_order)

    # --- rendering ------------------------------------------------------------------------------
    def header(self, linter: Linter, elapsed: float | None, connected: bool | None) -> str:
        parts = [f"waraps-conformance lint {self.title}".rstrip()]
        if elapsed is not None:
            parts.append(f"{int(elapsed) // 3600:02d}:{int(elapsed) % 3600 // 60:02d}:"
                         f"{int(elapsed) % 60:02d}")
        parts.append(f"{_count(linter.messages)} messages")
        if linter.unexamined:
            parts.append(f"{_count(linter.unexamined)} NOT EXAMINED (fell behind)")
        if linter.gaps or linter.open_gap:
            parts.append(f"{len(linter.gaps) + (linter.open_gap is not None)} connection gap(s)")
        if connected is not None:
            parts.append("connected" if connected else "DISCONNECTED, reconnecting")
        return " | ".join(parts)

    def table(self, rows: list[UnitRow], now: float | None, width: int = 200,
              max_rows: int | None = None) -> list[str]:
        """The scorecard table as lines of at most ``width`` characters."""
        return self.table_with_status(rows, now, width, max_rows)[0]

    def table_with_status(self, rows: list[UnitRow], now: float | None, width: int = 200,
                          max_rows: int | None = None) -> tuple[list[str], list[tuple[int, int, str]]]:
        """``table()``, and where each shown unit's status is: (line, column, status), for each
        status that fits in the width (the terminal colours it)."""
        statuses = []
        # Wire text (names, types, roles, levels) escaped before it is measured.
        names = {id(r): printable(r.unit) for r in rows}
        uw = max([4] + [len(n) for n in names.values()])
        uw = min(uw, max(20, width // 3))
        head = (f"{'UNIT':<{uw}} {'TYPE':<10} {'ROLE':<10} {'LEVELS':<17} {'MSG/S':>7} "
                f"{'LAST SEEN':>9} {'STATUS':<6} VIOLATIONS BY RULE")
        lines = [head[:width]]
        shown = rows if max_rows is None else rows[:max_rows]
        for r in shown:
            levels = "?" if r.levels is None else printable(
                ",".join(LEVEL_SHORT.get(lv, lv) for lv in r.levels))
            rate = "" if r.rate is None else f"{r.rate:.1f}"
            seen = "" if r.last_seen is None else (_ago(r.last_seen, now) if now else _clock(r.last_seen))
            viol = " ".join([f"{rule}(live)" for rule in r.live]
                            + [f"{rule}x{n}" for rule, n in r.violations]) or "-"
            name = names[id(r)]
            unit = name if len(name) <= uw else "…" + name[-(uw - 1):]
            line = (f"{unit:<{uw}} {printable(r.agent_type)[:10]:<10} "
                    f"{printable(r.role)[:10]:<10} {levels[:17]:<17} "
                    f"{rate:>7} {seen:>9} ")
            if len(line) + len(r.status) < width:
                statuses.append((len(lines), len(line), r.status))
            line += f"{r.status:<6} {viol}"
            lines.append(line if len(line) <= width else line[: width - 1] + "…")
        if not rows:
            lines.append("(no unit seen yet)")
        if max_rows is not None and len(rows) > max_rows:
            lines.append(f"... and {len(rows) - max_rows} more units")
        return lines, statuses

    def fleet_lines(self, linter: Linter, limit: int = 5) -> list[str]:
        latest = list(linter.fleet)[-limit:]
        if not latest:
            return []
        lines = ["fleet observations (latest):"]
        for v in latest:
            unit = linter.unit_of(v)
            lines.append("  " + violation_line(v, unit, self._verdict(linter, v.rule, unit)))
        return lines

    @staticmethod
    def _verdict(linter: Linter, rule: str, unit: str | None = None) -> str:
        return "FAIL" if linter.is_error(rule, unit) else "warn"

    @staticmethod
    def _found(linter: Linter, v: Violation) -> str:
        """One finding's own verdict: its condition's basis decides."""
        return "FAIL" if linter.fails(v) else "warn"

    # --- output ---------------------------------------------------------------------------------
    def update(self, linter: Linter, *, elapsed: float | None = None,
               connected: bool | None = None, force: bool = False) -> None:
        """Show what is new; redraw (terminal) or summarise (plain) when it is time."""
        if self.tty:
            now = time.monotonic()
            linter.take_fresh()
            linter.take_events()
            if force or now - self._last_draw >= TTY_REFRESH_EVERY:
                self._last_draw = now
                self._redraw(linter, elapsed, connected)
            return
        def write(line: str) -> None:  # one line each; what came from the wire, escaped
            self.out.write(printable(shorten(line.removesuffix("\n"), LINE_CHARS)) + "\n")

        for e in linter.take_events():
            if self.live:  # a recording's gaps are listed after its verdicts
                write(event_line(e, self._gap_start) + "\n")
            if e.kind == "disconnected":
                self._gap_start = e.time
            elif e.kind == "connected":
                self._gap_start = None
        for v, when in linter.take_fresh():
            if self.live:  # a recording's stream is not replayed: its verdicts come first
                write(violation_line(v, linter.unit_of(v), self._found(linter, v), when)
                      + "\n")
        now = time.monotonic()
        if self.live and (force or now - self._last_live >= TTY_REFRESH_EVERY):
            self._last_live = now
            self._write_live(linter)
        if force or now - self._last_summary >= PLAIN_SUMMARY_EVERY:
            self._last_summary = now
            units = len(list(linter.monitor.units()))
            # The rows the page and /metrics show (one source): failing so far, or live.
            rows = live_rows(linter)
            failing = sorted(r.unit for r in rows if r.failing)
            silent = sorted(r.unit for r in rows if r.status == "silent")
            write(f"{_clock(linter.last_time)} {units} units, {linter.messages} messages"
                  + (f", {linter.unexamined} not examined" if linter.unexamined else "")
                  + (f", failing: {', '.join(failing[:10])}"
                     + (f" and {len(failing) - 10} more" if len(failing) > 10 else "")
                     if failing else ", no unit fails so far")
                  + (f", silent now: {', '.join(silent[:10])}" if silent else "") + "\n")
        self.out.flush()

    def _write_live(self, linter: Linter) -> None:
        """Plain mode: a line when a rate goes off over its latest intervals, and one when it
        is back (the rule itself is judged over the whole run, at the end)."""
        write = self.out.write
        now_off: dict[tuple[str, str], Violation] = {}
        for unit in linter.monitor.units():
            for v in linter.monitor.live_findings(unit):
                now_off[(str(unit), v.rule)] = v
        for key, v in now_off.items():
            if key not in self._live_shown:
                write(violation_line(v, key[0], self._found(linter, v)) + " (live)\n")
        for key, v in self._live_shown.items():
            if key not in now_off:
                write(f"{_clock(linter.last_time)} ok   {key[0]} {key[1]} back within "
                      f"{v.expected} over its latest intervals (live)\n")
        self._live_shown = now_off
        silent = dict(getattr(linter, "silent", {}))
        for name, last in silent.items():
            if name not in self._silent_shown:
                write(printable(f"{_clock(linter.now())} down {shorten(name, NAME_CHARS)} "
                                f"silent: no heartbeat since {_clock(last)} (live)") + "\n")
        for name in self._silent_shown:
            if name not in silent:
                write(printable(f"{_clock(linter.now())} back {shorten(name, NAME_CHARS)} "
                                f"heard again (live; HB-010 judges its silence)") + "\n")
        self._silent_shown = silent

    def _redraw(self, linter: Linter, elapsed: float | None, connected: bool | None) -> None:
        display = self._terminal()
        size = display.console.size
        now = time.time() if self.live else linter.last_time
        fleet = self.fleet_lines(linter)
        room = max(3, size.height - 3 - len(fleet))
        table, statuses = self.table_with_status(self.rows(linter), now, size.width, room)
        display.update(styled(self.header(linter, elapsed, connected)[: size.width], table,
                              statuses, [ln[: size.width] for ln in fleet]), refresh=True)

    def _terminal(self) -> Live:
        """The live display, started on the first redraw (rich is imported only then)."""
        if self._display is None:
            from rich.console import Console
            from rich.live import Live

            self._display = Live(console=Console(file=self.out, force_terminal=True),
                                 auto_refresh=False, transient=True, vertical_overflow="crop",
                                 redirect_stdout=False, redirect_stderr=False)
            self._display.start()
            atexit.register(self.close)  # an error in the caller must not leave the cursor hidden
        return self._display

    def close(self) -> None:
        """Erase the live display and show the cursor again (a terminal only)."""
        if self._display is not None:
            self._display.stop()
            self._display = None
            atexit.unregister(self.close)

    def final(self, linter: Linter, report: Any, opening: str = "") -> None:
        """The final scorecard from the run report (finish-time judgements included), plain
        text whatever the output; rates over the whole run. ``opening``: what comes first
        (each unit's verdict and its most severe findings)."""
        if self.tty:
            self.close()
        else:
            self.update(linter)  # pending violations and events first
        lines = [self.header(linter, None, None), ""]
        if opening:  # our own lines (wire text in them is escaped line by line below)
            lines += [*opening.split("\n"), ""]
        lines += self.table(rows_from_report(report), None, width=400)
        found = findings_from_report(report)
        if found:
            lines += ["", "findings (each unit or commander and rule once: count, first and "
                          "last time):"] + ["  " + ln for ln in found]
        self.out.write("\n".join(printable(shorten(ln, LINE_CHARS)) for ln in lines) + "\n")
        self.out.flush()


def styled(header: str, table: list[str], statuses: list[tuple[int, int, str]],
           fleet: list[str]) -> Any:
    """The drawing for rich: the header bold, each unit's status (at its column) in its
    colour. Wire text is never read as rich markup (``Text``, not a markup string), and its
    control characters are shown escaped (``table_with_status`` escapes them before it
    measures the columns)."""
    from rich.console import Group
    from rich.text import Text

    def text(line: str) -> Text:
        return Text(printable(line), no_wrap=True, overflow="crop")

    head = text(header)
    head.stylize("bold")
    rows = [text(ln) for ln in table]
    for line, at, status in statuses:
        if status in STATUS_STYLES:
            rows[line].stylize(STATUS_STYLES[status], at, at + len(status))
    return Group(head, *rows, *map(text, fleet))


def _overall_rate(row: LintRow) -> float | None:
    """Messages per second between the first and the latest."""
    first, last = row.first_seen, row.last_seen
    if first is not None and last is not None and last > first and row.messages > 1:
        return (row.messages - 1) / (last - first)
    return None


def _order(row: UnitRow) -> tuple[int, bool, str]:
    return (STATUS_ORDER[row.status], row.pseudo, row.unit)


def rows_from_report(report: Any) -> list[UnitRow]:
    """Scorecard rows from a ``RunReport`` (``lint.rows.report_rows``), rate over the whole
    run. A capture without times shows no rate and no time."""
    return sorted((UnitRow(**seen_fields(row), rate=_overall_rate(row) if row.party == "unit"
                           else None)  # a commander's commands come in bursts: no rate
                   for row in report_rows(report)), key=_order)


MAX_FINDINGS_SHOWN = 40


def findings_from_report(report: Any, limit: int = MAX_FINDINGS_SHOWN) -> list[str]:
    """One line per (unit or commander, rule) that failed or warned: its verdict, the rule, how
    many violations, and the first and latest time; the most severe first (death, deafness,
    commands, messages, warnings: ``conclusion.TRIAGE``), then by first time."""
    found = []
    untimed = facts_of(report).untimed  # the reading's times are not the traffic's
    for unit, u in report.units.items():
        for rule, res in u.rules.items():
            if res.verdict.value not in ("fail", "warn"):
                continue
            n = u.violation_counts.get(rule, len(res.violations))
            first, last = (None, None) if untimed else u.violation_times.get(rule, (None, None))
            when = (f"at {_clock(first)}" if n == 1 or first == last
                    else f"first {_clock(first)}, last {_clock(last)}") if first else ""
            title = CATALOGUE[rule].title if rule in CATALOGUE else ""
            verdict = "FAIL" if res.verdict.value == "fail" else "warn"
            found.append(((triage_rank(rule, res.verdict), first or 0.0, unit, rule),
                          f"{verdict:<4} {shorten(unit, NAME_CHARS)} {rule} {title}: {n}x "
                          f"{when}".rstrip() if n else
                          f"{verdict:<4} {shorten(unit, NAME_CHARS)} {rule} {title}: "
                          f"{shorten(res.reason)}"))
    found.sort()
    lines = [line for _, line in found[:limit]]
    if len(found) > limit:
        lines.append(f"... and {len(found) - limit} more: every finding is in the reports")
    return lines

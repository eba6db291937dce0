"""A lint run: live traffic, a recording or a ROS bag fed to the ``Linter`` and the
scorecard, then the reports, the evidence of the failures, and the exit status.

``conformance.cli.lint`` parses the command line and calls ``lint``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO, Any

from conformance.bounds import MAX_UNITS
from conformance.checks import Monitor
from conformance.client import BrokerError
from conformance.conclusion import ranked_findings
from conformance.display import NAME_CHARS, printable, printable_lines, shorten, shown
from conformance.facts import Gate, RunFacts, RunKind
from conformance.judge import judge
from conformance.lint import EXIT_FAIL, EXIT_NOT_RUN, EXIT_PARTIAL, EXIT_PASS, REPORT_FORMATS
from conformance.lint.capture import LiveCapture
from conformance.lint.linter import Linter
from conformance.lint.scorecard import Scorecard
from conformance.lint.serve import Serving
from conformance.message import Message
from conformance.recording import (
    UNTIMED,
    UNTIMED_NOTE,
    UNTIMED_RULES,
    Event,
    RecordingError,
    RecordingReader,
    open_recording,
)
from conformance.report_meta import RunMeta
from conformance.reporting import write_html, write_json, write_junit
from conformance.reporting.bounds import file_stem
from conformance.reporting.text import render_verdicts, render_violation
from conformance.results import Party
from conformance.rosbag import BagError, BagReader, is_bag
from conformance.violation import Verdict


def lint(options: Any, profile: Any, *, source: str | None = None, ros_unit: Any = None,
         reports_dir: Path = Path("reports"), formats: tuple[str, ...] = REPORT_FORMATS,
         gate: Gate = Gate.ALL, plain: bool = False, stdout: IO[str] | None = None,
         stdin: IO[bytes] | None = None, serve: Any = None, linger: float | None = 0.0) -> int:
    """Lint the traffic ``options`` (``CaptureOptions``) name, live, or the recording or ROS
    bag at ``source``; print the scorecard and write the reports. Returns the exit status:
    EXIT_PASS, EXIT_FAIL (a unit, or with ``gate`` all also a commander, fails a rule of
    severity error) or EXIT_NOT_RUN (no broker, nothing read).

    ``serve`` (a ``serve.Address``): serve the fleet page, /metrics and /report.json while
    linting, and ``linger`` seconds after (None: until Ctrl-C). Raises ``ServeError`` when the
    address cannot be bound."""
    if serve is None:
        return _lint(options, profile, source=source, ros_unit=ros_unit,
                     reports_dir=reports_dir, formats=formats, gate=gate, plain=plain,
                     stdout=stdout, stdin=stdin)

    with Serving(serve, linger, stdout or sys.stdout, live=not source) as serving:
        return _lint(options, profile, source=source, ros_unit=ros_unit, reports_dir=reports_dir,
                     formats=formats, gate=gate, plain=plain, stdout=stdout, stdin=stdin,
                     serving=serving)


@dataclass
class _Read:
    """What one lint read, for its report: the scorecard it drew, when it ended (Unix
    seconds), the report's meta, notes, the broker (live), the malformed lines kept and
    their count."""

    scorecard: Any
    end: float
    meta: RunMeta
    notes: list[str] = field(default_factory=list)
    broker: str = ""
    problems: list[Any] = field(default_factory=list)
    problem_count: int = 0


def _lint(options: Any, profile: Any, *, source: str | None, ros_unit: Any,
          reports_dir: Path, formats: tuple[str, ...], gate: Gate, plain: bool,
          stdout: IO[str] | None, stdin: IO[bytes] | None, serving: Any = None) -> int:
    out = stdout or sys.stdout
    monitor = _monitor(profile, options.units)
    linter = Linter(monitor, profile)
    if serving:  # /report.json while lint runs: judged as the end will judge it

        serving.view.report_meta(broker=str(options.broker or ""),
                                 facts=RunFacts(kind=RunKind.LINT, gate=gate,
                                                strict=profile.is_strict))
    started = time.time()

    def scorecard(title: str, live: bool) -> Any:
        card = Scorecard(out, tty=False if plain else None, title=title, live=live)
        return serving.watch(card) if serving else card

    if source and is_bag(source):
        read = _read_bag(linter, scorecard, source, ros_unit, options)
    elif source:
        read = _read_recording(linter, scorecard, source, stdin, options, out)
    else:
        read = _read_live(linter, scorecard, options, out)
    if read is None:
        return EXIT_NOT_RUN
    end = read.end
    if linter.messages == 0:
        return _nothing_read(out, linter, read)

    over, over_units = monitor.not_judged()
    not_judged = _not_judged(over, over_units) if over else ""
    meta = replace(read.meta,
                   duration_s=f"{(linter.last_time or end) - (linter.first_time or end):.3f}",
                   units=" ".join(u.base for u in options.units) if options.units else None,
                   not_judged=not_judged or None)
    report = judge(_report(monitor, linter, kind_meta=meta, broker=read.broker,
                           started=started if not source else (linter.first_time or started),
                           finished=end),
                   RunFacts(kind=RunKind.LINT, gate=gate, strict=profile.is_strict,
                            untimed=untimed(linter), not_judged=not_judged,
                            not_examined=_malformed(read.problem_count)))
    if serving:  # the fleet page's last snapshot: every verdict final
        serving.view.finish(linter, report, verdict=report.conclusion.verdict,
                            not_judged=not_judged)
    _tell(out, linter, report, read)
    if formats:
        _write(out, report, Path(reports_dir), formats, report_stem(source))
    return _verdict(out, report, gate, not_judged)


def _write(out: IO[str], report: Any, reports_dir: Path, formats: tuple[str, ...],
           stem: str) -> None:
    """The reports, and where they went; a folder removed or filled since it was checked
    (before the run) is said, never a traceback: the run keeps its exit status."""
    try:
        paths = write_reports(report, reports_dir, formats, stem)
    except OSError as e:
        paths = []
        print(shown(f"waraps-conformance lint: could not write the reports into "
                    f"{reports_dir}: {e.strerror or e}"), file=sys.stderr)
    for path in paths:
        print(shown(f"report: {path}"), file=out)


def _read_bag(linter: Any, scorecard: Callable[[str, bool], Any], source: str, ros_unit: Any,
              options: Any) -> _Read | None:
    """Lint a ROS bag (None when it cannot be: said on stderr)."""
    reader = BagReader(source, ros_unit)
    card = scorecard(reader.name, False)
    try:
        end = run_bag(linter, card, reader, options)
    except BagError as e:
        print(shown(f"waraps-conformance lint: {e}"), file=sys.stderr)
        return None
    return _Read(card, end, RunMeta(source=reader.name, recording_formats=reader.format,
                                    bag_messages_read=str(reader.read)), list(reader.notes))


def _read_recording(linter: Any, scorecard: Callable[[str, bool], Any], source: str,
                    stdin: IO[bytes] | None, options: Any, out: IO[str]) -> _Read | None:
    """Lint a recording, ``-`` for standard input (None when it cannot be opened)."""
    try:
        stream, name = open_recording(source, stdin)
    except RecordingError as e:
        print(shown(f"waraps-conformance lint: {e}"), file=sys.stderr)
        return None
    card = scorecard(name, False)
    with stream if stream is not (stdin or sys.stdin.buffer) else _noop():
        reader, end = run_recorded(linter, card, stream, name, options)
    if reader.backwards:  # refused: judged as one, joined captures would tell what never was
        print(shown(f"waraps-conformance lint: {reader.backwards}"), file=sys.stderr)
        return None
    meta = RunMeta(source=name, recording_lines=str(reader.lines),
                   recording_formats=", ".join(sorted(reader.formats)))
    print(shown(f"read {name} as {', '.join(sorted(reader.formats)) or 'no known format'}"
                f" ({reader.messages} messages)"), file=out)
    if reader.problem_count:
        meta = replace(meta, recording_problems=str(reader.problem_count),
                       recording_problem_lines="; ".join(str(p) for p in reader.problems[:20]))
    return _Read(card, end, meta, [*reader.notes], "", reader.problems, reader.problem_count)


def _read_live(linter: Any, scorecard: Callable[[str, bool], Any], options: Any,
               out: IO[str]) -> _Read | None:
    """Lint live traffic, read-only (None when the broker cannot be reached)."""
    assert options.broker is not None
    capture = LiveCapture(options.broker, options.topics)
    try:
        capture.start()
    except BrokerError as e:
        print(shown(f"waraps-conformance lint: {e}"), file=sys.stderr)
        return None
    card = scorecard(f"{options.broker} {' '.join(options.topics)}", True)
    if not card.tty:
        print(shown(f"linting {', '.join(options.topics)} on {options.broker} (read-only)"
                    + (f" for {options.duration:g} s" if options.duration
                       else " until Ctrl-C")), file=out, flush=True)
    end = run_live(linter, card, capture, options)
    meta = RunMeta(
        source=f"live {' '.join(options.topics)}",
        # the rerun line repeats them (reporting/text.py)
        tls_options=" ".join(options.broker.tls_arguments()) or None,
        unexamined_reason="the linter fell behind the broker; oldest dropped"
        if capture.dropped else None)
    return _Read(card, end, meta, [], str(options.broker))


def _nothing_read(out: IO[str], linter: Any, read: _Read) -> int:
    """No message was read: nothing is judged, and the malformed lines say why."""
    read.scorecard.update(linter, force=True)
    for problem in read.problems:
        print(printable(f"malformed {problem}"), file=out)
    print("waraps-conformance lint: no messages were read, so nothing was judged"
          + (f" ({read.problem_count} malformed lines; the formats read are JSON Lines as "
             f"'waraps-conformance record' writes, mosquitto_sub -F %j, -F %J and -v "
             f"output, and ROS bags)" if read.problem_count else ""), file=sys.stderr)
    return EXIT_NOT_RUN


def _tell(out: IO[str], linter: Any, report: Any, read: _Read) -> None:
    """The end of a lint on the terminal: each unit's verdict and its most severe findings
    first, then the table; a capture without times says so before anything
    else; then the malformed lines, notes, gaps and stalls."""
    notes = read.notes
    first = [n for n in notes if n.startswith(UNTIMED_NOTE)] if report.facts.untimed else []
    notes = [n for n in notes if n not in first]
    read.scorecard.final(linter, report, opening="\n".join(
        [*(f"note: {n}" for n in first), render_verdicts(report)]))
    for problem in read.problems:
        print(printable(f"malformed {problem}"), file=out)
    if read.problem_count > len(read.problems):
        print(f"... {read.problem_count - len(read.problems)} more malformed lines", file=out)
    for note in notes:
        print(printable(f"note: {note}"), file=out)
    for gap in linter.gaps:
        print(f"connection gap: {time.strftime('%H:%M:%S', time.localtime(gap.start))} for "
              f"{gap.duration:.1f} s ({printable(gap.reason or 'connection lost')}); rates over it not "
              f"judged", file=out)
    for start, end in linter.monitor.ctx.stalls.found:  # The broker's, not the units'
        print(f"broker stalled: {time.strftime('%H:%M:%S', time.localtime(start))} for "
              f"{end - start:.1f} s (nothing arrived, then what it held at once); rates, "
              f"silences and deadlines over it not judged", file=out)
    if report.unexamined:
        print(f"not examined: {report.unexamined} messages (rates in those windows not judged)",
              file=out)


def _verdict(out: IO[str], report: Any, gate: Gate, not_judged: str) -> int:
    """The evidence of the failures, the last line (what was observed, never a certificate:
    docs/ARCHITECTURE.md 'Verdicts', 'clean', not 'pass'), and the exit status."""
    evidence = failures(report)
    if evidence:
        print(f"\n{printable_lines(evidence)}\n", file=out)
    failing = sorted(u for u, rep in report.units.items() if rep.worst().value == "fail"
                     and (gate == Gate.ALL or rep.party == Party.UNIT))
    gated = "no unit or commander" if gate == Gate.ALL else "no unit"
    conclusion = report.conclusion
    if failing or not not_judged:
        print(("FAIL: " + printable(", ".join(shorten(u, NAME_CHARS) for u in failing)))
              if failing else f"{conclusion.verdict.upper()}: {gated} fails a rule of "
              "severity error (observed, not certified)" + "".join(
                  f"; but {printable(why)}" for why in conclusion.why if conclusion.partial),
              file=out)
    if not_judged:  # past the bound: never a pass
        print(f"FAIL: {printable(not_judged)}", file=out)
    out.flush()
    return conclusion.exit_code if conclusion.exit_code in (EXIT_FAIL, EXIT_PARTIAL) else (
        EXIT_FAIL if conclusion.exit_code else EXIT_PASS)


def _malformed(count: int) -> str:
    """Lines of a recording that could not be read, in words (``RunFacts.not_examined``)."""
    return (f"{count} line(s) of the recording could not be read (malformed): what they held "
            f"was not examined" if count else "")


def _not_judged(over: int, units: list[str]) -> str:
    return (f"not judged: {over} messages of units past the {MAX_UNITS} units lint judges at "
            f"once ({', '.join(units)}{' and more' if len(units) >= 8 else ''}); lint them "
            f"apart with --unit ADDRESS or --topic FILTER")


def untimed(linter: Any) -> bool:
    """Whether the traffic had no recorded times (``recording.UNTIMED``)."""
    return bool(getattr(linter.monitor, "untimed", False))


MAX_FAILURES_SHOWN = 10


def failures(report: Any, limit: int = MAX_FAILURES_SHOWN) -> str:
    """The first violation of each failed (unit, rule), at most ``limit`` of them, as the
    certification prints them: what a person reads before opening the HTML."""
    shown: list[str] = []
    more = 0
    # Most severe first (death, deafness, commands, messages): the cap cuts the least severe.
    for _, unit, result in ranked_findings(report):
        rule, rep = result.rule, report.units[unit]
        if result.verdict is not Verdict.FAIL or not result.violations:
            continue
        if len(shown) >= limit:
            more += 1
            continue
        text = render_violation(rule, result.violations[0], unit, report=report,
                                verdict=result.verdict)
        extra = rep.violation_counts.get(rule, len(result.violations)) - 1  # a total
        shown.append(f"{unit}\n{text}" + (f"\n  (and {extra} more violations of {rule})"
                                            if extra else ""))
    if not shown:
        return ""
    if more:
        shown.append(f"... and {more} more failed rule{'s' if more > 1 else ''}: every "
                     f"violation is in the reports")
    return "\n\n".join(shown)


class _noop:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def _monitor(profile: Any, units: tuple[Any, ...]) -> Any:
    return Monitor(profile, units=list(units) or None, kind=RunKind.LINT)


def run_recorded(linter: Any, scorecard: Any, stream: IO[bytes], name: str,
                 options: Any) -> tuple[Any, float]:
    """Feed a recording to the linter at its recorded times; returns (reader, end time)."""
    reader = RecordingReader(stream, name)
    last_event = feed_recorded(linter, scorecard, reader, options)
    if reader.unprintable:
        linter.event(_unexamined(linter.last_time or 0.0, reader.unprintable))
    end = max(t for t in (linter.last_time, last_event, 0.0) if t is not None)
    linter.finish(end)
    return reader, end


def run_bag(linter: Any, scorecard: Any, bag: Any, options: Any) -> float:
    """Feed a ROS bag's messages (at their record times) and ROS findings to the linter
    (``conformance.rosbag``); returns the end time. Raises ``BagError``."""
    items = iter(bag)
    try:
        feed_recorded(linter, scorecard, items, options)
    finally:
        items.close()
    end = linter.last_time or 0.0
    linter.finish(end)
    return end


def feed_recorded(linter: Any, scorecard: Any, items: Any, options: Any) -> float | None:
    """Feed recorded items at their recorded times, until ``--duration`` past the first
    message or Ctrl-C: messages (of the ``--unit``s), capture events, and ROS findings
    (``rosbag.Finding``). Returns the time of the last capture event, if any."""
    units = set(options.units)
    wants = options.wants if units else None
    feed = linter.feed_one
    limit = None
    n = 0
    last_event = None
    try:
        for item in items:
            if type(item) is Message:
                if limit is None and options.duration:
                    limit = item.time + options.duration
                if limit is not None and item.time > limit:
                    break
                if wants is None or wants(item.topic):
                    feed(item)
            elif type(item) is Event:
                if item.kind == UNTIMED:
                    linter.monitor = _Untimed(linter.monitor)
                    feed = linter.feed_one
                    continue
                linter.event(item)
                last_event = item.time
            elif not units or item.unit in units:  # a ROS finding
                linter.record(item.unit, item.rule, item.violation)
            n += 1
            if n & 0xFF == 0:  # a pipe from mosquitto_sub is live: show progress (throttled)
                linter.watch_silences()
                scorecard.update(linter)
    except KeyboardInterrupt:
        pass
    return last_event


class _Untimed:
    """The Monitor of traffic without recorded times: what it finds on the rules that need
    them is not shown while feeding (the judge makes them could-not-test: ``conformance.judge``)."""

    untimed = True

    def __init__(self, monitor: Any) -> None:
        self._monitor = monitor
        self._rules = frozenset(UNTIMED_RULES)

    def feed(self, message: Any) -> list[Any]:
        found = self._monitor.feed(message)
        return [v for v in found if v.rule not in self._rules] if found else found

    def live_findings(self, unit: Any) -> list[Any]:
        return [v for v in self._monitor.live_findings(unit) if v.rule not in self._rules]

    def __getattr__(self, name: str) -> Any:
        return getattr(self._monitor, name)


def _unexamined(t: float, n: int) -> Any:
    return Event(t, "unexamined", "mosquitto_sub -F %J could not print them", n)


def run_live(linter: Any, scorecard: Any, capture: Any, options: Any) -> float:
    """Lint live traffic until the duration is over or Ctrl-C; returns the end time."""
    start = time.monotonic()
    deadline = None if not options.duration else start + options.duration
    wants = options.wants if options.units else None
    linter.live = True  # silences measured up to the wall clock, every tick
    try:
        while True:
            left = 0.25 if deadline is None else min(0.25, deadline - time.monotonic())
            if left <= 0:
                break
            batch, events = capture.take(timeout=left)
            for event in events:
                linter.event(event)
            if wants is not None:
                batch = [m for m in batch if wants(m.topic)]
            linter.feed(batch)
            linter.watch_silences()
            scorecard.update(linter, elapsed=time.monotonic() - start,
                             connected=capture.is_connected)
    except KeyboardInterrupt:
        pass
    finally:
        capture.stop()
    batch, events = capture.take(timeout=0, max_messages=10**9)
    for event in events:
        linter.event(event)
    linter.feed([m for m in batch if wants is None or wants(m.topic)])
    end = time.time()
    linter.finish(end)
    return end


def _report(monitor: Any, linter: Any, *, kind_meta: RunMeta, broker: str,
            started: float, finished: float) -> Any:
    """The run report from the Monitor (it holds the gaps and unexamined counts it was told),
    with what the linter knows about its source in ``meta``."""
    return monitor.report(kind_meta, broker=broker, started=started, finished=finished)


def report_stem(source: str | None) -> str:
    """``lint-<recording name>`` for a recording (stable for a CI gate), else
    ``lint-<local time>``."""
    if source and source != "-":
        name = Path(source).name.split(".")[0]
        if name:  # bounded and sanitised (a 300-character name)
            return f"lint-{file_stem(name).replace('.', '_')}"
    return time.strftime("lint-%Y%m%d-%H%M%S")


def write_reports(report: Any, directory: Path, formats: tuple[str, ...], stem: str) -> list[Path]:
    """Write the chosen report formats (``conformance.reporting``, the same writers as
    certification); returns their paths."""
    writers = {"json": (write_json, ".json"), "html": (write_html, ".html"),
               "junit": (write_junit, ".xml")}
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in formats:
        write, suffix = writers[fmt]
        paths.append(Path(write(report, directory / f"{stem}{suffix}")))
    return paths

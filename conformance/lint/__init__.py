"""``waraps-conformance lint``: passive linting of a whole fleet, live or recorded.

    waraps-conformance lint --broker mqtts://broker.example:8883 --duration 10m
    waraps-conformance lint --from field-test.jsonl
    waraps-conformance lint --from run.bag --ros-unit waraps/unit/ground/real/husky0
    mosquitto_sub -t 'waraps/#' -F %j | waraps-conformance lint --from -

Live, it subscribes read-only (its client may publish nowhere) and shows a per-unit scorecard;
recorded, it judges the messages at their recorded times. Either way it ends with JSON, HTML
and JUnit reports and exits non-zero when a unit fails a rule of severity error.

Parts: ``capture`` (live subscription, bounded buffer, connection events), ``linter`` (feeds the
shared passive checks, ``conformance.checks.Monitor``, and keeps tallies), the scorecard
(``conformance.scorecard``) and the recording formats (``conformance.recording``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import IO, Any

EXIT_PASS, EXIT_FAIL, EXIT_USAGE, EXIT_NOT_RUN = 0, 1, 2, 3
GATES = ("all", "units")
REPORT_FORMATS = ("json", "html", "junit")


def build_parser() -> argparse.ArgumentParser:
    from conformance.lint.capture import add_capture_arguments

    p = argparse.ArgumentParser(
        prog="waraps-conformance lint",
        description="Lint the traffic of a whole fleet, live (read-only: it never publishes) "
                    "or from a recording, and report a verdict per unit and rule.",
        epilog="Exit status: 0 no unit or commander fails a rule of severity error (with "
               "--gate units: no unit), 1 one does, 2 bad usage, 3 nothing could be linted "
               "(no broker, no messages). What is wrong in a command is its commander's "
               "fault: commanders (by the command's 'sender', else 'of UNIT') have rows of "
               "their own.")
    src = p.add_argument_group("recorded traffic")
    src.add_argument("--from", dest="source", metavar="FILE",
                     help="a recording: JSON Lines as 'waraps-conformance record' writes, or "
                          "'mosquitto_sub -F %%j' / '-F %%J' output; '-' reads standard input; "
                          "or a ROS bag: a ROS 1 .bag file, a ROS 2 bag directory (sqlite3 or "
                          "MCAP)")
    src.add_argument("--ros-unit", metavar="ADDRESS",
                     help="the unit address of a ROS bag's namespaced topics when no "
                          "/heartbeat_info TopicMsg names it, e.g. waraps/unit/ground/real/husky0")
    add_capture_arguments(p)
    out = p.add_argument_group("judging and reports")
    out.add_argument("--profile", default="default", metavar="NAME|FILE",
                     help="built-in profile name (default, strict) or a profile YAML file")
    out.add_argument("--reports-dir", default="reports", metavar="DIR",
                     help="where the reports go (default: reports/)")
    out.add_argument("--format", default=",".join(REPORT_FORMATS), metavar="LIST",
                     help="report formats, comma-separated from json, html, junit; or none "
                          "(default: all three)")
    out.add_argument("--gate", choices=GATES, default="all",
                     help="what the exit status judges: all (units and commanders, the "
                          "default) or units (a fleet gate that commanders' faults do not "
                          "fail)")
    out.add_argument("--plain", action="store_true",
                     help="plain lines even on a terminal (the default in a pipe or CI)")
    return p


def parse_formats(text: str) -> tuple[str, ...]:
    """Report formats from ``--format``; ValueError names the valid ones."""
    wanted = tuple(f.strip().lower() for f in text.split(",") if f.strip())
    if wanted == ("none",):
        return ()
    bad = [f for f in wanted if f not in REPORT_FORMATS]
    if bad or not wanted:
        raise ValueError(f"--format {text!r}: use a comma-separated list of "
                         f"{', '.join(REPORT_FORMATS)}, or none")
    return wanted


def main(argv: list[str] | None = None, *, stdout: IO[str] | None = None,
         stdin: IO[bytes] | None = None) -> int:
    from conformance.lint.capture import CaptureOptionsError, options_from_args
    from conformance.profile import ProfileError, load

    out = stdout or sys.stdout
    err = sys.stderr
    args = build_parser().parse_args(argv)

    def usage(message: str) -> int:
        print(f"waraps-conformance lint: {message}", file=err)
        return EXIT_USAGE

    if args.source and args.broker:
        return usage("--from and --broker exclude each other: lint a recording or a live broker")
    try:
        options = options_from_args(args, need_broker=not args.source)
        formats = parse_formats(args.format)
        profile = load(args.profile)
    except (CaptureOptionsError, ProfileError, ValueError) as e:
        return usage(str(e))
    from conformance.rosbag import is_bag

    bag = bool(args.source) and is_bag(args.source)
    ros_unit = None
    if args.ros_unit:
        from conformance.topics import TopicError, UnitAddress

        if not bag:
            return usage("--ros-unit applies to ROS bags only (--from run.bag or a ROS 2 bag "
                         "directory)")
        try:
            ros_unit = UnitAddress.parse(args.ros_unit)
        except TopicError as e:
            return usage(f"--ros-unit: {e}")

    from conformance.lint.linter import Linter
    from conformance.scorecard import Scorecard

    monitor = _monitor(profile, options.units)
    linter = Linter(monitor, profile)
    started = time.time()
    if bag:
        from conformance.rosbag import BagError, BagReader

        reader_of_bag = BagReader(args.source, ros_unit)
        scorecard = Scorecard(out, tty=False if args.plain else None, title=reader_of_bag.name,
                              live=False)
        try:
            end = run_bag(linter, scorecard, reader_of_bag, options)
        except BagError as e:
            print(f"waraps-conformance lint: {e}", file=err)
            return EXIT_NOT_RUN
        meta = {"source": reader_of_bag.name, "recording_formats": reader_of_bag.format,
                "bag_messages_read": str(reader_of_bag.read)}
        notes, broker, problems, problem_count = list(reader_of_bag.notes), "", [], 0
    elif args.source:
        from conformance.recording import RecordingError, open_recording

        try:
            stream, name = open_recording(args.source, stdin)
        except RecordingError as e:
            print(f"waraps-conformance lint: {e}", file=err)
            return EXIT_NOT_RUN
        scorecard = Scorecard(out, tty=False if args.plain else None, title=name, live=False)
        with stream if stream is not (stdin or sys.stdin.buffer) else _noop():
            reader, end = run_recorded(linter, scorecard, stream, name, options)
        meta = {"source": name, "recording_lines": str(reader.lines),
                "recording_formats": ", ".join(sorted(reader.formats))}
        if reader.problem_count:
            meta["recording_problems"] = str(reader.problem_count)
            meta["recording_problem_lines"] = "; ".join(str(p) for p in reader.problems[:20])
        notes = [*reader.notes]
        broker = ""
        problems = reader.problems
        problem_count = reader.problem_count
    else:
        from conformance.client import BrokerError
        from conformance.lint.capture import LiveCapture

        assert options.broker is not None
        capture = LiveCapture(options.broker, options.topics)
        try:
            capture.start()
        except BrokerError as e:
            print(f"waraps-conformance lint: {e}", file=err)
            return EXIT_NOT_RUN
        scorecard = Scorecard(out, tty=False if args.plain else None,
                              title=f"{options.broker} {' '.join(options.topics)}", live=True)
        if not scorecard.tty:
            print(f"linting {', '.join(options.topics)} on {options.broker} (read-only)"
                  + (f" for {options.duration:g} s" if options.duration else " until Ctrl-C"),
                  file=out, flush=True)
        end = run_live(linter, scorecard, capture, options)
        meta = {"source": f"live {' '.join(options.topics)}"}
        if capture.dropped:
            meta["unexamined_reason"] = "the linter fell behind the broker; oldest dropped"
        notes, broker, problems, problem_count = [], str(options.broker), [], 0
    meta["duration_s"] = f"{(linter.last_time or end) - (linter.first_time or end):.3f}"
    if options.units:
        meta["units"] = " ".join(u.base for u in options.units)

    if linter.messages == 0:
        scorecard.update(linter, force=True)
        for problem in problems:
            print(f"malformed {problem}", file=out)
        print("waraps-conformance lint: no messages were read, so nothing was judged"
              + (f" ({problem_count} malformed lines)" if problem_count else ""), file=err)
        return EXIT_NOT_RUN

    report = _report(monitor, linter, kind_meta=meta, broker=broker,
                     started=started if not args.source else (linter.first_time or started),
                     finished=end)
    scorecard.final(linter, report)
    for problem in problems:
        print(f"malformed {problem}", file=out)
    if problem_count > len(problems):
        print(f"... {problem_count - len(problems)} more malformed lines", file=out)
    for note in notes:
        print(f"note: {note}", file=out)
    for gap in linter.gaps:
        print(f"connection gap: {time.strftime('%H:%M:%S', time.localtime(gap.start))} for "
              f"{gap.duration:.1f} s ({gap.reason or 'connection lost'}); rates over it not "
              f"judged", file=out)
    if report.unexamined:
        print(f"not examined: {report.unexamined} messages (rates in those windows not judged)",
              file=out)
    if formats:
        paths = write_reports(report, Path(args.reports_dir), formats, report_stem(args.source))
        for path in paths:
            print(f"report: {path}", file=out)
    evidence = failures(report)
    if evidence:
        print(f"\n{evidence}\n", file=out)
    code = int(report.exit_code(args.gate))
    failing = sorted(u for u, rep in report.units.items() if rep.worst().value == "fail"
                     and (args.gate == "all" or rep.party == "unit"))
    gated = "no unit or commander" if args.gate == "all" else "no unit"
    print(("FAIL: " + ", ".join(failing)) if failing else f"PASS: {gated} fails a rule of "
          "severity error", file=out)
    out.flush()
    return EXIT_FAIL if code else EXIT_PASS


MAX_FAILURES_SHOWN = 10


def failures(report: Any, limit: int = MAX_FAILURES_SHOWN) -> str:
    """The first violation of each failed (unit, rule), at most ``limit`` of them, in the form
    the certification prints (STYLE.md): what a person reads before opening the HTML."""
    from conformance.reporting.text import render_violation
    from conformance.violation import Verdict

    shown: list[str] = []
    more = 0
    for unit, rep in sorted(report.units.items()):
        for rule, result in sorted(rep.rules.items()):
            if result.verdict is not Verdict.FAIL or not result.violations:
                continue
            if len(shown) >= limit:
                more += 1
                continue
            text = render_violation(rule, result.violations[0], unit, report=report,
                                    verdict=Verdict.FAIL)
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
    from conformance.checks import Monitor

    return Monitor(profile, units=list(units) or None, kind="lint")


def run_recorded(linter: Any, scorecard: Any, stream: IO[bytes], name: str,
                 options: Any) -> tuple[Any, float]:
    """Feed a recording to the linter at its recorded times; returns (reader, end time)."""
    from conformance.message import Message
    from conformance.recording import RecordingReader

    reader = RecordingReader(stream, name)
    feed = linter.feed_one
    wants = options.wants if options.units else None
    limit = None
    n = 0
    last_event = None
    try:
        for item in reader:
            if type(item) is Message:
                if limit is None and options.duration:
                    limit = item.time + options.duration
                if limit is not None and item.time > limit:
                    break
                if wants is None or wants(item.topic):
                    feed(item)
            else:
                linter.event(item)
                last_event = item.time
            n += 1
            if n & 0xFF == 0:  # a pipe from mosquitto_sub is live: show progress (throttled)
                scorecard.update(linter)
    except KeyboardInterrupt:
        pass
    if reader.unprintable:
        linter.event(_unexamined(linter.last_time or 0.0, reader.unprintable))
    end = max(t for t in (linter.last_time, last_event, 0.0) if t is not None)
    linter.finish(end)
    return reader, end


def run_bag(linter: Any, scorecard: Any, bag: Any, options: Any) -> float:
    """Feed a ROS bag's messages (at their record times) and ROS findings to the linter
    (``conformance.rosbag``); returns the end time. Raises ``BagError``."""
    from conformance.client import Message

    units = set(options.units)
    wants = options.wants if units else None
    limit = None
    n = 0
    items = iter(bag)
    try:
        for item in items:
            if type(item) is Message:
                if limit is None and options.duration:
                    limit = item.time + options.duration
                if limit is not None and item.time > limit:
                    break
                if wants is None or wants(item.topic):
                    linter.feed_one(item)
            elif not units or item.unit in units:
                linter.record(item.unit, item.rule, item.violation)
            n += 1
            if n & 0xFF == 0:
                scorecard.update(linter)
    except KeyboardInterrupt:
        pass
    finally:
        items.close()  # type: ignore[attr-defined]
    end = linter.last_time or 0.0
    linter.finish(end)
    return end


def _unexamined(t: float, n: int) -> Any:
    from conformance.recording import Event

    return Event(t, "unexamined", "mosquitto_sub -F %J could not print them", n)


def run_live(linter: Any, scorecard: Any, capture: Any, options: Any) -> float:
    """Lint live traffic until the duration is over or Ctrl-C; returns the end time."""
    start = time.monotonic()
    deadline = None if not options.duration else start + options.duration
    wants = options.wants if options.units else None
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


def _report(monitor: Any, linter: Any, *, kind_meta: dict[str, str], broker: str,
            started: float, finished: float) -> Any:
    """The run report from the Monitor (it holds the gaps and unexamined counts it was told),
    with what the linter knows about its source in ``meta``."""
    return monitor.report(broker=broker, started=started, finished=finished, **kind_meta)


def report_stem(source: str | None) -> str:
    """``lint-<recording name>`` for a recording (stable for a CI gate), else
    ``lint-<local time>``."""
    if source and source != "-":
        name = Path(source).name.split(".")[0]
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
        if safe:
            return f"lint-{safe}"
    return time.strftime("lint-%Y%m%d-%H%M%S")


def write_reports(report: Any, directory: Path, formats: tuple[str, ...], stem: str) -> list[Path]:
    """Write the chosen report formats (``conformance.reporting``, the same writers as
    certification); returns their paths."""
    from conformance.reporting import write_html, write_json, write_junit

    writers = {"json": (write_json, ".json"), "html": (write_html, ".html"),
               "junit": (write_junit, ".xml")}
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for fmt in formats:
        write, suffix = writers[fmt]
        paths.append(Path(write(report, directory / f"{stem}{suffix}")))
    return paths

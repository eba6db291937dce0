"""``waraps-conformance lint``: passive linting of a whole fleet, live or recorded.

    waraps-conformance lint --broker mqtts://broker.example:8883 --duration 10m
    waraps-conformance lint --from field-test.jsonl
    waraps-conformance lint --from run.bag --ros-unit waraps/unit/ground/real/husky0
    mosquitto_sub -t 'waraps/#' -F %j | waraps-conformance lint --from -
    mosquitto_sub -t 'waraps/#' -v > capture.txt; waraps-conformance lint --from capture.txt

Live, it subscribes read-only (its client may publish nowhere) and shows a per-unit scorecard;
recorded, it judges the messages at their recorded times (a ``-v`` capture has none: the rules
that need them are could-not-test), every input within the bounds of ``conformance.bounds``. Either way it ends with JSON, HTML
and JUnit reports and exits non-zero when a unit fails a rule of severity error. The run
itself is ``conformance.lint.runner.lint``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import IO, TYPE_CHECKING

from conformance.bounds import bounds_help
from conformance.cli import options as opts
from conformance.facts import GATES, Gate
from conformance.lint import EXIT_NOT_RUN, EXIT_USAGE, REPORT_FORMATS

if TYPE_CHECKING:
    from conformance.topics import UnitAddress


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser(
        "lint",
        "Lint the traffic of a whole fleet, live (read-only: it never publishes) "
                    "or from a recording, and report a verdict per unit and rule.",
        "Exit status: 0 no unit or commander fails a rule of severity error (with "
               "--gate units: no unit), 1 one does (or units past the bound were not judged), "
               "2 bad usage, 3 nothing could be linted (no broker, no messages, a ROS bag "
               "that cannot be read whole, a --serve address that cannot be bound), 4 none fails "
               "but part of the evidence could not be examined (malformed lines, messages "
               "past a bound): partial, never clean. What is wrong in a command is its commander's "
               "fault: commanders (by the command's 'sender', else 'of UNIT') have rows of "
               "their own. " + bounds_help())
    src = p.add_argument_group("recorded traffic")
    src.add_argument("--from", dest="source", metavar="FILE",
                     help="a recording: JSON Lines as 'waraps-conformance record' writes, or "
                          "'mosquitto_sub -F %%j' / '-F %%J' / '-v' output (told from the "
                          "content; -v has no times: the rules on rates, silences, stamps and "
                          "deadlines are could-not-test); '-' reads standard input; or a ROS "
                          "bag: a ROS 1 .bag file, a ROS 2 bag directory (sqlite3 or MCAP), "
                          "read whole or refused")
    src.add_argument("--ros-unit", metavar="ADDRESS",
                     help="the unit address of a ROS bag's namespaced topics when no "
                          "/heartbeat_info TopicMsg names it, e.g. waraps/unit/ground/real/husky0")
    opts.add_capture_options(p)
    _add_judging_options(p)
    _add_serve_options(p)
    return p


def _add_judging_options(p: argparse.ArgumentParser) -> None:
    """How lint judges (profile, gate, strict) and what it writes."""
    out = p.add_argument_group("judging and reports")
    opts.add_profile_option(out)
    opts.add_reports_dir_option(out)
    out.add_argument("--format", default=",".join(REPORT_FORMATS), metavar="LIST",
                     help="report formats, comma-separated from json, html, junit; or none "
                          "(default: all three)")
    out.add_argument("--plain", action="store_true",
                     help="plain lines even on a terminal (the default in a pipe or CI)")
    out.add_argument("--gate", choices=GATES, default="all",
                     help="what the exit status judges: all (units and commanders, the "
                          "default) or units (a fleet gate that commanders' faults do not "
                          "fail)")
    out.add_argument("--strict", action="store_true",
                     help="adopt the suite's decisions as conventions: a rule whose basis is "
                          "'decided' (the spec is silent) fails instead of warning (as "
                          "'strict: true' in the profile)")


def _add_serve_options(p: argparse.ArgumentParser) -> None:
    """``--serve``: the live fleet page while lint runs."""
    web = p.add_argument_group("serving the fleet page (read-only)")
    web.add_argument("--serve", metavar="[HOST:]PORT",
                     help="while linting, serve the live fleet page on http://127.0.0.1:PORT/ "
                          "(a row per unit and commander, its rates and findings, a page per "
                          "unit), /metrics (Prometheus text) and /report.json (the report as "
                          "it stands); HOST:PORT serves on another address, with a warning "
                          "(anyone who reaches it can read it); port 0 picks a free one")
    web.add_argument("--serve-linger", metavar="TIME",
                     help="how long to keep serving once lint has ended: 0, or a time like "
                          "90s, 10m (default: until Ctrl-C after a recording (--from), not at "
                          "all after live linting)")


def parse_linger(text: str | None, recorded: bool) -> float | None:
    """Seconds to keep serving after the run (None: until Ctrl-C)."""
    if text is None:
        return None if recorded else 0.0
    if text.strip() in ("0", "0s"):
        return 0.0
    return opts.parse_duration(text)


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


def _ros_unit(args: argparse.Namespace) -> UnitAddress | None:
    """``--ros-unit``'s address (None without it); ValueError when it is no address or the
    source is no ROS bag."""
    if not args.ros_unit:
        return None
    from conformance.rosbag import is_bag
    from conformance.topics import TopicError, UnitAddress

    if not (args.source and is_bag(args.source)):
        raise ValueError("--ros-unit applies to ROS bags only (--from run.bag or a ROS 2 bag "
                         "directory)")
    try:
        return UnitAddress.parse(args.ros_unit)
    except TopicError as e:
        raise ValueError(f"--ros-unit: {e}") from None


def main(argv: list[str] | None = None, *, stdout: IO[str] | None = None,
         stdin: IO[bytes] | None = None) -> int:
    # Loaded here, not at the top: `lint --help` loads no MQTT client, schema or report writer.
    from conformance.lint.capture import CaptureOptionsError
    from conformance.lint.runner import lint
    from conformance.lint.serve import ServeError, parse_address
    from conformance.profile import ProfileError, load

    args = build_parser().parse_args(argv)

    def usage(message: str) -> int:
        opts.say("lint", message)
        return EXIT_USAGE

    if args.source and args.broker:
        return usage("--from and --broker exclude each other: lint a recording or a live broker")
    try:
        options = opts.capture_options(args, need_broker=not args.source)
        formats = parse_formats(args.format)
        problem = opts.reports_dir_problem(args.reports_dir) if formats else None
        if problem:
            raise ValueError(problem)
        profile = load(args.profile)
        if args.strict:
            import dataclasses

            profile = dataclasses.replace(profile, strict=True)
        serve = parse_address(args.serve) if args.serve is not None else None
        linger = parse_linger(args.serve_linger, bool(args.source))
    except (CaptureOptionsError, ProfileError, ValueError) as e:
        return usage(str(e))
    if args.serve_linger is not None and serve is None:
        return usage("--serve-linger applies with --serve only")
    try:
        ros_unit = _ros_unit(args)
    except ValueError as e:
        return usage(str(e))
    try:
        return lint(options, profile, source=args.source, ros_unit=ros_unit,
                    reports_dir=Path(args.reports_dir), formats=formats, gate=Gate(args.gate),
                    plain=args.plain, stdout=stdout, stdin=stdin, serve=serve, linger=linger)
    except ServeError as e:  # the address cannot be bound: nothing was linted
        opts.say("lint", e)
        return EXIT_NOT_RUN

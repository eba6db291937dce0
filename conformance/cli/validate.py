"""``waraps-conformance validate TOPIC [FILE|-]``: validate one message and say why, for a
person (what it prints: ``conformance.explanation``).

    waraps-conformance validate waraps/unit/air/simulation/dji0/heartbeat hb.json
    mosquitto_sub -t '.../heartbeat' -C 1 | waraps-conformance validate .../heartbeat -
    waraps-conformance validate --tst plan.json

``--tst`` checks a TST plan before it is sent: the file holds a start-tst command or just its
tree (the ``tst`` node object); every problem of the tree is listed with its JSON path in the
file (schemas, task parameters, structure: TST-001, TASK-*, TST-014, ERR-*).

Exit code: 0 when nothing fails under the profile (warnings allowed), 1 when a rule fails or
the message could not be examined whole (past MSG-004's size or nesting bound: verdict
could-not-test, judged on its shallower top-level fields alone), 2 for a usage error (also a topic it cannot place: it says which forms it accepts, and an input
past ``bounds.MAX_VALIDATE_BYTES``: an endless stream such as /dev/zero is not read forever).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time as time_module
from pathlib import Path
from typing import Any

from conformance import content
from conformance import profile as profile_module
from conformance.bounds import MAX_VALIDATE_BYTES, bounds_help
from conformance.cli import options as opts
from conformance.explanation import overall_verdict, render, to_dict, unplaceable, validate_tst
from conformance.validator import Validator
from conformance.violation import Verdict

PLAUSIBLE_CLOCK = content.PLAUSIBLE_CLOCK
"""Seconds a stamp may be from now when no arrival time is given (no --now, no --time): wide
enough for any recorded message of the last year, narrow enough that a stamp in milliseconds
or microseconds (MSG-008, as lint explains it), or a clock that never synchronised, fails."""


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.tst:
        if args.topic is not None and args.file != "-":
            parser.error("--tst takes one FILE (or -), no topic")
        args.file = args.topic if args.topic is not None else args.file
    elif args.topic is None:
        parser.error("a TOPIC is needed (or --tst FILE for a TST plan)")
    try:
        profile = profile_module.load(args.profile)
    except profile_module.ProfileError as e:
        opts.say("validate", e)
        return 2
    try:
        payload = read_bounded(args.file)
    except OSError as e:
        opts.say("validate", f"cannot read {args.file}: {e.strerror}")
        return 2
    except ValueError as e:
        opts.say("validate", e)
        return 2
    arrival = time_module.time() if args.now else args.time
    notes: list[str] = []
    if args.tst:
        validation = validate_tst(Validator(profile), payload)
    else:
        judging = profile
        if arrival is None:  # no arrival time: the stamp is judged for plausibility only
            judging = dataclasses.replace(profile, clock_tolerance=PLAUSIBLE_CLOCK)
            arrival = time_module.time()
        validation = Validator(judging).validate(args.topic, payload, arrival)
        if validation.topic.unit is None:
            print(unplaceable(args.topic), file=sys.stderr)
            return 2
        stamp = validation.message.get("stamp") if isinstance(validation.message, dict) else None
        if judging is not profile and type(stamp) in (int, float):
            notes.append(_plausibility_only(profile))
    if args.json:
        print(json.dumps({**to_dict(validation, profile), "notes": notes}, indent=2))
    else:
        print(render(validation, profile))
        for note in notes:
            print(f"note      {note}")
    # Not examined whole (MSG-004) is no pass either: 1, as a failure.
    return 1 if overall_verdict(validation, profile) in (Verdict.FAIL,
                                                         Verdict.COULD_NOT_TEST) else 0


def _plausibility_only(profile: profile_module.Profile) -> str:
    """The note on a stamp judged without an arrival time."""
    return (f"the stamp was judged for plausibility only (Unix seconds within "
            f"{PLAUSIBLE_CLOCK / 86400:.0f} days of now: not milliseconds, not a "
            f"clock left at 1970); pass --now for a message just captured, or "
            f"--time T, to judge it within {profile.clock_tolerance:g} s (MSG-005)")


def _parser() -> argparse.ArgumentParser:
    """validate's options: a topic and a file, or --tst and a file; the arrival time."""
    parser = opts.parser("validate",
                         "Validate one WARA-PS message: print its kind and every violation.",
                         bounds_help(validate=True))
    parser.add_argument("topic", nargs="?", default=None,
                        help="the MQTT topic, e.g. waraps/unit/air/simulation/dji0/heartbeat "
                             "(not with --tst)")
    parser.add_argument("file", nargs="?", default="-",
                        help="file with the raw payload, or - for standard input (default)")
    parser.add_argument("--tst", action="store_true",
                        help="the file is a TST plan: a start-tst command or its tree; list "
                             "every problem of the tree with its JSON path")
    opts.add_profile_option(parser)
    when = parser.add_mutually_exclusive_group()
    when.add_argument("--time", type=float, default=None,
                      help="arrival time (Unix seconds) to judge the stamp against (MSG-005)")
    when.add_argument("--now", action="store_true",
                      help="judge the stamp against the current time (a message just captured); "
                           "with neither, a stamp is judged for plausibility only (seconds, "
                           "within a year of now), and the output says so")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    return parser


def read_bounded(name: str, limit: int = MAX_VALIDATE_BYTES) -> bytes:
    """The bytes of file ``name`` (``-``: standard input), at most ``limit``: ValueError past
    it, so an endless stream (/dev/zero) is refused after ``limit`` + 1 bytes, never read to
    the end of memory. A directory is an OSError (IsADirectoryError)."""
    if name == "-":
        data = _read_at_most(sys.stdin.buffer, limit)
    else:
        with Path(name).open("rb") as f:
            data = _read_at_most(f, limit)
    if data is not None:
        return data
    where = "standard input" if name == "-" else name
    raise ValueError(f"{where} holds more than the {limit >> 20} MiB validate reads (one message "
                     f"is examined up to 1 MiB, MSG-004); pass a file holding one message")


def _read_at_most(f: Any, limit: int) -> bytes | None:
    """All of ``f`` if it holds at most ``limit`` bytes, else None (``limit`` + 1 read)."""
    chunks: list[bytes] = []
    size = 0
    while size <= limit:
        chunk = f.read(min(1 << 20, limit + 1 - size))
        if not chunk:
            return b"".join(chunks)
        chunks.append(chunk)
        size += len(chunk)
    return None

"""``waraps-conformance profile --unit ADDRESS``: observe a unit (read-only) and write a
starting profile from what it declares and publishes; the drafting is
``conformance.profile_draft``, the format ``schemas/generated/PROFILE.md``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from conformance.cli import options as opts
from conformance.masking import mask_password

EXIT_NOT_SEEN = 6
"""The unit was not heard (no heartbeat): as a certification of it would say (README 'Exit
status')."""


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser(
        "profile",
        "Observe a unit for a while (read-only: it never publishes) and write a starting "
        "profile from what it declares and publishes: levels, sensors, tasks, rates. Edit it, "
        "then certify with 'pytest --unit ADDRESS --profile FILE'. The format: "
        "schemas/generated/PROFILE.md.",
        "Exit status: 0 drafted, 2 bad usage (an option, an output that exists), 3 the broker "
        "could not be reached or the output not written, 6 no heartbeat of the unit was seen "
        "(a commented draft is written all the same).")
    opts.add_broker_options(p, broker_help=f"mqtt://host:port or mqtts://host:port (default: "
                                           f"{opts.BROKER_ENV})")
    p.add_argument("--unit", required=True, metavar="ADDRESS",
                   help="the unit, e.g. waraps/unit/air/real/dji0")
    p.add_argument("--observe", default="30s", metavar="TIME",
                   help="how long to observe it: long enough for its info messages and ten "
                        "intervals of its slowest rate (default 30s)")
    p.add_argument("-o", "--output", default="-", metavar="FILE",
                   help="where to write the profile (default: standard output); an existing "
                        "file is not overwritten")
    return p


def _output_problem(out: Path | None) -> str:
    """Why the draft cannot go to ``out`` ('' when it can; None: standard output)."""
    if out is not None and out.exists():
        return f"{out} exists; name a new file (a profile you edited is never overwritten)"
    if out is not None and not out.absolute().parent.is_dir():
        return f"cannot write {out}: {out.parent} is not a folder"
    return ""


def _write(text: str, out: Path | None) -> bool:
    """The draft written to ``out`` (None: standard output); False when it could not be."""
    if out is None:
        sys.stdout.write(text)
        return True
    try:
        out.write_text(text, "utf-8")
    except OSError as e:  # a full disk
        opts.say("profile", f"cannot write {out}: {e.strerror or e}")
        return False
    print(opts.shown(f"wrote {out}"), file=sys.stderr)
    return True


def main(argv: list[str] | None = None) -> int:
    from conformance.client import BrokerError, BrokerURL, MqttClient
    from conformance.profile_draft import draft, observe, problems
    from conformance.topics import TopicError, UnitAddress

    args = build_parser().parse_args(argv)
    try:
        option = "--unit"
        unit = UnitAddress.parse(args.unit)
        option = "--observe"
        seconds = opts.parse_duration(args.observe)
        option = "--broker"
        broker = BrokerURL.parse(args.broker) if args.broker else BrokerURL.from_env()
    except (TopicError, ValueError) as e:
        opts.say("profile", f"{option}: {e}")
        return 2
    if broker is None:
        opts.say("profile", "no broker: pass --broker mqtt://host:port or set WARAPS_BROKER")
        return 2
    out = None if args.output == "-" else Path(args.output)
    problem = _output_problem(out)
    if problem:  # said before observing
        opts.say("profile", problem)
        return 2

    def say(text: str) -> None:
        print(opts.shown(text), file=sys.stderr)

    try:
        with MqttClient(opts.with_tls(broker, args)).connect() as client:
            seen = observe(lambda: client, unit, seconds, say=say)
    except BrokerError as e:  # the message says what failed and how to fix it
        opts.say("profile", e)
        return 3
    text = draft(seen)
    for problem in problems(seen):  # said, not only written: the unit contradicts itself
        print(opts.shown(f"PROBLEM: {problem}"), file=sys.stderr)
    if not _write(text, out):
        return 3
    if seen.heartbeat is None:  # said, not only in the draft's comments
        opts.say("profile", f"no heartbeat of {unit} within {args.observe} on "
                            f"{mask_password(str(broker), url=True)}: the draft says what "
                            f"was not seen (is the unit running, and is its address right?)")
        return EXIT_NOT_SEEN
    return 0

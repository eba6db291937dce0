"""``waraps-conformance record -o FILE``: record live traffic (read-only) to JSON Lines; the
recording is ``conformance.lint.recorder.record``, its format ``conformance.recording``."""

from __future__ import annotations

import argparse
import sys

from conformance.cli import options as opts


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser(
        "record",
        "Record live traffic (read-only: it never publishes) to a JSON Lines file "
                    "that 'waraps-conformance lint --from FILE' judges later. Connection "
                    "losses and messages the recorder could not keep up with are recorded too.")
    opts.add_capture_options(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="the JSON Lines file to write ('-' for standard output)")
    return p


def main(argv: list[str] | None = None) -> int:
    from conformance.client import BrokerError
    from conformance.lint.capture import CaptureOptionsError
    from conformance.lint.recorder import record

    args = build_parser().parse_args(argv)
    try:
        options = opts.capture_options(args)
    except CaptureOptionsError as e:
        opts.say("record", e)
        return 2
    out = sys.stdout.buffer if args.output == "-" else open(args.output, "wb")
    try:
        return record(options, out, name=args.output, log=sys.stderr)
    except BrokerError as e:  # the message says what failed and how to fix it
        opts.say("record", e)
        return 3
    finally:
        if out is not sys.stdout.buffer:
            out.close()

"""``waraps-conformance record -o FILE``: record live traffic (read-only) to JSON Lines; the
recording is ``conformance.lint.recorder.record``, its format ``conformance.recording``."""

from __future__ import annotations

import argparse
import sys

from conformance.cli import options as opts
from conformance.cli.pipe import reader_left


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser(
        "record",
        "Record live traffic (read-only: it never publishes) to a JSON Lines file "
                    "that 'waraps-conformance lint --from FILE' judges later. Connection "
                    "losses and messages the recorder could not keep up with are recorded too.",
        "Exit status: 0 recorded, 2 bad usage (an option, an output that cannot be opened), "
        "3 the broker could not be reached or the output could not be written (a full disk).")
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
    try:
        out = sys.stdout.buffer if args.output == "-" else open(args.output, "wb")
    except OSError as e:
        opts.say("record", f"cannot write {args.output}: {e.strerror or e}")
        return 2
    try:
        try:
            return record(options, out, name=args.output, log=sys.stderr)
        finally:
            if out is not sys.stdout.buffer:
                out.close()
    except BrokerError as e:  # the message says what failed and how to fix it
        opts.say("record", e)
        return 3
    except BrokenPipeError:  # `record -o - | head`: the reader left, the recording ends
        reader_left(sys.stdout)
        return 0
    except OSError as e:  # the disk is full (ENOSPC)
        opts.say("record", f"cannot write {args.output}: {e.strerror or e}; what was "
                           f"recorded before is kept")
        return 3

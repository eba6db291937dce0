"""``waraps-conformance record -o FILE``: record live traffic (read-only) to JSON Lines; the
recording is ``conformance.lint.recorder.record``, its format ``conformance.recording``."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import IO

from conformance.cli import options as opts
from conformance.cli.pipe import reader_left


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser(
        "record",
        "Record live traffic (read-only: it never publishes) to a JSON Lines file "
                    "that 'waraps-conformance lint --from FILE' judges later. Connection "
                    "losses and messages the recorder could not keep up with are recorded too.",
        "Exit status: 0 recorded, 2 bad usage (an option, an output that cannot be opened or "
        "exists without --force), "
        "3 the broker could not be reached or the output could not be written (a full disk).")
    opts.add_capture_options(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="the JSON Lines file to write ('-' for standard output); created once "
                        "the broker is reached (nothing is written when it is not)")
    p.add_argument("--force", action="store_true",
                   help="replace FILE when it exists (without it, an existing file is kept "
                        "and record exits 2: a recording is never lost by accident)")
    return p


def refused(path: Path, force: bool) -> str | None:
    """Why ``record -o path`` may not write there (said before connecting), or None: a
    regular file is replaced only with --force; a FIFO or a device is written to."""
    if path.exists() and path.is_file() and not force:
        return (f"{path} exists; pass --force to replace it, or name a new file (a "
                f"recording is never overwritten by accident)")
    if not path.absolute().parent.is_dir():
        return f"cannot write {path}: {path.parent} is not a folder"
    return None


def opener(path: Path, force: bool) -> Callable[[], IO[bytes]]:
    """Opens ``path`` when the recording starts (after the broker was reached): a new
    file exclusively, so that a file created meanwhile is not replaced either."""
    exclusive = not force and not path.exists()
    return lambda: open(path, "xb" if exclusive else "wb")


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
    path = None if args.output == "-" else Path(args.output)
    why = refused(path, args.force) if path is not None else None
    if why:
        opts.say("record", why)
        return 2
    open_output = (lambda: sys.stdout.buffer) if path is None else opener(path, args.force)
    try:
        return record(options, open_output, name=args.output, log=sys.stderr)
    except BrokerError as e:  # the message says what failed and how to fix it; no file
        opts.say("record", e)
        return 3
    except FileExistsError:  # created by someone else since it was checked: theirs
        opts.say("record", refused(Path(args.output), False) or f"{args.output} exists")
        return 2
    except BrokenPipeError:  # `record -o - | head`: the reader left, the recording ends
        reader_left(sys.stdout)
        return 0
    except OSError as e:  # the disk is full (ENOSPC)
        opts.say("record", f"cannot write {args.output}: {e.strerror or e}; what was "
                           f"recorded before is kept")
        return 3

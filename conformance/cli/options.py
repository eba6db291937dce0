"""Option groups the subcommands share, defined once, so an option has one spelling and one
meaning everywhere: the broker and its TLS files (also the pytest plugin's names), the live
traffic to capture, the reference unit, the profile, where reports go, and how a duration is
written (also for the plugin's durations).

Only the standard library is imported at module level (the plugin imports this module, and
must stay cheap); what an option means is decided by the part that does the work.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, NoReturn

from conformance.display import shown

if TYPE_CHECKING:
    from conformance.client import BrokerURL
    from conformance.lint.capture import CaptureOptions

BROKER_ENV = "WARAPS_BROKER, WARAPS_PORT, WARAPS_TLS_CONNECTION"
CREDENTIALS = ("user and password only from WARAPS_USERNAME / WARAPS_PASSWORD (never on the "
               "command line)")

TLS_FILES: tuple[tuple[str, str], ...] = (
    ("--ca-file", "CA certificate to verify an mqtts:// broker"),
    ("--cert-file", "client certificate for an mqtts:// broker"),
    ("--key-file", "client key for an mqtts:// broker"),
)
"""The TLS file options (metavar PEM) of every command that connects, and of the plugin."""
TLS_INSECURE = ("--tls-insecure",
                "do not verify the mqtts:// broker's certificate (test brokers only)")


MAX_DURATION_SECONDS = 366 * 86400
"""The longest duration an option takes (a year: '9' * 400 seconds is infinity as a float)."""
_DURATION = re.compile(r"(\d+(?:\.\d*)?|\.\d+)(ms|min|h|m|s)?")
_UNIT_SECONDS = {"h": 3600.0, "min": 60.0, "m": 60.0, "s": 1.0, "ms": 0.001, None: 1.0}


def parse_duration(text: str) -> float:
    """Seconds from a duration as a person types it: ``10m``, ``90s``, ``1h30m``, ``1.5h``,
    ``10min`` or a plain number of seconds; the same for every option that takes one (the
    plugin's ``--max-duration`` and ``--observe``, ``lint``/``record --duration``).
    ValueError says what is accepted."""
    s = text.strip().lower().replace(" ", "")
    pos, total = 0, 0.0
    while pos < len(s):
        m = _DURATION.match(s, pos)
        if m is None:
            break
        total += float(m.group(1)) * _UNIT_SECONDS[m.group(2)]
        pos = m.end()
    if not s or pos != len(s) or not 0 < total <= MAX_DURATION_SECONDS:  # inf and nan too
        raise ValueError(f"duration {_excerpt(text)} is not a positive time like 90s, 10m, "
                         f"1h30m or a number of seconds, at most {MAX_DURATION_SECONDS // 86400} "
                         f"days")
    return total


def _excerpt(text: str) -> str:
    return repr(text) if len(text) <= 80 else f"{text[:80]!r}... ({len(text)} chars)"


def say(command: str, message: object, file: IO[str] | None = None) -> None:
    """``waraps-conformance COMMAND: message`` on one line of ``file`` (standard error)."""
    print(shown(f"waraps-conformance {command}: {message}"),
          file=sys.stderr if file is None else file, flush=True)


class _Parser(argparse.ArgumentParser):
    """argparse's parser whose errors (which repeat what was typed: ``unrecognized
    arguments: ...``) are shown escaped and masked, like every other error."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {shown(message)}\n")


MAX_RATE = 1000.0
"""The fastest the reference unit publishes, in Hz (a period of 1 ms: its loop keeps up)."""


def parse_rate(text: str) -> float:
    """A rate in Hz as ``--rate`` and ``--sim-rate`` take it: a number above 0, at most
    ``MAX_RATE`` (``inf``, ``nan``, 0 and negative numbers are refused). An
    ``argparse.ArgumentTypeError`` (a usage error of the command, or of pytest) says so."""
    try:
        rate = float(text)
    except ValueError:
        rate = float("nan")
    if not 0 < rate <= MAX_RATE:  # False for nan too
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a rate: a positive number of Hz, at most {MAX_RATE:g}")
    return rate


def parser(command: str, description: str, epilog: str | None = None
           ) -> argparse.ArgumentParser:
    """The argument parser of ``waraps-conformance COMMAND``."""
    return _Parser(prog=f"waraps-conformance {command}", description=description,
                   epilog=epilog)


class _DeprecatedFlag(argparse.Action):
    """A hidden old spelling of a flag: still works, and says which spelling replaces it."""

    def __init__(self, option_strings: list[str], dest: str, *, replacement: str,
                 **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=False, help=argparse.SUPPRESS,
                         **kwargs)
        self.replacement = replacement

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        print(f"{parser.prog}: {option_string} is deprecated, use {self.replacement}",
              file=sys.stderr)
        setattr(namespace, self.dest, True)


def add_broker_options(parser: argparse.ArgumentParser, *, title: str = "broker",
                       broker_help: str) -> argparse._ArgumentGroup:
    """``--broker URL`` and the TLS options (``--ca-file``, ``--cert-file``, ``--key-file``,
    ``--tls-insecure``; ``--insecure`` is a hidden deprecated alias). Returns the group."""
    g = parser.add_argument_group(title)
    g.add_argument("--broker", metavar="URL", default=None,
                   help=f"{broker_help}; {CREDENTIALS}")
    for option, help_ in TLS_FILES:
        g.add_argument(option, metavar="PEM", help=help_)
    g.add_argument(TLS_INSECURE[0], dest="tls_insecure", action="store_true",
                   help=TLS_INSECURE[1])
    # lint and record spelled it --insecure before the plugin's --tls-insecure was shared.
    g.add_argument("--insecure", dest="tls_insecure", action=_DeprecatedFlag,
                   replacement=TLS_INSECURE[0])
    return g


def with_tls(broker: BrokerURL, args: argparse.Namespace) -> BrokerURL:
    """``broker`` with the TLS files and ``--tls-insecure`` given on the command line."""
    if args.ca_file or args.cert_file or args.key_file or args.tls_insecure:
        return broker.with_tls_files(args.ca_file, args.cert_file, args.key_file,
                                     args.tls_insecure)
    return broker


def add_capture_options(parser: argparse.ArgumentParser) -> None:
    """What ``lint`` and ``record`` capture live: the broker and TLS options, the
    subscriptions, the units, for how long."""
    from conformance.lint.capture import DEFAULT_TOPIC

    g = add_broker_options(parser, title="live traffic",
                           broker_help=f"mqtt://host:port or mqtts://host:port (default: "
                                       f"{BROKER_ENV})")
    g.add_argument("--topic", action="append", metavar="FILTER",
                   help=f"subscription filter, repeatable (default {DEFAULT_TOPIC!r}, or "
                        f"UNIT/# for each --unit)")
    g.add_argument("--unit", action="append", metavar="ADDRESS",
                   help="only this unit, e.g. waraps/unit/air/real/dji0 (repeatable)")
    g.add_argument("--duration", metavar="TIME",
                   help="stop after this long: 90s, 10m, 1h (default: until Ctrl-C)")


def capture_options(args: argparse.Namespace, *, need_broker: bool = True) -> CaptureOptions:
    """The capture options of parsed arguments; ``CaptureOptionsError`` says what to fix."""
    from conformance.lint.capture import CaptureOptionsError
    from conformance.lint.capture import capture_options as build

    try:
        duration = parse_duration(args.duration) if args.duration else None
    except ValueError as e:
        raise CaptureOptionsError(str(e)) from None
    options = build(args.broker, topics=args.topic or (), units=args.unit or (),
                    duration=duration, need_broker=need_broker)
    return options if options.broker is None else options.with_broker(with_tls(options.broker,
                                                                               args))


def add_profile_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, *,
                       default: str | None = "default") -> None:
    """``--profile NAME|FILE``: a built-in profile (default, strict, ...) or a YAML file."""
    parser.add_argument("--profile", default=default, metavar="NAME|FILE",
                        help="built-in profile name (default, strict) or a profile YAML file "
                             "(default: default)")


def add_reports_dir_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--reports-dir DIR``, as the plugin spells it."""
    parser.add_argument("--reports-dir", default="reports", metavar="DIR",
                        help="where the reports go (default: reports/)")


def reports_dir_problem(path: str | Path, *, create: bool = True) -> str | None:
    """Why ``--reports-dir`` ``path`` cannot hold reports (it, or the nearest of its parents
    that exists, is not a folder; with ``create``, it cannot be made), or None; said before
    anything runs, not at the end."""
    here = Path(path)
    for folder in (here, *here.parents):
        if folder.exists():
            if not folder.is_dir():
                return (f"--reports-dir {str(path)!r}: {str(folder)!r} is not a folder (the "
                        f"reports go into a folder, created when missing)")
            break
    if create:
        try:
            here.mkdir(parents=True, exist_ok=True)
        except OSError as e:  # a read-only file system, no permission
            return f"--reports-dir {str(path)!r}: cannot create it: {e.strerror or e}"
        try:  # a folder that exists may still refuse files (read-only, /proc, permissions)
            import tempfile

            with tempfile.TemporaryFile(dir=here, prefix=".waraps-conformance-probe-"):
                pass
        except OSError as e:
            return (f"--reports-dir {str(path)!r}: cannot write a report into it: "
                    f"{e.strerror or e}; pass a folder you can write to")
    return None


REFERENCE_UNIT = "waraps/unit/air/simulation/dji0"
"""Where the bundled reference unit runs unless told otherwise (``sim``, ``demo``)."""


def add_reference_unit_options(parser: argparse.ArgumentParser, *,
                               fault_metavar: str = "NAME") -> None:
    """The reference unit's ``--unit``, ``--rate``, ``--fault``, ``--variant`` and ``--tst``, as
    ``sim`` and ``demo`` (which runs it under the certification) both take them."""
    parser.add_argument("--unit", default=REFERENCE_UNIT, metavar="ADDRESS",
                        help=f"its address, PREFIX/unit/TYPE/ROLE/NAME (default {REFERENCE_UNIT})")
    parser.add_argument("--rate", type=parse_rate, default=1.0, metavar="HZ",
                        help="declared rate of heartbeat, info messages and sensors (default 1)")
    parser.add_argument("--fault", action="append", default=[], metavar=fault_metavar,
                        help="switch a fault on (repeatable; waraps-conformance sim "
                             "--list-faults lists them)")
    parser.add_argument("--variant", action="append", default=[], metavar="NAME",
                        help="switch a conformant variant on (repeatable; waraps-conformance "
                             "sim --list-variants lists them)")
    parser.add_argument("--tst", action="store_true",
                        help="declare 'tst execution' and run TST trees (spec 14) sent to the "
                             "unit's own tst/command")

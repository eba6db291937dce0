"""The console script ``waraps-conformance``: one subcommand per product part.

Each subcommand is a thin module of this package, ``conformance.cli.<name>``, exposing
``main(argv) -> int``: it parses its arguments (the shared option groups are in
``conformance.cli.options``) and calls the part that does the work, imported inside ``main``
after the arguments are parsed, so that ``COMMAND --help`` loads no MQTT client, schema or
broker (the pytest plugin, ``plugin.py``, likewise loads the suite only for ``--unit``).
This module only dispatches, so ``waraps-conformance --help`` stays fast (no amqtt, paho or
schema import).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

# name -> one-line help; the command is the module conformance.cli.<name>
COMMANDS: dict[str, str] = {
    "demo": "certify the bundled reference unit on the embedded broker",
    "lint": "lint live or recorded traffic of a whole fleet (never publishes)",
    "record": "record live traffic to a JSON Lines file",
    "profile": "write a starting profile from what a unit declares and publishes",
    "sim": "run the reference unit (or a fleet of them), with faults",
    "broker": "run the embedded amqtt broker on loopback",
    "rules": "print the rule catalogue",
    "schemas": "generate the JSON Schemas and task docs (schemas generate)",
    "validate": "validate one message: TOPIC [PAYLOAD-FILE|-]",
}


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: waraps-conformance COMMAND [options]", "", "commands:"]
    lines += [f"  {name:<{width}}  {help_}" for name, help_ in COMMANDS.items()]
    lines += ["", "Certify one unit with pytest: pytest --unit waraps/unit/air/simulation/dji0 "
              "--broker mqtt://127.0.0.1:1883",
              "Run 'waraps-conformance COMMAND --help' for a command's options."]
    return "\n".join(lines)


def _terminate_as_ctrl_c() -> Callable[[], None]:
    """SIGTERM (``kill``, ``timeout``, a service manager) ends a command as Ctrl-C does: a
    recording gets its end and its closing line, lint its reports (``sim`` sets its own).
    Returns what puts the previous handler back (a caller in process: the tests)."""
    import signal
    import threading

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGTERM, interrupt)

    def restore() -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)

    return restore


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    if argv[0] in ("-V", "--version"):
        from conformance import __version__

        print(__version__)
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        import difflib

        close = difflib.get_close_matches(name, COMMANDS, n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        from conformance.display import printable

        print(f"waraps-conformance: unknown command {printable(repr(name))}.{hint}\n\n{usage()}",
              file=sys.stderr)
        return 2
    module = importlib.import_module(f"{__name__}.{name}")
    from conformance.cli.pipe import PipeOut

    restore = _terminate_as_ctrl_c()

    stdout, sys.stdout = sys.stdout, PipeOut(sys.stdout)
    try:
        return int(module.main(rest) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `... | head` where a part writes to the stream itself
        sys.stderr.close()
        return 0
    finally:
        sys.stdout = stdout
        restore()

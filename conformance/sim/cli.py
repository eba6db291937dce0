"""``waraps-conformance sim``: run the reference unit (or a fleet of them), with faults.

    waraps-conformance sim --unit waraps/unit/air/simulation/dji0 --broker mqtt://127.0.0.1:1883
    waraps-conformance sim --broker embedded --count 500 --fault heartbeat-rate-drift@3
    waraps-conformance sim --list-faults
    waraps-conformance sim --tst --tst-operator waraps/unit/ground/real/op0 --count 3

When ready it prints one line, ``ready pid=... broker=... unit=...`` (with ``--broker
embedded`` the broker's URL comes first, on a line of its own), then runs until SIGINT or
SIGTERM. SIGHUP reboots every unit (so a certifier can pass ``--reboot-cmd "kill -HUP
<pid>"``); lines on stdin control it too: ``reboot``, ``reboot NAME``, ``stop``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from collections.abc import Sequence

from conformance.client import BrokerError, BrokerURL
from conformance.sim.faults import FAULTS, NOT_UNIT_BREAKABLE, FaultError, check_names
from conformance.topics import TopicError, UnitAddress

DEFAULT_UNIT = "waraps/unit/air/simulation/dji0"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="waraps-conformance sim",
        description="Run the WARA-PS reference unit: conformant on the levels 'sensor' and "
                    "'direct execution' (and 'tst execution' with --tst), unless faults are "
                    "switched on.")
    p.add_argument("--unit", default=DEFAULT_UNIT, metavar="ADDRESS",
                   help=f"PREFIX1/unit/TYPE/ROLE/NAME (default {DEFAULT_UNIT})")
    p.add_argument("--broker", default=None, metavar="URL",
                   help="mqtt://host:port, mqtts://host:port or 'embedded' (start one in this "
                        "process); default: WARAPS_BROKER/WARAPS_PORT, else embedded")
    p.add_argument("--count", type=int, default=1, metavar="N",
                   help="run N units named with a numeric suffix (dji0, dji1, ...) on one "
                        "connection")
    p.add_argument("--rate", type=float, default=1.0, metavar="HZ",
                   help="declared rate of heartbeat, info messages and sensors (default 1)")
    p.add_argument("--fault", action="append", default=[], metavar="NAME[@I,J]",
                   help="switch a fault on (repeatable); @I,J only for the units with those "
                        "indexes (0-based) of a --count fleet")
    p.add_argument("--list-faults", action="store_true",
                   help="print the faults with the rule ids each one breaks, and exit")
    p.add_argument("--json", action="store_true", help="with --list-faults: as JSON")
    p.add_argument("--seed", type=int, default=None,
                   help="repeatable agent-uuids and com-uuids (a process restarted with the "
                        "same seed starts with the same agent-uuid: reboot it with SIGHUP)")
    p.add_argument("--tst", action="store_true",
                   help="declare 'tst execution' and run TST trees (spec 14) sent to the "
                        "unit's own tst/command")
    p.add_argument("--tst-operator", default=None, metavar="ADDRESS",
                   help="with --tst: also take TST commands for this unit from the operator's "
                        "tst/command (14.1: 'usually sent to op0'), e.g. "
                        "waraps/unit/ground/real/op0; answered on the operator's topics")
    p.add_argument("--task-seconds", type=float, default=3.0, metavar="S",
                   help="about how long a simulated task takes (time compression; default 3)")
    return p


def list_faults(as_json: bool) -> str:
    if as_json:
        return json.dumps({
            "faults": [{"name": f.name, "rules": list(f.rules), "scope": f.scope,
                        "active": f.active, "description": f.description}
                       for f in FAULTS.values()],
            "not_unit_breakable": NOT_UNIT_BREAKABLE,
        }, indent=2)
    width = max(map(len, FAULTS))
    lines = [f"{'fault':<{width}}  rules broken / what it does", ""]
    for f in FAULTS.values():
        scope = "  [only visible to a broker-wide observer]" if f.scope == "broker" else ""
        lines.append(f"{f.name:<{width}}  {' '.join(f.rules)}{scope}")
        lines.append(f"{'':<{width}}    {f.description}")
    lines += ["", "Rules no unit can break (no fault):"]
    lines += [f"  {rule}: {why}" for rule, why in NOT_UNIT_BREAKABLE.items()]
    return "\n".join(lines)


def parse_faults(specs: Sequence[str], count: int) -> tuple[frozenset[str], dict[int, set[str]]]:
    """``NAME`` (every unit) and ``NAME@I,J`` (units I and J) into common and per-index sets."""
    common: set[str] = set()
    by_index: dict[int, set[str]] = {}
    for spec in specs:
        name, _, where = spec.partition("@")
        check_names([name])
        if not where:
            common.add(name)
            continue
        for part in where.split(","):
            if not part.strip().isdigit() or not 0 <= int(part) < count:
                raise FaultError(f"--fault {spec}: {part!r} is not a unit index from 0 to "
                                 f"{count - 1}")
            by_index.setdefault(int(part), set()).add(name)
    return frozenset(common), by_index


def main(argv: list[str]) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.list_faults:
        print(list_faults(args.json))
        return 0
    if args.count < 1:
        parser.error(f"--count {args.count}: at least 1")
    if not args.rate > 0:
        parser.error(f"--rate {args.rate}: a rate is a positive number of Hz")
    if args.tst_operator and not args.tst:
        parser.error("--tst-operator needs --tst")
    try:
        address = UnitAddress.parse(args.unit)
        operator = UnitAddress.parse(args.tst_operator) if args.tst_operator else None
        common, by_index = parse_faults(args.fault, args.count)
    except (TopicError, FaultError) as e:
        parser.error(str(e))

    broker_text = args.broker
    if broker_text is None:
        env = BrokerURL.from_env()
        broker_text = str(env) if env is not None else "embedded"
    embedded = None
    if broker_text == "embedded":
        from conformance.broker import EmbeddedBroker

        embedded = EmbeddedBroker().start()
        broker_text = embedded.url
        print(broker_text, flush=True)
    try:
        broker = BrokerURL.parse(broker_text)
    except ValueError as e:
        parser.error(str(e))

    from conformance.sim.fleet import Fleet, SimUnit

    runner: SimUnit | Fleet
    if args.count == 1:
        runner = SimUnit(address, broker, faults=common | by_index.get(0, set()),
                         rate=args.rate, seed=args.seed, task_seconds=args.task_seconds,
                         tst_execution=args.tst, tst_operator=operator)
        units = f"unit={runner.base} agent-uuid={runner.agent_uuid}"
    else:
        runner = Fleet(address, broker, args.count, faults=common, faults_by_index=by_index,
                       rate=args.rate, seed=args.seed, task_seconds=args.task_seconds,
                       tst_execution=args.tst, tst_operator=operator)
        units = (f"units={runner.addresses[0]}..{runner.addresses[-1].name} "
                 f"count={args.count}")
    stop = threading.Event()
    try:
        runner.start(timeout=max(10.0, 3.0 / args.rate))
    except (BrokerError, TimeoutError) as e:
        print(f"waraps-conformance sim: {e}", file=sys.stderr)
        if embedded is not None:
            embedded.stop()
        return 1

    def reboot(name: str | None = None) -> None:
        if isinstance(runner, SimUnit):
            runner.reboot()
        else:
            runner.reboot(None if name is None else (
                int(name) if name.isdigit() else runner.index_of(name)))

    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    if hasattr(signal, "SIGHUP"):
        signal.signal(signal.SIGHUP, lambda *_: reboot())
    threading.Thread(target=_read_control, args=(reboot, stop), daemon=True,
                     name="sim-stdin").start()
    faults = ",".join(args.fault) or "none"
    tst = f" tst=on{f' operator={operator}' if operator else ''}" if args.tst else ""
    print(f"ready pid={os.getpid()} broker={broker} {units} rate={args.rate:g} "
          f"faults={faults}{tst}", flush=True)
    try:
        while not stop.wait(0.2):
            pass
    finally:
        runner.stop()
        if embedded is not None:
            embedded.stop()
    return 0


def _read_control(reboot, stop: threading.Event) -> None:  # type: ignore[no-untyped-def]
    """stdin lines: 'reboot', 'reboot NAME|INDEX', 'stop'. End of input changes nothing."""
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        try:
            if words[0] == "reboot":
                reboot(words[1] if len(words) > 1 else None)
                print(f"rebooting {words[1] if len(words) > 1 else 'all'}", flush=True)
            elif words[0] in ("stop", "quit", "exit"):
                stop.set()
                return
            else:
                print(f"unknown control {words[0]!r}: reboot [NAME], stop", flush=True)
        except (KeyError, IndexError) as e:
            print(f"control {line.strip()!r}: {e}", flush=True)

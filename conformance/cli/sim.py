"""``waraps-conformance sim``: run the reference unit (or a fleet of them), with faults.

    waraps-conformance sim --unit waraps/unit/air/simulation/dji0 --broker mqtt://127.0.0.1:1883
    waraps-conformance sim --broker embedded --count 500 --fault heartbeat-rate-drift@3
    waraps-conformance sim --list-faults
    waraps-conformance sim --variant strict --variant key-order
    waraps-conformance sim --list-variants

What it prints and how it is controlled (signals, stdin): ``conformance.sim.process``.
"""

from __future__ import annotations

import argparse

from conformance.cli import options as opts


def build_parser() -> argparse.ArgumentParser:
    p = opts.parser(
        "sim",
        "Run the WARA-PS reference unit: conformant on the levels 'sensor' and "
                    "'direct execution' (and 'tst execution' with --tst), unless faults are "
                    "switched on.",
        "Exit status: 0 stopped (Ctrl-C, SIGTERM), 2 bad usage, 3 the broker could not be "
        "reached (as for lint, record and profile).")
    opts.add_reference_unit_options(p, fault_metavar="NAME[@I,J]")
    p.add_argument("--count", type=int, default=1, metavar="N",
                   help="run N units named with a numeric suffix (dji0, dji1, ...) on one "
                        "connection; --fault NAME@I,J only for the units with those indexes "
                        "(0-based)")
    p.add_argument("--task-seconds", type=float, default=3.0, metavar="S",
                   help="about how long a simulated task takes (time compression; default 3)")
    p.add_argument("--seed", type=int, default=None,
                   help="repeatable agent-uuids and com-uuids (a process restarted with the "
                        "same seed starts with the same agent-uuid: reboot it with SIGHUP)")
    p.add_argument("--tst-operator", default=None, metavar="ADDRESS",
                   help="with --tst: also take TST commands for this unit from the operator's "
                        "tst/command (14.1: 'usually sent to op0'), e.g. "
                        "waraps/unit/ground/real/op0; answered on the operator's topics")
    opts.add_broker_options(p, broker_help=f"mqtt://host:port, mqtts://host:port or "
                                           f"'embedded' (start one in this process); default: "
                                           f"{opts.BROKER_ENV}, else embedded")
    faults = p.add_argument_group("the faults and variants")
    faults.add_argument("--list-faults", action="store_true",
                        help="print the faults with the rule ids each one breaks, and exit")
    faults.add_argument("--json", action="store_true",
                        help="with --list-faults or --list-variants: as JSON")
    faults.add_argument("--list-variants", action="store_true",
                        help="print the conformant variants with the spec sections that allow "
                             "each, and exit")
    return p


def main(argv: list[str]) -> int:
    from conformance.client import BrokerURL
    from conformance.sim.faults import FaultError
    from conformance.sim.process import list_faults, run
    from conformance.sim.variants import VariantError, list_variants
    from conformance.topics import TopicError, UnitAddress

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.list_faults:
        print(list_faults(args.json))
        return 0
    if args.list_variants:
        print(list_variants(args.json))
        return 0
    if args.count < 1:
        parser.error(f"--count {args.count}: at least 1")
    if args.tst_operator and not args.tst:
        parser.error("--tst-operator needs --tst")
    try:
        address = UnitAddress.parse(args.unit)
        operator = UnitAddress.parse(args.tst_operator) if args.tst_operator else None
    except TopicError as e:
        parser.error(str(e))
    text = args.broker
    if text is None:
        try:
            env = BrokerURL.from_env()
        except ValueError as e:  # WARAPS_BROKER, WARAPS_PORT: said masked, one line
            parser.error(str(e))
        text = str(env) if env is not None else "embedded"
    broker = None  # embedded: run() starts one
    if text != "embedded":
        try:
            broker = opts.with_tls(BrokerURL.parse(text), args)
        except ValueError as e:
            parser.error(str(e))
    try:
        return run(address, broker, count=args.count, rate=args.rate, faults=args.fault,
                   variants=args.variant,
                   seed=args.seed, tst=args.tst, tst_operator=operator,
                   task_seconds=args.task_seconds)
    except (FaultError, VariantError) as e:
        parser.error(str(e))

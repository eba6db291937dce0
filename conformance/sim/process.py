"""The reference unit (or a fleet of them) as a process, with faults: what
``waraps-conformance sim`` runs (its command line: ``conformance.cli.sim``).

    waraps-conformance sim --unit waraps/unit/air/simulation/dji0 --broker mqtt://127.0.0.1:1883
    waraps-conformance sim --broker embedded --count 500 --fault heartbeat-rate-drift@3
    waraps-conformance sim --list-faults
    waraps-conformance sim --variant strict --variant slow      # conformant, but different
    waraps-conformance sim --tst --tst-operator waraps/unit/ground/real/op0 --count 3

When ready it prints one line, ``ready pid=... broker=... unit=...`` (with ``--broker
embedded`` the broker's URL comes first, on a line of its own), then runs until SIGINT or
SIGTERM. SIGHUP reboots every unit (so a certifier can pass ``--reboot-cmd "kill -HUP
<pid>"``); lines on stdin control it too: ``reboot``, ``reboot NAME``, ``stop``.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from conformance.client import BrokerError, BrokerURL
from conformance.display import shown as shown_line
from conformance.sim.faults import FAULTS, NOT_UNIT_BREAKABLE, FaultError, check_names
from conformance.sim.fleet import Fleet, SimUnit
from conformance.sim.variants import VariantError, check_variants
from conformance.topics import UnitAddress

if TYPE_CHECKING:
    from conformance.broker import EmbeddedBroker

EXIT_UNREACHABLE = 3
"""The broker could not be reached: the status ``lint``, ``record`` and ``profile`` give it."""


def list_faults(as_json: bool) -> str:
    if as_json:
        return json.dumps({
            "faults": [{"name": f.name, "rules": list(f.rules), "scope": f.scope,
                        "active": f.active, "description": f.description}
                       for f in FAULTS.values()],
            "not_unit_breakable": NOT_UNIT_BREAKABLE,
        }, indent=2)
    width = max(map(len, FAULTS))
    lines = [f"{'fault':<{width}}  the rules it fails, and those it only warns (a decided rule, "
             f"unless --strict-rules) / what it does", ""]
    for f in FAULTS.values():
        scope = "  [only visible to a broker-wide observer]" if f.scope == "broker" else ""
        lines.append(f"{f.name:<{width}}  {rules_broken(f.rules, f.decided)}{scope}")
        lines.append(f"{'':<{width}}    {f.description}")
    lines += ["", "Rules no unit can break (no fault):"]
    lines += [f"  {rule}: {why}" for rule, why in NOT_UNIT_BREAKABLE.items()]
    return "\n".join(lines)


def rules_broken(rules: Sequence[str], decided: Sequence[str] = ()) -> str:
    """``fails TOPIC-002 SI-001; warns HB-010``: what the judge makes of each rule a fault
    breaks, by the catalogue's severity and basis (``judge.violation_verdict``); ``decided``:
    rules it breaks only through a decided condition (they warn)."""
    from conformance.judge import violation_verdict
    from conformance.rules import CATALOGUE
    from conformance.violation import Verdict

    fails = [r for r in rules if r in CATALOGUE and violation_verdict(
        CATALOGUE[r], CATALOGUE[r].severity, strict=False) is Verdict.FAIL and r not in decided]
    warns = [r for r in rules if r not in fails]
    return "; ".join(f"{word} {' '.join(found)}" for word, found in (("fails", fails),
                                                                      ("warns", warns)) if found)


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


def _switches(faults: Sequence[str], variants: frozenset[str] | set[str], tst: bool,
              tst_operator: UnitAddress | None) -> str:
    """The ready line's faults, variants and TST level, as the command line gave them."""
    shown = ",".join(faults) or "none"
    if variants:
        shown += f" variants={','.join(sorted(variants))}"
    tst_shown = f" tst=on{f' operator={tst_operator}' if tst_operator else ''}" if tst else ""
    return f"faults={shown}{tst_shown}"


def _embedded_broker() -> tuple[EmbeddedBroker, BrokerURL]:
    """An embedded broker started here, its URL printed first (the caller stops it)."""
    from conformance.broker import EmbeddedBroker  # amqtt loads only when it is needed

    embedded = EmbeddedBroker().start()
    print(embedded.url, flush=True)
    return embedded, BrokerURL.parse(embedded.url)


def run(address: UnitAddress, broker: BrokerURL | None, *, count: int = 1, rate: float = 1.0,
        faults: Sequence[str] = (), variants: Sequence[str] = (), seed: int | None = None, tst: bool = False,
        tst_operator: UnitAddress | None = None, task_seconds: float = 3.0) -> int:
    """Run ``count`` reference units from ``address`` on ``broker`` (None: an embedded broker
    started here, its URL printed first) until SIGINT, SIGTERM or ``stop`` on stdin; print
    the ready line once they are up. ``faults`` are ``NAME`` or ``NAME@I,J`` (FaultError);
    ``variants`` apply to every unit (VariantError).
    Returns 0, or 1 when the units could not start."""
    common, by_index = parse_faults(faults, count)
    variant_names = check_variants(list(variants))
    if broker is None and "mqtt5-qos1" in variant_names:
        raise VariantError("variant mqtt5-qos1 needs a broker that speaks MQTT 5: the "
                           "embedded amqtt broker refuses it (pass --broker mqtt://HOST:PORT)")
    embedded = None
    if broker is None:
        embedded, broker = _embedded_broker()

    runner: SimUnit | Fleet
    if count == 1:
        runner = SimUnit(address, broker, faults=common | by_index.get(0, set()),
                         variants=variant_names, rate=rate, seed=seed, task_seconds=task_seconds,
                         tst_execution=tst, tst_operator=tst_operator)
        units = f"unit={runner.base} agent-uuid={runner.agent_uuid}"
    else:
        runner = Fleet(address, broker, count, faults=common, faults_by_index=by_index,
                       variants=variant_names, rate=rate, seed=seed, task_seconds=task_seconds,
                       tst_execution=tst, tst_operator=tst_operator)
        units = (f"units={runner.addresses[0]}..{runner.addresses[-1].name} "
                 f"count={count}")
    stop = threading.Event()
    try:
        runner.start(timeout=max(10.0, 3.0 / rate))
    except (BrokerError, TimeoutError) as e:
        print(shown_line(f"waraps-conformance sim: {e}"), file=sys.stderr)
        if embedded is not None:
            embedded.stop()
        return EXIT_UNREACHABLE
    _listen(runner, stop)
    print(shown_line(f"ready pid={os.getpid()} broker={broker} {units} rate={rate:g} "
                     f"{_switches(faults, variant_names, tst, tst_operator)}"), flush=True)
    try:
        while not stop.wait(0.2):
            pass
    finally:
        runner.stop()
        if embedded is not None:
            embedded.stop()
    return 0


def _listen(runner: SimUnit | Fleet, stop: threading.Event) -> None:
    """SIGINT and SIGTERM set ``stop``; SIGHUP reboots the unit (every unit of a fleet); a
    line on stdin stops or reboots (``_read_control``)."""
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


def _read_control(reboot: Callable[[str | None], None], stop: threading.Event) -> None:
    """stdin lines: 'reboot', 'reboot NAME|INDEX', 'stop'. End of input changes nothing."""
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        try:
            if words[0] == "reboot":
                reboot(words[1] if len(words) > 1 else None)
                print(shown_line(f"rebooting {words[1] if len(words) > 1 else 'all'}"),
                      flush=True)
            elif words[0] in ("stop", "quit", "exit"):
                stop.set()
                return
            else:
                print(shown_line(f"unknown control {words[0]!r}: reboot [NAME], stop"),
                      flush=True)
        except (KeyError, IndexError) as e:
            print(shown_line(f"control {line.strip()!r}: {e}"), flush=True)

"""Benchmark: certifying the reference unit at 1 Hz, end to end, conformant and with each fault.

    python bench/bench_certify.py                 # conformant (two setups) + every fault
    python bench/bench_certify.py --jobs 2        # the fault sweep two at a time
    python bench/bench_certify.py --faults no-final-feedback task-uuid-ignored
    python bench/bench_certify.py --rate 5 --no-faults   # a quick look

Every run is a real ``pytest --unit ...`` in a subprocess, started through ``sys.executable``
(so the bench works from an un-activated virtualenv):

- ``embedded``: ``--broker embedded`` (what ``waraps-conformance demo`` does): the embedded
  amqtt broker and the reference unit run inside the pytest process;
- ``separate``: the reference unit and its embedded broker run in a process of their own
  (``python -m conformance.cli sim --broker embedded``), rebooted with
  ``--reboot-cmd 'kill -HUP PID'``; then the pytest process's CPU time is the suite's own;
- the fault sweep: ``embedded`` with one ``--sim-fault`` each (every fault of
  ``conformance.sim.FAULTS``), timed as ratios to the conformant ``embedded`` run of the same
  bench run. With ``--jobs N`` the conformant run goes through the same pool, so the ratios
  compare runs under the same load.

The bound: a 1 Hz unit at timing scale 1 is certified within 90 s whatever single
fault it has. Prints a table and writes bench/results/certify.json. Measures, asserts nothing
(the machine is shared: figures drift 10-30 %).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import psutil

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
UNIT = "waraps/unit/air/simulation/dji0"
BOUND_S = 90.0


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_pytest(args: list[str], cwd: Path) -> dict[str, object]:
    """Run pytest in a subprocess; its wall time, CPU time (exact only when runs do not
    overlap) and outcome line."""
    cpu0, t0 = children_cpu(), time.monotonic()
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-o",
                           "addopts=", "-q", *args], cwd=cwd, capture_output=True, text=True)
    wall, cpu = time.monotonic() - t0, children_cpu() - cpu0
    summary = [line for line in done.stdout.splitlines()
               if re.search(r"\d+ (passed|failed)|no tests ran", line)]
    return {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
            "cpu_share": round(cpu / wall, 3) if wall else None, "exit": done.returncode,
            "outcome": summary[-1].strip("= ") if summary else done.stdout[-300:]}


def embedded(rate: float, cwd: Path, fault: str | None = None) -> dict[str, object]:
    reports = cwd / "reports" / (fault or "conformant")
    args = ["--unit", UNIT, "--broker", "embedded", f"--reports-dir={reports}", "--seed", "1"]
    if rate != 1.0:
        args += ["--sim-rate", str(rate)]
    if fault:
        args.append(f"--sim-fault={fault}")
    return {"setup": "embedded", "fault": fault or "", **run_pytest(args, cwd)}


def separate(rate: float, cwd: Path) -> dict[str, object]:
    sim = subprocess.Popen([sys.executable, "-m", "conformance.cli", "sim", "--unit", UNIT,
                            "--broker", "embedded", "--rate", str(rate)],
                           stdout=subprocess.PIPE, text=True)
    try:
        assert sim.stdout is not None
        url = ""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            line = sim.stdout.readline()
            if line.startswith("ready "):
                url = dict(kv.split("=", 1) for kv in line.split()[1:] if "=" in kv)["broker"]
                break
        if not url:
            raise RuntimeError("the reference unit did not report ready within 30 s")
        proc = psutil.Process(sim.pid)
        sim_cpu0 = sum(proc.cpu_times()[:2])
        result = run_pytest(["--unit", UNIT, "--broker", url, "--reboot-cmd",
                             f"kill -HUP {sim.pid}", f"--reports-dir={cwd / 'reports'}",
                             "--seed", "1"], cwd)
        sim_cpu = sum(proc.cpu_times()[:2]) - sim_cpu0
        return {"setup": "separate", "fault": "", **result,
                "unit_and_broker_cpu_s": round(sim_cpu, 2),
                "unit_and_broker_cpu_share": round(sim_cpu / float(result["wall_s"]), 3)}
    finally:
        sim.send_signal(signal.SIGINT)
        try:
            sim.wait(10)
        except subprocess.TimeoutExpired:
            sim.kill()


def sweep(rate: float, cwd: Path, faults: list[str], jobs: int
          ) -> tuple[dict[str, object], list[dict[str, object]]]:
    """The conformant embedded run and one run per fault, ``jobs`` at a time."""
    names: list[str | None] = [None, *faults]
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        rows = []
        for row in pool.map(lambda f: embedded(rate, cwd, f), names):
            print(f"  {row['fault'] or 'conformant'}: {row['wall_s']} s (exit {row['exit']})",
                  flush=True)
            rows.append(row)
    return rows[0], rows[1:]


def summarise(conformant: dict[str, object], faults: list[dict[str, object]]
              ) -> dict[str, object]:
    base = float(conformant["wall_s"])  # type: ignore[arg-type]
    if not faults:
        return {"conformant_s": base}
    walls = sorted((float(r["wall_s"]), str(r["fault"])) for r in faults)  # type: ignore[arg-type]
    worst_s, worst = walls[-1]
    median_s = statistics.median(w for w, _ in walls)
    return {"conformant_s": base, "faults": len(walls),
            "median_s": round(median_s, 2), "median_ratio": round(median_s / base, 2),
            "worst_s": worst_s, "worst_ratio": round(worst_s / base, 2), "worst_fault": worst,
            "over_bound": [f for w, f in walls if w > BOUND_S]}


def main(argv: list[str]) -> int:
    from conformance.sim import FAULTS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=float, default=1.0, help="the reference unit's rate in Hz")
    p.add_argument("--jobs", type=int, default=1, help="fault runs at a time (default 1)")
    p.add_argument("--faults", nargs="*", default=None,
                   help="only these faults (default: every fault of the reference unit)")
    p.add_argument("--no-faults", action="store_true", help="the conformant runs only")
    p.add_argument("--no-separate", action="store_true",
                   help="leave out the separate-process setup")
    args = p.parse_args(argv)
    faults = [] if args.no_faults else sorted(args.faults if args.faults is not None else FAULTS)
    unknown = sorted(set(faults) - set(FAULTS))
    if unknown:
        p.error(f"unknown faults: {', '.join(unknown)}")
    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as tmp:
        conformant, fault_rows = sweep(args.rate, Path(tmp), faults, max(1, args.jobs))
        rows.append(conformant)
        if not args.no_separate:
            rows.append(separate(args.rate, Path(tmp)))
            print(f"  separate: {rows[-1]['wall_s']} s", flush=True)
    summary = summarise(conformant, fault_rows)
    print(f"\ncertification of the reference unit at {args.rate:g} Hz "
          f"(bound: < {BOUND_S:g} s wall at 1 Hz, whatever single fault)")
    print(f"{'setup':<10} {'wall s':>7} {'suite cpu s':>12} {'cpu share':>10} "
          f"{'unit+broker cpu s':>18} {'exit':>5}  outcome")
    for r in rows:
        print(f"{r['setup']:<10} {r['wall_s']:>7} {r['cpu_s']:>12} {r['cpu_share']:>10} "
              f"{r.get('unit_and_broker_cpu_s', '(in it)')!s:>18} {r['exit']:>5}  {r['outcome']}")
    if fault_rows:
        print(f"\n{len(fault_rows)} faults, each alone ({args.jobs} at a time): "
              f"median {summary['median_s']} s ({summary['median_ratio']}x conformant), "
              f"worst {summary['worst_s']} s ({summary['worst_ratio']}x, "
              f"{summary['worst_fault']}); over {BOUND_S:g} s: "
              f"{', '.join(summary['over_bound']) or 'none'}")  # type: ignore[arg-type]
        slowest = sorted(fault_rows, key=lambda r: -float(r["wall_s"]))[:5]  # type: ignore[arg-type]
        for r in slowest:
            print(f"  {r['fault']:<28} {r['wall_s']:>7} s  exit {r['exit']}  {r['outcome']}")
    RESULTS.mkdir(exist_ok=True)
    data = {
        "benchmark": "certify", "rate_hz": args.rate, "jobs": args.jobs, "rows": rows,
        "faults": fault_rows,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_avg_1m": round(os.getloadavg()[0], 2)},
        "summary": summary,
    }
    (RESULTS / "certify.json").write_text(json.dumps(data, indent=2) + "\n")
    print(f"\nwrote {RESULTS / 'certify.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

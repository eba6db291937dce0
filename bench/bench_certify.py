"""Benchmark: certifying the reference unit at 1 Hz, end to end (wall time, CPU share).

    python bench/bench_certify.py            # both setups below, once each
    python bench/bench_certify.py --rate 5   # faster windows (a quick look)

Two setups, each a real ``pytest --unit ...`` in a subprocess:

- ``embedded``: ``--broker embedded`` (what ``waraps-conformance demo`` does): the embedded
  amqtt broker and the reference unit run inside the pytest process;
- ``separate``: the reference unit and its embedded broker run in a process of their own
  (``waraps-conformance sim --broker embedded``), rebooted with ``--reboot-cmd 'kill -HUP PID'``;
  then the pytest process's CPU time is the suite's own.

CPU share = CPU seconds (user + system) / wall seconds of the process. Target: under 60 s of
wall time at 1 Hz. Prints a table and writes bench/results/certify.json. Measures, asserts
nothing (the machine is shared: figures drift 10-30 %).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
UNIT = "waraps/unit/air/simulation/dji0"


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_pytest(args: list[str], cwd: Path) -> dict[str, object]:
    """Run pytest in a subprocess; its wall time, CPU time and outcome line."""
    cpu0, t0 = children_cpu(), time.monotonic()
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-o",
                           "addopts=", "-q", *args], cwd=cwd, capture_output=True, text=True)
    wall, cpu = time.monotonic() - t0, children_cpu() - cpu0
    summary = [line for line in done.stdout.splitlines() if re.search(r"\d+ (passed|failed)",
                                                                       line)]
    return {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
            "cpu_share": round(cpu / wall, 3) if wall else None, "exit": done.returncode,
            "outcome": summary[-1].strip("= ") if summary else done.stdout[-300:]}


def embedded(rate: float, cwd: Path) -> dict[str, object]:
    args = ["--unit", UNIT, "--broker", "embedded", f"--reports-dir={cwd / 'reports'}",
            "--seed", "1"]
    if rate != 1.0:
        args += ["--sim-rate", str(rate)]
    return {"setup": "embedded", **run_pytest(args, cwd)}


def separate(rate: float, cwd: Path) -> dict[str, object]:
    sim = subprocess.Popen(["waraps-conformance", "sim", "--unit", UNIT, "--broker", "embedded",
                            "--rate", str(rate)], stdout=subprocess.PIPE, text=True)
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
        return {"setup": "separate", **result, "unit_and_broker_cpu_s": round(sim_cpu, 2),
                "unit_and_broker_cpu_share": round(sim_cpu / float(result["wall_s"]), 3)}
    finally:
        sim.send_signal(signal.SIGINT)
        try:
            sim.wait(10)
        except subprocess.TimeoutExpired:
            sim.kill()


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=float, default=1.0, help="the reference unit's rate in Hz")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for setup in (embedded, separate):
            rows.append(setup(args.rate, Path(tmp)))
            print(f"  {rows[-1]['setup']}: {rows[-1]['wall_s']} s", flush=True)
    print(f"\ncertification of the reference unit at {args.rate:g} Hz "
          f"(target: < 60 s wall at 1 Hz)")
    print(f"{'setup':<10} {'wall s':>7} {'suite cpu s':>12} {'cpu share':>10} "
          f"{'unit+broker cpu s':>18} {'exit':>5}  outcome")
    for r in rows:
        print(f"{r['setup']:<10} {r['wall_s']:>7} {r['cpu_s']:>12} {r['cpu_share']:>10} "
              f"{r.get('unit_and_broker_cpu_s', '(in it)')!s:>18} {r['exit']:>5}  {r['outcome']}")
    RESULTS.mkdir(exist_ok=True)
    sep = next(r for r in rows if r["setup"] == "separate")
    emb = next(r for r in rows if r["setup"] == "embedded")
    data = {
        "benchmark": "certify", "rate_hz": args.rate, "rows": rows,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_avg_1m": round(os.getloadavg()[0], 2)},
        "summary": {"wall_s_embedded": emb["wall_s"], "wall_s_separate": sep["wall_s"],
                    "suite_cpu_share": sep["cpu_share"], "under_60s": emb["wall_s"] < 60,
                    "exit_embedded": emb["exit"], "exit_separate": sep["exit"]},
    }
    (RESULTS / "certify.json").write_text(json.dumps(data, indent=2) + "\n")
    print(f"\nwrote {RESULTS / 'certify.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

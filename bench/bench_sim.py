"""Benchmark: can the fleet simulator sustain 500 units at 1 Hz on one core?

    python bench/bench_sim.py                       # 500 and 1000 units, 15 s each
    python bench/bench_sim.py --counts 500 --seconds 30

Runs ``waraps-conformance sim --count N --rate 1`` against the local Mosquitto
(127.0.0.1:1883) in a process of its own, counts what arrives with a subscriber in this process
over a measuring window (after every unit has started), and reports:

- the sustained message rate, as a ratio against the ideal rate (units x messages per period:
  heartbeat, sensor_info, direct_execution_info, four sensors, and the camera URL every tenth
  period);
- the simulator's CPU share (CPU seconds per wall second: 1.0 is one core) and memory;
- how regular the heartbeats are (mean and worst interval against the declared period).

Prints a table and writes bench/results/sim.json. Nothing is asserted: benchmarks measure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import psutil

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE.parent))

from conformance.client import BrokerURL, Message, MqttClient  # noqa: E402
from conformance.sim.unit import CAMERA_URL_EVERY  # noqa: E402

MOSQUITTO = "mqtt://127.0.0.1:1883"
PER_PERIOD = 3 + 4 + 1 / CAMERA_URL_EVERY  # info messages, mandatory sensors, camera URL


class Counter:
    """Counts every message, and heartbeat arrival times per unit (topic)."""

    def __init__(self) -> None:
        self.count = 0
        self.counting = False
        self.heartbeats: dict[str, list[float]] = {}
        self.lock = threading.Lock()

    def on_message(self, m: Message) -> None:
        if not self.counting:
            return
        self.count += 1
        if m.topic.endswith("/heartbeat"):
            with self.lock:
                self.heartbeats.setdefault(m.topic, []).append(m.time)


def run(count: int, seconds: float, rate: float) -> dict:
    prefix = f"bench{uuid.uuid4().hex[:8]}"
    counter = Counter()
    sub = MqttClient(BrokerURL.parse(MOSQUITTO), on_message=counter.on_message).connect()
    sub.subscribe(f"{prefix}/#")
    proc = subprocess.Popen(
        [sys.executable, "-m", "conformance.cli", "sim", "--broker", MOSQUITTO, "--unit",
         f"{prefix}/unit/air/simulation/dji0", "--count", str(count), "--rate", str(rate)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=HERE.parent)
    try:
        assert proc.stdout is not None
        started = time.monotonic()
        line = proc.stdout.readline()
        if not line.startswith("ready"):
            raise RuntimeError(f"the simulator did not start: {line!r} "
                               f"{proc.stderr.read() if proc.stderr else ''}")
        startup = time.monotonic() - started
        ps = psutil.Process(proc.pid)
        time.sleep(2.0 / rate)  # warm up: every unit has published a couple of periods
        cpu0, wall0 = sum(ps.cpu_times()[:2]), time.monotonic()
        counter.counting = True
        time.sleep(seconds)  # the measuring window (a benchmark measures durations)
        counter.counting = False
        cpu1, wall1 = sum(ps.cpu_times()[:2]), time.monotonic()
        rss = ps.memory_info().rss / 2**20
    finally:
        proc.terminate()
        proc.wait(15)
        sub.close()
    wall = wall1 - wall0
    ideal = count * rate * PER_PERIOD
    intervals = [b - a for ts in counter.heartbeats.values()
                 for a, b in zip(ts, ts[1:], strict=False)]
    period = 1.0 / rate
    return {
        "units": count, "rate_hz": rate, "window_s": round(wall, 2),
        "startup_s": round(startup, 2),
        "messages": counter.count,
        "messages_per_s": round(counter.count / wall, 1),
        "ideal_per_s": round(ideal, 1),
        "ratio": round(counter.count / wall / ideal, 4),
        "cpu_share": round((cpu1 - cpu0) / wall, 3),
        "cpu_us_per_message": round((cpu1 - cpu0) / max(1, counter.count) * 1e6, 1),
        "rss_mib": round(rss, 1),
        "heartbeat_units_seen": len(counter.heartbeats),
        "heartbeat_mean_interval_periods": round(sum(intervals) / len(intervals) / period, 4)
        if intervals else None,
        "heartbeat_max_interval_periods": round(max(intervals) / period, 3)
        if intervals else None,
        "heartbeat_intervals_over_1_5_periods": sum(i > 1.5 * period for i in intervals),
    }


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--counts", type=int, nargs="+", default=[500, 1000])
    p.add_argument("--seconds", type=float, default=15.0)
    p.add_argument("--rate", type=float, default=1.0)
    args = p.parse_args(argv)
    runs = []
    for count in args.counts:
        print(f"running {count} units at {args.rate:g} Hz for {args.seconds:g} s ...",
              flush=True)
        runs.append(run(count, args.seconds, args.rate))
    results = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_avg_1m": round(os.getloadavg()[0], 2)},
        "parameters": {"counts": args.counts, "seconds": args.seconds, "rate_hz": args.rate,
                       "broker": MOSQUITTO, "messages_per_unit_period": PER_PERIOD},
        "runs": runs,
    }
    main_run = next((r for r in runs if r["units"] == 500), runs[0])
    results["summary"] = {"units": main_run["units"], "ratio": main_run["ratio"],
                          "cpu_share": main_run["cpu_share"],
                          "messages_per_s": main_run["messages_per_s"]}
    header = ("units", "msg/s", "ideal", "ratio", "CPU share", "us/msg", "RSS MiB",
              "HB mean", "HB max", ">1.5 P")
    rows = [(r["units"], r["messages_per_s"], r["ideal_per_s"], r["ratio"], r["cpu_share"],
             r["cpu_us_per_message"], r["rss_mib"], r["heartbeat_mean_interval_periods"],
             r["heartbeat_max_interval_periods"], r["heartbeat_intervals_over_1_5_periods"])
            for r in runs]
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows, strict=False)]
    for row in (header, *rows):
        print("  ".join(str(x).rjust(w) for x, w in zip(row, widths, strict=False)))
    print(f"(load average {results['machine']['load_avg_1m']} on {os.cpu_count()} cores; "
          f"CPU share 1.0 = one core; HB intervals in declared periods)")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "sim.json").write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {RESULTS / 'sim.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

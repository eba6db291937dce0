"""Benchmark: memory stays flat whatever the unit sends, and reports stay bounded.

    python bench/bench_memory.py                       # both parts, 120 s of 5 MiB payloads
    python bench/bench_memory.py --seconds 30          # a shorter, scaled run
    python bench/bench_memory.py --only reports --units 4096
    python bench/bench_memory.py --python /path/to/other/python   # e.g. the code before a change

1. **Certification against a unit publishing 5 MiB payloads at 1 Hz.** The reference unit
   (``waraps-conformance sim``) runs on the local Mosquitto (127.0.0.1:1883) under a prefix of
   its own, a publisher sends a 5 MiB JSON payload to its ``sensor/camera`` once a second, and
   ``pytest --unit ... --observe SECONDS`` certifies it (a real run in a subprocess, started
   with ``--python``: the benchmark compares code by the interpreter it points at). The RSS of
   the pytest process is sampled every second and printed as a curve: flat means the message
   store keeps digests and excerpts, not payloads.
2. **Writing the reports of a fleet.** A RunReport of ``--units`` units (the Monitor fed with
   3 s of each unit's traffic) is written as JSON, HTML and JUnit in a subprocess of
   ``--python``: wall time, peak RSS and the size of each file.

Loopback only; the publisher publishes only under the benchmark's own prefix. Writes
bench/results/memory.json. Measures, asserts nothing (the machine is shared: figures drift).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import psutil

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
BROKER = "mqtt://127.0.0.1:1883"
PAYLOAD_MIB = 5


def _publisher(topic: str, stop: threading.Event, sent: list[int]) -> None:
    """A 5 MiB JSON payload to ``topic`` once a second until ``stop``."""
    import paho.mqtt.client as mqtt

    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bench-{uuid.uuid4()}")
    client.connect("127.0.0.1", 1883)
    client.loop_start()
    deadline = time.monotonic() + 10
    while not client.is_connected() and time.monotonic() < deadline:
        stop.wait(0.05)  # the connection is being made: bounded by the deadline
    image = "A" * (PAYLOAD_MIB << 20)
    try:
        while not stop.is_set():
            payload = json.dumps({"image": image, "stamp": time.time()})
            try:
                client.publish(topic, payload, qos=0).wait_for_publish(10)
            except (RuntimeError, ValueError):
                stop.wait(1.0)  # not connected for a moment: paho reconnects
                continue
            sent[0] += 1
            stop.wait(1.0)
    finally:
        client.loop_stop()
        client.disconnect()


def certification(python: str, seconds: float, cwd: Path) -> dict[str, object]:
    prefix = f"bench{uuid.uuid4().hex[:8]}"
    unit = f"{prefix}/unit/air/simulation/dji0"
    sim = subprocess.Popen([python, "-m", "conformance.cli", "sim", "--unit", unit,
                            "--broker", BROKER], stdout=subprocess.PIPE, text=True, cwd=cwd)
    stop, sent = threading.Event(), [0]
    publisher = threading.Thread(target=_publisher, args=(f"{unit}/sensor/camera", stop, sent),
                                 daemon=True)
    curve: list[tuple[float, float]] = []
    try:
        assert sim.stdout is not None
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not sim.stdout.readline().startswith("ready"):
            pass
        publisher.start()
        t0 = time.monotonic()
        run = subprocess.Popen(
            [python, "-m", "pytest", "-p", "no:cacheprovider", "-o", "addopts=", "-q",
             "--unit", unit, "--broker", BROKER, "--observe", f"{seconds:g}", "--seed", "1",
             f"--reports-dir={cwd / 'reports'}"],
            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        proc = psutil.Process(run.pid)
        while run.poll() is None:
            try:
                rss = proc.memory_info().rss
            except psutil.NoSuchProcess:
                break
            if rss:  # 0: the process is exiting
                curve.append((time.monotonic() - t0, rss / 2**20))
            time.sleep(1.0)  # sampling once a second: a benchmark, not a test
        out = run.communicate()[0]
        wall = time.monotonic() - t0
    finally:
        stop.set()
        publisher.join(15)
        sim.send_signal(signal.SIGINT)
        try:
            sim.wait(10)
        except subprocess.TimeoutExpired:
            sim.kill()
    outcome = [ln for ln in out.splitlines() if " passed" in ln or " failed" in ln]
    rss = [r for _, r in curve]
    late = [r for t, r in curve if t >= wall / 3]  # after the start-up (imports, schemas)
    return {"python": python, "seconds_observed": seconds, "wall_s": round(wall, 1),
            "payloads_sent": sent[0], "payload_mib": PAYLOAD_MIB,
            "rss_start_mib": round(rss[0], 1) if rss else None,
            "rss_peak_mib": round(max(rss), 1) if rss else None,
            "rss_growth_after_first_third_mib": round(max(late) - min(late), 1) if late else None,
            "outcome": outcome[-1].strip("= ") if outcome else out[-300:],
            "curve": [(round(t, 1), round(r, 1)) for t, r in curve]}


REPORTS_CHILD = r"""
import sys, time, threading, psutil
sys.path[:0] = [sys.argv[3], sys.argv[3] + "/lint"]
from lint_helpers import unit_traffic
from conformance.checks import Monitor
from conformance.profile import Profile
from conformance.reporting import write_all
n = int(sys.argv[1])
m = Monitor(Profile(), kind="lint")
msgs = []
for i in range(n):
    msgs += unit_traffic("waraps", f"u{i}", seconds=3)
msgs.sort(key=lambda x: x.time)
for x in msgs:
    m.feed(x)
m.finish(msgs[-1].time)
report = m.report()
del msgs
proc = psutil.Process()
base = peak = proc.memory_info().rss
done = threading.Event()
def watch():
    global peak
    while not done.wait(0.05):
        peak = max(peak, proc.memory_info().rss)
threading.Thread(target=watch, daemon=True).start()
t = time.perf_counter()
paths = write_all(report, sys.argv[2], "fleet", junit=True)
wall = time.perf_counter() - t
done.set()
peak = max(peak, proc.memory_info().rss)
print(f"{wall:.2f} {base / 2**20:.1f} {peak / 2**20:.1f} " + " ".join(
    f"{k}={p.stat().st_size}" for k, p in sorted(paths.items())))
"""


def reports(python: str, units: int, cwd: Path) -> dict[str, object]:
    done = subprocess.run([python, "-c", REPORTS_CHILD, str(units), str(cwd / "fleet"),
                           str(HERE.parent / "tests")], capture_output=True, text=True,
                          cwd=cwd, timeout=3600)
    if done.returncode != 0:
        return {"python": python, "units": units, "error": done.stderr[-1000:]}
    wall, base, peak, *sizes = done.stdout.split()
    return {"python": python, "units": units, "write_s": float(wall),
            "rss_before_mib": float(base), "rss_peak_mib": float(peak),
            "files_mb": {k: round(int(v) / 1e6, 2) for k, v in (s.split("=") for s in sizes)}}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=120.0,
                        help="seconds the certification observes the unit (default 120)")
    parser.add_argument("--units", type=int, default=4096, help="units in the fleet report")
    parser.add_argument("--only", choices=("certification", "reports"))
    parser.add_argument("--python", default=sys.executable,
                        help="the interpreter whose conformance package is measured")
    args = parser.parse_args()
    results: dict[str, object] = {"python": args.python}
    with tempfile.TemporaryDirectory() as tmp:
        cwd = Path(tmp)
        if args.only in (None, "certification"):
            c = certification(args.python, args.seconds, cwd)
            results["certification"] = c
            print(f"certification, {PAYLOAD_MIB} MiB payloads at 1 Hz, --observe "
                  f"{args.seconds:g}: {c['payloads_sent']} payloads in {c['wall_s']} s, "
                  f"{c['outcome']}")
            print(f"  RSS MiB: start {c['rss_start_mib']}, peak {c['rss_peak_mib']}, growth "
                  f"after the first third {c['rss_growth_after_first_third_mib']}")
            curve = c["curve"]
            assert isinstance(curve, list)
            step = max(1, len(curve) // 24)
            print("  curve (s: MiB): " + ", ".join(f"{t:.0f}: {r:.0f}" for t, r in curve[::step]))
        if args.only in (None, "reports"):
            r = reports(args.python, args.units, cwd)
            results["reports"] = r
            if "error" in r:
                print(f"reports of {args.units} units: failed: {r['error']}")
            else:
                print(f"reports of {args.units} units: {r['write_s']} s, RSS before "
                      f"{r['rss_before_mib']} MiB, peak {r['rss_peak_mib']} MiB; files (MB) "
                      f"{r['files_mb']}")
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / "memory.json"
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"written {out.relative_to(HERE.parent)}" if out.is_relative_to(HERE.parent)
          else f"written {out}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main())

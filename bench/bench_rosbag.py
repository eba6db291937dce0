"""Benchmark of ``waraps-conformance lint --from BAG``: messages per second linted from a ROS bag.

    python bench/bench_rosbag.py             # 50 units, 10 minutes (about 150k messages)
    python bench/bench_rosbag.py --quick     # 5 units, 2 minutes: a smoke test

A fleet of ROS units (heartbeat, sensor_info and direct_execution_info as TopicMsg on
/heartbeat_info, spec 4; position GeoPoint and speed, heading, course Float32 under
/UNIT/sensor/, spec 7; at the rates of bench_lint.py's mix) is written with ``rosbags`` into a
temporary ROS 1 bag and ROS 2 bags (sqlite3 and MCAP), never committed. In a child process each
(one thread), per bag: the same-run baseline, ``rosbags`` merely reading and deserializing
every message of the bag (types from the bag's own definitions, as its ``AnyReader`` does); the
bag reader alone (``conformance.rosbag``: deserialize and map to JSON API messages); and the
full lint (bag reader + validator + Monitor + report). Messages per second each, and the full
lint as a ratio to the baseline, medians over the repetitions.

Prints a table and writes bench/results/rosbag.json. Nothing is asserted: benchmarks measure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
T0 = 1_763_700_000.0
TOPIC_MSG = "lrs_msgs_common/msg/TopicMsg"
GEOPOINT = "geographic_msgs/msg/GeoPoint"
FLOAT32 = "std_msgs/msg/Float32"
SPEC_TYPES = {TOPIC_MSG: "string topic\nstring msg\n",
              GEOPOINT: "float64 latitude\nfloat64 longitude\nfloat64 altitude\n"}
MIX = {"heartbeat": 1.0, "sensor/position": 1.0, "sensor/speed": 1.0, "sensor/heading": 0.5,
       "sensor/course": 0.5, "sensor_info": 0.2, "direct_execution_info": 0.2}
"""Messages per second of each kind, per unit (bench_lint.py's mix)."""
FORMATS = ("rosbag1", "rosbag2-sqlite3", "rosbag2-mcap")


# --- a fleet's bag ---------------------------------------------------------------------------------

def write_fleet_bag(path: Path, fmt: str, units: int, seconds: int) -> int:
    """Write the fleet's bag in format ``fmt`` to ``path``; the message count."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ros2 = fmt != "rosbag1"
    store = get_typestore(Stores.LATEST if ros2 else Stores.ROS1_NOETIC)
    types: dict = {}
    for name, text in SPEC_TYPES.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    serialize = store.serialize_cdr if ros2 else store.serialize_ros1
    topic_msg, geopoint, float32 = (store.types[t] for t in (TOPIC_MSG, GEOPOINT, FLOAT32))
    if ros2:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if fmt.endswith("mcap") else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=plugin)
    else:
        from rosbags.rosbag1 import Writer  # type: ignore[assignment]

        writer = Writer(path)  # type: ignore[call-arg]
    periods = {k: round(1.0 / r) for k, r in MIX.items()}
    count = 0
    with writer:
        hb_conn = writer.add_connection("/heartbeat_info", TOPIC_MSG, typestore=store)
        conns = {}
        for i in range(units):
            for kind in MIX:
                if kind.startswith("sensor/"):
                    conns[i, kind] = writer.add_connection(
                        f"/unit{i}/{kind}", GEOPOINT if kind == "sensor/position" else FLOAT32,
                        typestore=store)
        names = [(f"waraps/unit/{('air', 'surface', 'ground')[i % 3]}/real/unit{i}",
                  ("air", "surface", "ground")[i % 3], str(uuid.UUID(int=i + 1, version=4)))
                 for i in range(units)]
        for s in range(seconds):
            for i, (base, agent_type, uid) in enumerate(names):
                t = T0 + s + (i * 0.6180339887) % 1.0
                kinds = [k for k, every in periods.items() if s % every == 0]
                for k, kind in enumerate(kinds):
                    tk = int((t + k * 0.002) * 1e9)
                    if kind.startswith("sensor/"):
                        if kind == "sensor/position":
                            msg = geopoint(latitude=58.39 + (i % 20) * 1e-3 + s * 1e-6,
                                           longitude=15.56 + (i // 20) * 1e-3, altitude=50.0)
                        else:
                            msg = float32(data=2.0 if kind == "sensor/speed"
                                          else (i * 37 + s * 0.1) % 360.0)
                        writer.write(conns[i, kind], tk, serialize(msg, msg.__msgtype__))
                    else:
                        payload = info_message(kind, f"unit{i}", agent_type, uid, t + k * 0.002)
                        msg = topic_msg(topic=f"{base}/{kind}", msg=json.dumps(payload))
                        writer.write(hb_conn, tk, serialize(msg, TOPIC_MSG))
                    count += 1
    return count


def info_message(kind: str, name: str, agent_type: str, uid: str, t: float) -> dict:
    if kind == "heartbeat":
        return {"agent-type": agent_type, "agent-uuid": uid,
                "levels": ["sensor", "direct execution"], "name": name, "rate": 1.0,
                "stamp": t, "type": "HeartBeat"}
    if kind == "sensor_info":
        return {"name": name, "rate": 0.2, "agent-uuid": uid, "stamp": t, "type": "SensorInfo",
                "sensor-data-provided": ["position", "heading", "course", "speed"]}
    return {"name": name, "rate": 0.2, "agent-uuid": uid, "stamp": t,
            "type": "DirectExecutionInfo", "tasks-executing": [],
            "tasks-available": [{"name": "move-to",
                                 "signals": ["$abort", "$enough", "$pause", "$continue"]}]}


# --- children: one measurement each, in a process of its own -------------------------------------

def child(mode: str, path: str) -> dict:
    """``baseline``: rosbags reads and deserializes every message; ``read``: the bag reader
    maps them to JSON API messages; ``lint``: the full lint (Linter, Monitor, report), as
    ``lint --from BAG`` does it without printing."""
    start = time.perf_counter()
    n = 0
    if mode == "baseline":
        from rosbags.highlevel import AnyReader

        with AnyReader([Path(path)]) as reader:
            deserialize = reader.deserialize
            for conn, _, raw in reader.messages():
                deserialize(raw, conn.msgtype)
                n += 1
    elif mode == "read":
        from conformance.client import Message
        from conformance.rosbag import BagReader

        for item in BagReader(path):
            n += type(item) is Message
    else:  # what 'lint --from BAG' does, without printing
        from conformance.checks import Monitor
        from conformance.client import Message
        from conformance.lint.linter import Linter
        from conformance.profile import Profile
        from conformance.rosbag import BagReader

        profile = Profile()
        monitor = Monitor(profile, kind="lint")
        linter = Linter(monitor, profile)
        for item in BagReader(path):
            if type(item) is Message:
                linter.feed_one(item)
            else:
                linter.record(item.unit, item.rule, item.violation)  # type: ignore[union-attr]
        linter.finish(linter.last_time or T0)
        report = monitor.report()
        n = linter.messages
        failing = sum(1 for u in report.units.values() if u.worst().value == "fail")
        if failing:
            raise SystemExit(f"{failing} units fail: the fleet's bag should be conformant")
    elapsed = time.perf_counter() - start
    return {"mode": mode, "messages": n, "seconds": round(elapsed, 3),
            "per_second": round(n / elapsed)}


def run_child(mode: str, path: Path) -> dict:
    done = subprocess.run([sys.executable, __file__, "--child", mode, str(path)],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--child", nargs=2, metavar=("MODE", "BAG"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(*args.child)))
        return 0
    units, seconds = (5, 120) if args.quick else (50, 600)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-rosbag-") as tmp:
        for fmt in FORMATS:
            path = Path(tmp) / (f"fleet-{fmt}" + (".bag" if fmt == "rosbag1" else ""))
            t0 = time.perf_counter()
            count = write_fleet_bag(path, fmt, units, seconds)
            wrote = time.perf_counter() - t0
            size = sum(f.stat().st_size for f in ([path] if path.is_file()
                                                  else path.iterdir()))
            runs: dict[str, list[dict]] = {"baseline": [], "read": [], "lint": []}
            for _ in range(args.repeat):
                for mode in runs:  # interleaved: the machine's speed drifts alike for all
                    runs[mode].append(run_child(mode, path))
            med = {m: statistics.median(r["per_second"] for r in rs) for m, rs in runs.items()}
            ratios = [lint["per_second"] / base["per_second"]
                      for lint, base in zip(runs["lint"], runs["baseline"], strict=True)]
            rows.append({"format": fmt, "messages": count, "bag_mb": round(size / 2**20, 1),
                         "write_s": round(wrote, 1),
                         "baseline_per_second": round(med["baseline"]),
                         "read_per_second": round(med["read"]),
                         "lint_per_second": round(med["lint"]),
                         "lint_to_baseline": round(statistics.median(ratios), 3),
                         "runs": runs})
            print(f"{fmt}: {count} messages written in {wrote:.1f} s", flush=True)
    print(f"\n{'format':<18}{'messages':>9}{'rosbags msg/s':>15}{'reader msg/s':>14}"
          f"{'lint msg/s':>12}{'lint/rosbags':>14}")
    for r in rows:
        print(f"{r['format']:<18}{r['messages']:>9}{r['baseline_per_second']:>15}"
              f"{r['read_per_second']:>14}{r['lint_per_second']:>12}"
              f"{r['lint_to_baseline']:>14.3f}")
    RESULTS.mkdir(exist_ok=True)
    summary = {f"{r['format']}_lint_to_baseline": r["lint_to_baseline"] for r in rows}
    summary.update({f"{r['format']}_lint_per_second": r["lint_per_second"] for r in rows})
    result = {"summary": summary, "units": units, "seconds": seconds, "repeat": args.repeat,
              "rows": rows, "python": platform.python_version(), "cpus": os.cpu_count(),
              "quick": args.quick}
    (RESULTS / "rosbag.json").write_text(json.dumps(result, indent=1) + "\n")
    print(f"\nwrote {RESULTS / 'rosbag.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""Validation throughput on one core: conformance.validator against plain jsonschema.

    python bench/bench_validate.py [--seconds 1.0] [--rounds 3]

A realistic mix of one unit's traffic (positions, heartbeats, the three info messages, exec
feedback, and a start-task of move-path with six waypoints) is validated end to end by
``Validator.validate(topic, payload, time)`` (topic grammar, orjson, jsonschema-rs compiled
once with ``is_valid`` first, error collection only on failure, content rules), and by a
baseline in the same process: ``json.loads`` plus ``list(Draft202012Validator.iter_errors())``
of the pure-Python ``jsonschema``, each validator built once. A faulty mix (every message
breaks a rule) shows the error path. Prints a table and writes bench/results/validate.json.
Nothing is asserted: benchmarks measure (the target is >= 10x on the mix).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import jsonschema_rs
import orjson

from conformance import schema
from conformance.validator import Validator

RESULTS = Path(__file__).resolve().parent / "results"
UNIT = "waraps/unit/air/simulation/dji0"
NOW = time.time()
U = ["b992552b-90b0-4911-8707-d6f808362bd2", "1c5284da-b803-49d1-8c39-b96ef00603e7",
     "29c24bbf-88f0-4de2-97e9-4bd0d5f6bf23", "49fb88b8-4d4a-4268-a69a-35e620a1a5f4"]


def geo(i: int) -> dict[str, Any]:
    return {"altitude": 40.0, "latitude": 57.7611363 + i * 1e-4,
            "longitude": 16.6805011 - i * 1e-4, "rostype": "GeoPoint"}


MESSAGES: dict[str, tuple[str, Any]] = {
    "heartbeat": ("heartbeat", {
        "agent-type": "air", "agent-uuid": U[0], "levels": ["sensor", "direct execution"],
        "name": "dji0", "rate": 1.0, "stamp": NOW, "type": "HeartBeat"}),
    "sensor_info": ("sensor_info", {
        "agent-uuid": U[0], "name": "dji0", "rate": 1.0, "stamp": NOW, "type": "SensorInfo",
        "sensor-data-provided": ["position", "heading", "course", "speed", "camera_url"]}),
    "direct_execution_info": ("direct_execution_info", {
        "agent-uuid": U[0], "name": "dji0", "rate": 1.0, "stamp": NOW,
        "type": "DirectExecutionInfo",
        "tasks-available": [{"name": n, "signals": ["$abort", "$enough", "$pause", "$continue"]}
                            for n in ("move-to", "move-path", "look-at-position")],
        "tasks-executing": [{"task-name": "move-path", "task-uuid": U[1]}]}),
    "position": ("sensor/position", geo(0)),
    "start-task (move-path, 6 waypoints)": ("exec/command", {
        "com-uuid": U[2], "command": "start-task", "execution-unit": "dji0",
        "sender": "commander", "task-uuid": U[1],
        "task": {"name": "move-path", "params": {"speed": "standard",
                                                 "waypoints": [geo(i) for i in range(6)]}}}),
    "exec feedback": ("exec/feedback", {"agent-uuid": U[0], "com-uuid": U[3],
                                        "status": "running", "task-uuid": U[1]}),
}
# How often each appears in the mix: positions dominate a unit's traffic (sensors at several
# Hz, info messages at 1 Hz, commands and feedback rarely).
MIX_WEIGHTS = {"position": 4, "heartbeat": 2, "sensor_info": 1, "direct_execution_info": 1,
               "start-task (move-path, 6 waypoints)": 1, "exec feedback": 1}


def faulty(name: str, message: Any) -> Any:
    """The same message breaking one rule (the error path)."""
    m = json.loads(json.dumps(message))
    if name == "position":
        m["latitude"] = 91.0
    elif name.startswith("start-task"):
        m["task"]["params"]["waypoints"][2]["latitude"] = "57.76"
    elif name == "exec feedback":
        m.pop("task-uuid")
    else:
        m["rate"] = -1.0
    return m


def timed(fn: Callable[[], Any], seconds: float, rounds: int) -> float:
    """Median seconds per call over ``rounds`` runs of about ``seconds`` each."""
    calls = 1
    while True:  # calibrate
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        elapsed = time.perf_counter() - t0
        if elapsed > 0.05:
            break
        calls *= 4
    per_round = max(1, int(calls * seconds / elapsed))
    samples = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(per_round):
            fn()
        samples.append((time.perf_counter() - t0) / per_round)
    return statistics.median(samples)


def build_baseline(bundled: bool) -> Callable[[str, bytes], list[Any]]:
    """json.loads + jsonschema Draft202012Validator.iter_errors, one validator per schema:
    the schema files with a registry for their $refs, or (``bundled``) copies with every $ref
    inlined, which spares jsonschema the reference lookups. The faster of the two is the
    baseline (conservative)."""
    registry = schema.referencing_registry()
    validators: dict[str, jsonschema.Draft202012Validator] = {}

    def run(kind: str, payload: bytes) -> list[Any]:
        path = schema.schema_path_for_kind(kind)
        assert path is not None
        v = validators.get(path)
        if v is None:
            document = schema.inline_refs(schema.load(path)) if bundled else schema.load(path)
            v = validators[path] = jsonschema.Draft202012Validator(document, registry=registry)
        return list(v.iter_errors(json.loads(payload)))

    return run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="per measurement round")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):  # one core, as the target says
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})

    validator = Validator()
    baselines = {"registry": build_baseline(False), "bundled": build_baseline(True)}
    rows = []
    cases = {}
    for name, (sub, message) in MESSAGES.items():
        for variant, m in (("valid", message), ("faulty", faulty(name, message))):
            topic = f"{UNIT}/{sub}"
            payload = orjson.dumps(m)
            result = validator.validate(topic, payload, NOW)
            assert result.ok == (variant == "valid"), (name, variant, result.violations)
            kind_schema = schema.schema_path_for_kind(sub)
            for baseline in baselines.values():
                errors = baseline(sub, payload)
                assert bool(errors) == (variant == "faulty"), (name, variant, errors)
            cases[(name, variant)] = (topic, payload, sub, kind_schema, m)

    for (name, variant), (topic, payload, sub, kind_schema, m) in cases.items():
        ours = timed(lambda t=topic, p=payload: validator.validate(t, p, NOW), args.seconds,
                     args.rounds)
        bases = {label: timed(lambda b=b, s=sub, p=payload: b(s, p), args.seconds, args.rounds)
                 for label, b in baselines.items()}
        base = min(bases.values())
        rs = schema.compiled(kind_schema)
        raw = timed(lambda rs=rs, m=m: rs.is_valid(m), args.seconds / 2, args.rounds)
        rows.append({"message": name, "variant": variant, "bytes": len(payload),
                     "ours_us": ours * 1e6, "jsonschema_us": base * 1e6,
                     "jsonschema_registry_us": bases["registry"] * 1e6,
                     "jsonschema_bundled_us": bases["bundled"] * 1e6,
                     "jsonschema_rs_is_valid_us": raw * 1e6, "ratio": base / ours})

    def mix(variant: str) -> dict[str, float]:
        total = sum(MIX_WEIGHTS.values())
        ours = sum(MIX_WEIGHTS[r["message"]] * r["ours_us"] for r in rows
                   if r["variant"] == variant) / total
        base = sum(MIX_WEIGHTS[r["message"]] * r["jsonschema_us"] for r in rows
                   if r["variant"] == variant) / total
        return {"ours_msgs_per_s": 1e6 / ours, "jsonschema_msgs_per_s": 1e6 / base,
                "ratio": base / ours}

    valid_mix, faulty_mix = mix("valid"), mix("faulty")
    print(f"{'message':<38}{'variant':<8}{'bytes':>6}{'ours us':>10}{'jsonschema us':>15}"
          f"{'rs is_valid us':>16}{'ratio':>8}")
    for r in rows:
        print(f"{r['message']:<38}{r['variant']:<8}{r['bytes']:>6}{r['ours_us']:>10.1f}"
              f"{r['jsonschema_us']:>15.1f}{r['jsonschema_rs_is_valid_us']:>16.2f}"
              f"{r['ratio']:>7.1f}x")
    weights = ", ".join(f"{k} x{v}" for k, v in MIX_WEIGHTS.items())
    print(f"\nmix ({weights}), one core:")
    for label, m in (("valid", valid_mix), ("faulty", faulty_mix)):
        print(f"  {label:<7} ours {m['ours_msgs_per_s']:>9.0f} msg/s   jsonschema "
              f"{m['jsonschema_msgs_per_s']:>7.0f} msg/s   ratio {m['ratio']:.1f}x"
              + ("   (target >= 10x)" if label == "valid" else ""))

    RESULTS.mkdir(exist_ok=True)
    out = {
        "benchmark": "validate",
        "summary": {"mix_ratio": round(valid_mix["ratio"], 1),
                    "mix_msgs_per_s": round(valid_mix["ours_msgs_per_s"]),
                    "baseline_msgs_per_s": round(valid_mix["jsonschema_msgs_per_s"]),
                    "faulty_mix_ratio": round(faulty_mix["ratio"], 1),
                    "target_ratio": 10, "meets_target": valid_mix["ratio"] >= 10},
        "mix_weights": MIX_WEIGHTS, "mix": valid_mix, "faulty_mix": faulty_mix, "rows": rows,
        "environment": {"python": platform.python_version(), "machine": platform.machine(),
                        "cpus": os.cpu_count(), "jsonschema_rs": jsonschema_rs.__name__,
                        "schemas_hash": schema.schemas_hash(),
                        "when": time.strftime("%Y-%m-%dT%H:%M:%S%z")},
    }
    (RESULTS / "validate.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"\nwrote {RESULTS / 'validate.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

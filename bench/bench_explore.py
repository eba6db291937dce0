"""Benchmark: exploration against the 1 Hz reference unit.

    python bench/bench_explore.py                  # N=10 seeds, every sequence fault
    python bench/bench_explore.py --seeds 3 --jobs 6 --faults pause-pauses-all
    python bench/bench_explore.py --order random    # without the model's guidance

Every run is a real ``pytest --unit ... --broker embedded -k test_explore`` in a subprocess
(only the exploration runs: it starts from the unit's own state, as after the scripted
scenarios), with ``--explore`` the default budget at 1 Hz (50 s) unless ``--budget``:

- conformant: steps per minute (the report's ``explore`` summary), and that nothing is found;
- each sequence fault of ``conformance.sim.faults`` (``SEQUENCE_FAULTS``), over ``--seeds``
  seeds: how often it is found within the budget, how often by its own rule, the median time
  and number of steps until the first failing example, the median length of the story
  reported, and how many were shrunk to the end within the budget.

Prints a table and writes bench/results/explore-ORDER.json. Measures, asserts nothing (the
machine is shared: figures drift). ``--jobs`` runs that many at once (they mostly wait on the unit).
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
UNIT = "waraps/unit/air/simulation/dji0"
SUMMARY = re.compile(r"(\d+) examples?, (\d+) steps? in (\d+) s")


def run(fault: str | None, seed: int, budget: str, rate: float, order: str = "model",
        extra: tuple[str, ...] = ()) -> dict[str, object]:
    """One exploration in a subprocess: its wall time, exit status, and what it found."""
    with tempfile.TemporaryDirectory() as tmp:
        reports = Path(tmp) / "reports"
        args = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "no:xdist",
                "-o", "addopts=", "-q", "--unit", UNIT, "--broker", "embedded",
                f"--sim-rate={rate:g}", f"--seed={seed}", f"--explore={budget}",
                f"--reports-dir={reports}", f"--explore-order={order}", "-k", "test_explore"]
        args += extra
        if fault:
            args.append(f"--sim-fault={fault}")
        t0 = time.monotonic()
        done = subprocess.run(args, cwd=tmp, capture_output=True, text=True, timeout=600)
        wall = time.monotonic() - t0
        out: dict[str, object] = {"fault": fault, "seed": seed, "exit": done.returncode,
                                  "wall_s": round(wall, 1)}
        reports_json = sorted(p for p in reports.glob("*.json")
                              if not p.name.endswith("-explore.json"))
        if reports_json:
            meta = json.loads(reports_json[-1].read_text())["meta"]
            m = SUMMARY.search(meta.get("explore", ""))
            if m:
                out.update(examples=int(m[1]), steps=int(m[2]), explore_s=int(m[3]))
        story = next(iter(reports.glob("*-explore.json")), None)
        if story is not None:
            data = json.loads(story.read_text())
            out.update(found=True, rules=data["rules"], length=data["length"],
                       shrunk=data["shrunk"], found_after_s=data["found_after_s"],
                       found_steps=data["found_steps"], first_length=data["first_length"])
        else:
            out["found"] = False
        return out


def median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def main() -> int:
    from conformance.sim.faults import FAULTS, SEQUENCE_FAULTS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds per fault (issue: 10)")
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--faults", nargs="*", default=sorted(SEQUENCE_FAULTS))
    ap.add_argument("--budget", default="50s", help="--explore of each run (default 50s)")
    ap.add_argument("--rate", type=float, default=1.0)
    ap.add_argument("--jobs", type=int, default=4)
    ap.add_argument("--no-conformant", action="store_true")
    ap.add_argument("--conformant-seeds", type=int, default=1,
                    help="seeds of the conformant unit (precision: nothing may be found)")
    ap.add_argument("--variant", action="append", default=[],
                    help="a conformant variant of the reference unit for every run "
                         "(repeatable; sim --list-variants)")
    ap.add_argument("--tst", action="store_true", help="with the TST level (--sim-tst)")
    ap.add_argument("--order", choices=("model", "random"), default="model",
                    help="--explore-order of each run: random measures the search without "
                         "the model's guidance (most telling command first)")
    a = ap.parse_args()
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    jobs: list[tuple[str | None, int]] = [] if a.no_conformant else [
        (None, s) for s in range(a.first_seed, a.first_seed + a.conformant_seeds)]
    jobs += [(f, s) for f in a.faults for s in seeds]
    extra = tuple(f"--sim-variant={v}" for v in a.variant) + (("--sim-tst",) if a.tst else ())
    with ThreadPoolExecutor(a.jobs) as pool:
        runs = list(pool.map(lambda j: run(j[0], j[1], a.budget, a.rate, a.order, extra), jobs))
    table: dict[str, dict[str, object]] = {}
    conformant = [r for r in runs if r["fault"] is None]
    if conformant:
        per_min = [60 * r.get("steps", 0) / max(1, r.get("explore_s", 1))  # type: ignore
                   for r in conformant]
        table["conformant"] = {
            "steps_per_minute": round(median(per_min) or 0), "runs": len(conformant),
            "found": sum(bool(r["found"]) for r in conformant),
            "found_seeds": [r["seed"] for r in conformant if r["found"]],
            "examples": median([r.get("examples", 0) for r in conformant]),  # type: ignore
            "wall_s": median([r["wall_s"] for r in conformant])}  # type: ignore
    for r in runs:
        if r["fault"] is None:
            continue
        row = table.setdefault(str(r["fault"]), {"runs": 0, "found": 0, "own": 0, "shrunk": 0,
                                                 "after": [], "steps": [], "length": [],
                                                 "rules": set()})
        row["runs"] += 1  # type: ignore[operator]
        if r["found"]:
            row["found"] += 1  # type: ignore[operator]
            own = set(FAULTS[str(r["fault"])].rules) & set(r["rules"])  # type: ignore[arg-type]
            row["own"] += bool(own)  # type: ignore[operator]
            row["shrunk"] += bool(r["shrunk"])  # type: ignore[operator]
            row["after"].append(r["found_after_s"])  # type: ignore[union-attr]
            row["steps"].append(r["found_steps"])  # type: ignore[union-attr]
            row["length"].append(r["length"])  # type: ignore[union-attr]
            row["rules"].update(r["rules"])  # type: ignore[union-attr]
    print(f"exploration at {a.rate:g} Hz, budget {a.budget}, seeds {seeds.start}.."
          f"{seeds.stop - 1}, order {a.order}"
          + "".join(f", variant {v}" for v in a.variant) + (", TST" if a.tst else ""))
    if "conformant" in table:
        c = table["conformant"]
        print(f"  conformant: {c['steps_per_minute']} steps/min (median of {c['runs']} runs, "
              f"{c['examples']} examples each), found something in {c['found']} of "
              f"{c['runs']}" + (f" (seeds {c['found_seeds']}: false accusations)"
                                if c["found"] else ""))
    print(f"  {'fault':<30} {'found':>7} {'own rule':>8} {'median s':>9} {'med steps':>10} "
          f"{'story':>6} {'shrunk':>7}  rules")
    summary: dict[str, object] = {"rate": a.rate, "budget": a.budget, "seeds": a.seeds,
                                  "order": a.order, "variants": a.variant, "tst": a.tst,
                                  "conformant": table.get("conformant"), "faults": {}}
    for fault in a.faults:
        row = table.get(fault)
        if row is None:
            continue
        after, steps, length = (median(row[k]) for k in ("after", "steps", "length"))  # type: ignore
        print(f"  {fault:<30} {row['found']}/{row['runs']:<5} {row['own']:>8} "
              f"{'-' if after is None else f'{after:.0f}':>9} "
              f"{'-' if steps is None else f'{steps:.0f}':>10} "
              f"{'-' if length is None else f'{length:.0f}':>6} {row['shrunk']:>7}  "
              f"{' '.join(sorted(row['rules']))}")  # type: ignore[arg-type]
        summary["faults"][fault] = {  # type: ignore[index]
            "found": row["found"], "runs": row["runs"], "own_rule": row["own"],
            "shrunk": row["shrunk"], "median_found_after_s": after,
            "median_found_steps": steps, "median_story_length": length,
            "rules": sorted(row["rules"])}  # type: ignore[arg-type]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"explore-{a.order}.json").write_text(json.dumps({"summary": summary, "runs": runs},
                                                     indent=1, default=list))
    return 0


if __name__ == "__main__":
    sys.exit(main())

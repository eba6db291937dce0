"""Benchmark of the hostile corpus: every case of ``tests/lint/hostile.py`` run as
the console script in a subprocess under the same 3 GiB address-space cap as the tests, its wall
time and peak resident memory (the kernel's, wait4); then the slowest case and the largest peak.

    python bench/bench_hostile.py            # the corpus, the 100k-unit fleet, damaged bags
                                             # (and 200 recordings damaged at random)
    python bench/bench_hostile.py --quick    # without the fleet and the bags

The same-run baseline is a clean recording of the same size as the recording cases (each case
is that recording with one hostile line): what a case costs beyond it is the cost of the
hostile input. Inputs are generated into a temporary folder, never committed.

Prints a table and writes bench/results/hostile.json. Nothing is asserted: benchmarks measure
(the tests assert the bounds: ``hostile.MAX_SECONDS``, ``hostile.MAX_PEAK_MB``).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE.parent / "tests" / "lint"))

from hostile import (  # noqa: E402  (tests/lint/hostile.py: the corpus itself)
    ADDRESS_SPACE,
    BAG_DRIVER,
    COMMAND_CASES,
    MUTATION_DRIVER,
    RECORDING_CASES,
    Case,
    Run,
    damaged_bags,
    fleet,
    good_lines,
    run_bounded,
    write_case,
)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="no fleet, no damaged bags")
    args = parser.parse_args(argv)
    runs: list[Run] = []
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        baseline = Case("baseline", b"\n".join(good_lines()) + b"\n")
        for case in [baseline, *RECORDING_CASES, *COMMAND_CASES]:
            folder = tmp / case.name
            folder.mkdir()
            command, stdin = write_case(case, folder)
            runs.append(run_bounded(case.name, command, folder, stdin=stdin))
            _show(runs[-1])
        runs.append(run_bounded("mutations-200", [str(HERE.parent / "tests" / "lint"), "19",
                                                  "200"], tmp, script=MUTATION_DRIVER))
        _show(runs[-1])
        if not args.quick:
            path = fleet(tmp)
            runs.append(run_bounded("fleet-100k-units", ["lint", "--from", str(path),
                                                         "--plain", "--format", "none"], tmp))
            _show(runs[-1])
            for storage in ("ros1", "sqlite3", "mcap"):
                folder = tmp / storage
                folder.mkdir()
                _, copies = damaged_bags(folder, storage, 16)
                runs.append(run_bounded(f"damaged-{storage}-x{len(copies)}",
                                        [str(p) for p in copies], folder, script=BAG_DRIVER))
                _show(runs[-1])
    slowest = max(runs, key=lambda r: r.seconds)
    largest = max(runs, key=lambda r: r.peak_mb)
    base = runs[0]
    crashed = [r.name for r in runs if r.traceback or r.killed]
    summary = {
        "cases": len(runs), "slowest": slowest.name, "slowest_s": round(slowest.seconds, 2),
        "peak_case": largest.name, "peak_mb": round(largest.peak_mb, 1),
        "baseline_s": round(base.seconds, 2), "baseline_mb": round(base.peak_mb, 1),
        "address_space_cap_gib": ADDRESS_SPACE >> 30, "crashed_or_hung": len(crashed),
    }
    print(f"\nslowest: {slowest.name} {slowest.seconds:.2f} s; largest peak: {largest.name} "
          f"{largest.peak_mb:.0f} MB; baseline (clean recording) {base.seconds:.2f} s "
          f"{base.peak_mb:.0f} MB; crashed or hung: {', '.join(crashed) or 'none'}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "hostile.json").write_text(json.dumps({
        "summary": summary, "machine": platform.platform(),
        "runs": [{"name": r.name, "code": r.code, "seconds": round(r.seconds, 3),
                  "peak_mb": round(r.peak_mb, 1)} for r in runs]}, indent=1) + "\n")
    return 0


def _show(run: Run) -> None:
    print(f"{run.name:44} exit {run.code:>2} {run.seconds:7.2f} s {run.peak_mb:7.0f} MB"
          + ("  TRACEBACK" if run.traceback else "") + ("  KILLED" if run.killed else ""),
          flush=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""Run every benchmark under bench/ and print one summary table.

    python bench/run_all.py            # all of them
    python bench/run_all.py validate   # only bench_validate.py

Each bench_*.py measures its target and a baseline in the same run (the machines are shared and
noisy: ratios hold, absolute figures drift), prints its own table and writes
bench/results/<name>.json. Nothing here asserts a figure: benchmarks measure.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


def main(argv: list[str]) -> int:
    wanted = set(argv)
    scripts = sorted(p for p in HERE.glob("bench_*.py")
                     if not wanted or p.stem.removeprefix("bench_") in wanted)
    if not scripts:
        print(f"no benchmark matches {sorted(wanted)}; have: "
              f"{[p.stem.removeprefix('bench_') for p in HERE.glob('bench_*.py')]}")
        return 2
    failed = []
    for script in scripts:
        print(f"\n=== {script.name} ===", flush=True)
        t0 = time.monotonic()
        rc = subprocess.call([sys.executable, str(script)], cwd=HERE.parent)
        print(f"--- {script.name}: exit {rc} in {time.monotonic() - t0:.1f} s", flush=True)
        if rc:
            failed.append(script.name)
    print("\n=== summary (bench/results/*.json) ===")
    for path in sorted(RESULTS.glob("*.json")):
        data = json.loads(path.read_text())
        summary = data.get("summary", data)
        print(f"{path.stem}: " + ", ".join(f"{k}={v}" for k, v in summary.items()
                                            if not isinstance(v, (list, dict))))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

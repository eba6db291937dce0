"""Coverage-guided fuzzing of every input surface: each target of ``fuzz/`` run
under libFuzzer (atheris) for a given time, one at a time, from its seeds
(``python -m fuzz.seeds``) and the corpus earlier runs kept (``fuzz/corpus/TARGET``).

    python bench/bench_fuzz.py                      # every target, 60 s each
    python bench/bench_fuzz.py --seconds 600 rosbag_ros1 recording_mixed
    nice -n 19 python bench/bench_fuzz.py --seconds 600   # the done-when's 10 minutes each

Prints per target: executions, executions per second, coverage (libFuzzer's ``cov:`` edges and
``ft:`` features), corpus size, peak RSS, and the crashes, hangs or broken bounds found (their
inputs are kept in bench/results/fuzz-artifacts/). Writes bench/results/fuzz.json. Nothing is
asserted: benchmarks measure (``tests/fuzz/test_fuzz_targets.py`` fails on a crash).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
sys.path.insert(0, str(ROOT))

from fuzz import TARGETS  # noqa: E402

_STATUS = re.compile(r"^#(\d+)\s+\w+\s+cov: (\d+) ft: (\d+) corp: (\d+)/\S+ .*?exec/s: (\d+)"
                     r"(?: rss: (\d+)Mb)?")
_FINAL = re.compile(r"^stat::(\w+):\s+(\d+)")
_FAILURE = re.compile(r"ERROR: libFuzzer: (\S.*)|^Broken: (.*)|^\w*Error: (.*)")


def run_target(target: str, seconds: int, corpus: Path, artifacts: Path) -> dict[str, object]:
    """One target for ``seconds``; its figures from libFuzzer's own lines."""
    artifacts.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "fuzz", target, f"-max_total_time={seconds}",
           "-print_final_stats=1", f"-artifact_prefix={artifacts}/{target}-", str(corpus)]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, errors="replace",
                          timeout=seconds + 300)
    wall = time.monotonic() - t0
    last: tuple[str, ...] | None = None
    final: dict[str, int] = {}
    failure = ""
    for line in proc.stderr.splitlines():
        m = _STATUS.match(line)
        if m:
            last = m.groups()
        m = _FINAL.match(line)
        if m:
            final[m[1]] = int(m[2])
        m = _FAILURE.search(line)
        if m and not failure and proc.returncode:
            failure = next(g for g in m.groups() if g)[:200]
    runs = final.get("number_of_executed_units", int(last[0]) if last else 0)
    return {"target": target, "seconds": round(wall, 1), "runs": runs,
            "exec_per_s": round(runs / wall, 1) if wall else 0.0,
            "cov": int(last[1]) if last else 0, "ft": int(last[2]) if last else 0,
            "corpus": int(last[3]) if last else 0,
            "peak_rss_mb": final.get("peak_rss_mb", int(last[5] or 0) if last else 0),
            "exit": proc.returncode, "failure": failure}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=int, default=60, help="per target (default 60)")
    parser.add_argument("targets", nargs="*", help=f"default: all of {', '.join(TARGETS)}")
    args = parser.parse_args(argv)
    targets = args.targets or list(TARGETS)
    unknown = [t for t in targets if t not in TARGETS]
    if unknown:
        parser.error(f"unknown targets {unknown}; have {', '.join(TARGETS)}")
    # In a process of its own: a child's peak RSS (libFuzzer's rss, -rss_limit_mb) starts from
    # its parent's at the fork, and writing the bags takes ~200 MB.
    corpus = ROOT / "fuzz" / "corpus"
    subprocess.run([sys.executable, "-m", "fuzz.seeds", str(corpus)], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    corpora = {target: corpus / target for target in targets}
    RESULTS.mkdir(exist_ok=True)
    rows = []
    print(f"{'target':24} {'s':>6} {'runs':>10} {'exec/s':>8} {'cov':>6} {'ft':>7} "
          f"{'corpus':>6} {'rss MB':>6}  result", flush=True)
    for target in targets:
        row = run_target(target, args.seconds, corpora[target], RESULTS / "fuzz-artifacts")
        rows.append(row)
        print(f"{target:24} {row['seconds']:>6} {row['runs']:>10} {row['exec_per_s']:>8} "
              f"{row['cov']:>6} {row['ft']:>7} {row['corpus']:>6} {row['peak_rss_mb']:>6}  "
              f"{'ok' if not row['exit'] else 'FOUND: ' + str(row['failure'])}", flush=True)
    found = [r["target"] for r in rows if r["exit"]]
    summary = {"targets": len(rows), "seconds_each": args.seconds, "found": len(found)}
    out = RESULTS / "fuzz.json"
    previous = json.loads(out.read_text()).get("targets", {}) if out.exists() else {}
    previous.update({r["target"]: r for r in rows})
    out.write_text(json.dumps({"summary": summary, "targets": previous}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

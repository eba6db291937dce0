"""Every fuzz target (``fuzz/``) run briefly under libFuzzer from its seeds: a crash,
a hang past libFuzzer's ``-timeout``, memory past ``-rss_limit_mb`` or a broken bound of the
target's invariant fails the test with the input's path and the end of libFuzzer's output.

Each target runs ``RUNS`` inputs or ``SECONDS`` at most (about 3 s with its start); the long
runs are ``bench/bench_fuzz.py``'s. The crashes found so far are cases of their own (in
``tests/lint/hostile.py``, ``tests/ros``, ``tests/plugin/test_plugin_explore.py``).
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from fuzz import TARGETS  # noqa: E402

RUNS = 300
SECONDS = 1
SURFACES = {
    "recording formats": ("recording_jsonl", "recording_mosquitto_j", "recording_mosquitto_jj",
                          "recording_mosquitto_v", "recording_mixed"),
    "ROS bags": ("rosbag_ros1", "rosbag_sqlite3", "rosbag_mcap", "rosbag_metadata"),
    "profiles": ("profile_loader",), "explore replays": ("explore_replay",),
    "validate": ("validate_input",), "option parsers": ("option_parsers",),
    "the message path": ("message_path",), "the profile drafter's feed": ("profile_draft",),
    "the environment": ("environment",), "the serve address and metrics labels":
    ("serve_address",), "bag decompression": ("bag_inflate",),
}
"""The input surfaces, each with its targets."""
KNOWN_OPEN: dict[str, str] = {}
"""Targets whose findings are owned elsewhere: run, but a finding is an expected failure."""


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("fuzz-seeds")
    subprocess.run([sys.executable, "-m", "fuzz.seeds", str(where)], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL, timeout=120)
    return where


def test_every_surface_has_a_target_stating_its_invariant() -> None:
    assert sorted(t for ts in SURFACES.values() for t in ts) == sorted(TARGETS)
    for target in TARGETS:
        module = importlib.import_module(f"fuzz.{target}")
        assert "Invariant" in (module.__doc__ or ""), target
        assert callable(module.test_one_input) and callable(module.prepare), target


@pytest.mark.parametrize("target", TARGETS)
def test_a_target_runs_briefly_without_a_finding(target: str, seeds: Path,
                                                 tmp_path: Path) -> None:
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    for seed in (seeds / target).iterdir():
        (corpus / seed.name).write_bytes(seed.read_bytes())
    done = subprocess.run(
        [sys.executable, "-m", "fuzz", target, f"-runs={RUNS}", f"-max_total_time={SECONDS}",
         "-seed=1", f"-artifact_prefix={tmp_path}/", str(corpus)],
        cwd=ROOT, capture_output=True, text=True, errors="replace", timeout=120)
    found = sorted(p.name for p in tmp_path.iterdir() if p.name != "corpus")
    if target in KNOWN_OPEN and (done.returncode or found):
        pytest.xfail(KNOWN_OPEN[target])
    assert done.returncode == 0 and not found, (
        f"fuzz/{target}: exit {done.returncode}, kept {found}\n{done.stderr[-3000:]}")
    assert "Done" in done.stderr, done.stderr[-2000:]


REGRESSIONS = Path(__file__).parent / "regressions"
"""Inputs that broke a target's invariant (found by fuzzing or by hand), one folder
per target: each is run once through its target and must now hold."""


@pytest.mark.parametrize("target", sorted(p.name for p in REGRESSIONS.iterdir()))
def test_the_inputs_that_broke_a_target_hold_now(target: str, tmp_path: Path) -> None:
    inputs = sorted(str(p) for p in (REGRESSIONS / target).iterdir())
    done = subprocess.run([sys.executable, "-m", "fuzz", target, f"-artifact_prefix={tmp_path}/",
                           *inputs], cwd=ROOT, capture_output=True, text=True, errors="replace",
                          timeout=120)
    assert done.returncode == 0, f"fuzz/{target}:\n{done.stderr[-3000:]}"
    assert done.stderr.count("Executed ") == len(inputs), done.stderr[-2000:]

"""Coverage-guided fuzz targets (atheris, libFuzzer in-process), one module per input surface.

A top-level package beside ``bench/`` and ``tests/``, not inside ``conformance``: the targets
are shared by the benchmark (``bench/bench_fuzz.py``, long runs) and CI
(``tests/fuzz/test_fuzz_targets.py``, brief runs) and are never shipped or imported by the
tool. Each module states its invariant in its docstring and defines ``test_one_input(data)``,
which raises ``harness.Broken`` (or lets any other exception escape) when the invariant
does not hold: libFuzzer then keeps the input as a crash.

    python -m fuzz TARGET [libFuzzer options] [CORPUS_DIR ...]
    python -m fuzz.seeds            # writes the seed corpora fuzz/corpus/TARGET/
"""

TARGETS = (
    "recording_jsonl", "recording_mosquitto_j", "recording_mosquitto_jj", "recording_mosquitto_v",
    "recording_mixed", "rosbag_ros1", "rosbag_sqlite3", "rosbag_mcap", "rosbag_metadata",
    "profile_loader", "explore_replay", "validate_input", "option_parsers", "message_path",
    "profile_draft", "environment", "serve_address", "bag_inflate",
)
"""Every target, by module name."""

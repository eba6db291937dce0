"""Bad ROS bags: each a clear message (what, where, how to fix) and a non-zero exit, never a
traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from ros_bags import UNIT, Entry, lint_bag, unit_entries, write_bag

from conformance.lint import EXIT_NOT_RUN, EXIT_USAGE
from conformance.rosbag import is_bag


def _storage_file(bag: Path) -> Path:
    return next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))


def test_a_truncated_ros1_bag(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "run.bag", unit_entries())
    bag.write_bytes(bag.read_bytes()[: bag.stat().st_size * 2 // 3])
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN and run.report is None
    assert f"{bag}: cannot read this rosbag1 bag" in run.err
    assert f"Fix: 'rosbag reindex {bag}'" in run.err


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_truncated_ros2_bag(tmp_path: Path, storage: str) -> None:
    bag = write_bag(tmp_path / "run", unit_entries(ros2=True), ros2=True, storage=storage)
    store = _storage_file(bag)
    store.write_bytes(store.read_bytes()[: store.stat().st_size // 2])
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN and run.report is None
    assert f"{bag}: cannot read this rosbag2 ({storage}) bag" in run.err
    assert f"Fix: 'ros2 bag reindex {bag}'" in run.err


def test_a_ros2_bag_cut_off_before_its_metadata(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "run", unit_entries(ros2=True), ros2=True)
    (bag / "metadata.yaml").unlink()
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN
    assert "without metadata.yaml (a recording that was cut off?)" in run.err
    assert f"'ros2 bag reindex {bag}'" in run.err and str(_storage_file(bag)) in run.err
    # The fix it names works: its storage file alone is a bag.
    assert lint_bag(_storage_file(bag), tmp_path / "r2").code == 0


def test_a_bag_without_wara_ps_topics(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "tf.bag", [Entry("/tf_static", "std_msgs/msg/String",
                                                1_763_700_000.0, {"data": "x"})])
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN and run.report is None
    assert f"{bag}: no WARA-PS topic in this bag" in run.err
    assert "it holds /tf_static. Fix: record the unit's topics" in run.err


def test_a_directory_that_is_not_a_bag(tmp_path: Path) -> None:
    folder = tmp_path / "notes"
    folder.mkdir()
    (folder / "readme.txt").write_text("field test 3\n")
    run = lint_bag(folder, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN
    assert f"{folder} is a directory but not a ROS 2 bag (no metadata.yaml" in run.err


def test_a_bag_file_that_is_not_a_bag(tmp_path: Path) -> None:
    fake = tmp_path / "capture.bag"
    fake.write_text('{"ts": 1.0, "topic": "a", "payload": "1"}\n')
    run = lint_bag(fake, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN
    assert f"{fake} is not a ROS 1 bag (it does not start with '#ROSBAG V2.0')" in run.err


def test_sensor_topics_without_a_unit_address_ask_for_ros_unit(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "run.bag", unit_entries(heartbeat_info=False))
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN
    assert "no unit address for the topics of /husky0" in run.err
    assert "Fix: pass --ros-unit PREFIX/unit/TYPE/ROLE/NAME" in run.err
    assert lint_bag(bag, tmp_path / "r2", "--ros-unit", UNIT).code == 0


def test_ros_unit_is_checked(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "run.bag", unit_entries(heartbeat_info=False))
    run = lint_bag(bag, tmp_path / "reports", "--ros-unit", "husky0")
    assert run.code == EXIT_USAGE and "--ros-unit: 'husky0' is not a unit address" in run.err
    jsonl = tmp_path / "run.jsonl"
    jsonl.write_text("")
    run = lint_bag(jsonl, tmp_path / "reports", "--ros-unit", UNIT)
    assert run.code == EXIT_USAGE and "--ros-unit applies to ROS bags only" in run.err


def test_bags_are_told_from_recordings(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "renamed.bin", unit_entries())  # found by its first line
    (tmp_path / "run.jsonl").write_text("{}\n")
    assert is_bag(str(bag)) and is_bag(str(tmp_path)) and is_bag(str(tmp_path / "x.mcap"))
    assert not is_bag(str(tmp_path / "run.jsonl")) and not is_bag("-")


def test_the_console_script_prints_no_traceback(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "run", unit_entries(ros2=True), ros2=True)
    _storage_file(bag).write_bytes(b"not a database" * 100)
    done = subprocess.run([sys.executable, "-m", "conformance.cli", "lint", "--from", str(bag),
                           "--plain", "--format", "none"], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == EXIT_NOT_RUN
    assert "Traceback" not in done.stderr + done.stdout
    assert done.stderr.startswith(f"waraps-conformance lint: {bag}: cannot read this rosbag2")


def test_a_message_its_type_cannot_read_refuses_the_bag(tmp_path: Path) -> None:
    """A damaged container gives no verdict, never 'clean' on what survives."""
    entries = unit_entries()
    entries.append(Entry("/husky0/sensor/speed", "std_msgs/msg/Float32", 1_763_700_005.5,
                         raw=b"\x01"))  # 1 byte where a float32 takes 4
    bag = write_bag(tmp_path / "run.bag", entries)
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN, run.out + run.err
    assert run.err.strip() == (
        f"waraps-conformance lint: {bag}: 1 message(s) could not be deserialized with their "
        f"connection's type (the bag is damaged), so nothing was judged. Fix: record it again")


def test_a_ros1_bag_damaged_in_the_middle(tmp_path: Path) -> None:
    """Its index is whole, so it opens; a message record halfway is overwritten."""
    import re

    bag = write_bag(tmp_path / "run.bag", unit_entries())
    data = bytearray(bag.read_bytes())
    records = [m.start() for m in re.finditer(b"op=\x02", bytes(data))]  # message data records
    at = records[len(records) // 2]
    data[at - 8:at + 12] = b"\xff" * 20
    bag.write_bytes(bytes(data))
    run = lint_bag(bag, tmp_path / "reports")
    assert run.code == EXIT_NOT_RUN and run.report is None
    assert f"{bag}: the bag is damaged after " in run.err
    assert "Fix: reindex it ('rosbag reindex' / 'ros2 bag reindex') or record it again" in run.err

"""What the bag targets share: a small conformant bag of each storage (the tests' own writer,
``tests/ros/ros_bags.py``), the fuzzed bytes put in its place, and the reader's invariant.

The invariant of a bag: ``BagReader`` reads the bag whole or raises
``BagError`` with a one-line message; nothing else escapes. A damaged container gives no
verdict: when any message could not be read (``undecodable``), the bag is refused, never
judged on what survives. Time proportional to the input.
"""

from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from conformance.rosbag import BagError, BagReader
from fuzz.harness import Broken, one_line, within_time

ROS_TESTS = Path(__file__).resolve().parent.parent / "tests" / "ros"
WORK = Path(tempfile.mkdtemp(prefix="fuzz-bags-"))
atexit.register(shutil.rmtree, WORK, True)


def good_bag(storage: str) -> Path:
    """A conformant bag of ``storage`` (ros1, sqlite3, mcap) of 3 s, written once."""
    path = WORK / f"good-{storage}" / ("run.bag" if storage == "ros1" else "run")
    if path.exists():
        return path
    sys.path.insert(0, str(ROS_TESTS))
    from ros_bags import unit_entries, write_bag

    path.parent.mkdir(parents=True, exist_ok=True)
    ros2 = storage != "ros1"
    write_bag(path, unit_entries(seconds=3, ros2=ros2), ros2=ros2, storage=storage)
    return path


def storage_file(bag: Path) -> Path:
    """The file holding a bag's messages (a ROS 2 bag's .db3 or .mcap)."""
    if bag.is_file():
        return bag
    return next(p for p in sorted(bag.iterdir()) if p.suffix in (".db3", ".mcap"))


def copy_of(storage: str) -> Path:
    """A fresh copy of the good bag, to damage."""
    good = good_bag(storage)
    target = WORK / f"fuzz-{storage}"
    shutil.rmtree(target, ignore_errors=True)
    target.mkdir()
    if good.is_file():
        return Path(shutil.copy(good, target / good.name))
    return Path(shutil.copytree(good, target / good.name))


def check(bag: Path, size: int) -> None:
    """Read the bag whole as lint does: refused with one line, or read without a skipped
    message."""
    with within_time(size):
        reader = BagReader(str(bag))
        try:
            for _ in reader:
                pass
        except BagError as e:
            one_line(e, "bag error", shown=True)
            return
    if reader.undecodable:
        raise Broken(f"{reader.undecodable} message(s) could not be deserialized, and the bag "
                     f"was judged on the rest")
    for note in reader.notes:
        one_line(note, "a note", shown=True)


def target(storage: str) -> tuple[Callable[[], None], Callable[[bytes], None]]:
    """``prepare`` and ``test_one_input`` of the target of one storage: the good bag written
    once, then each input in place of its storage file."""

    def prepare() -> None:
        good_bag(storage)

    def test_one_input(data: bytes) -> None:
        bag = copy_of(storage)
        storage_file(bag).write_bytes(data)
        check(bag, len(data))

    return prepare, test_one_input

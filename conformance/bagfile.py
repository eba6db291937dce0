"""Which ROS bag a ``--from SOURCE`` names, and opening it: a ROS 1 ``.bag`` file, a ROS 2 bag
directory (``metadata.yaml``, sqlite3 or MCAP storage) or one ``.db3``/``.mcap`` file. What is
not a bag, or not one rosbags can be trusted with (a FIFO, a directory without metadata.yaml,
a wrong magic, metadata that lies: ``bagmeta.py``), is a ``BagError`` that says how to fix it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from conformance.baginflate import check_sqlite, install
from conformance.bagmeta import check_metadata

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MAX_DIR_ENTRIES = 1000
"""Entries of a ROS 2 bag directory looked at before opening it."""


class BagError(ValueError):
    """A bag that cannot be linted: the message says what, where and how to fix it."""


def is_bag(source: str) -> bool:
    """Whether ``--from SOURCE`` names a ROS bag (or a directory, which only a ROS 2 bag can
    be) rather than a JSON Lines recording."""
    if source == "-":
        return False
    path = Path(source)
    if path.is_dir() or path.suffix in (".bag", ".db3", ".mcap"):
        return True  # BagReader refuses what is not a regular file (a FIFO would block)
    if path.is_file():  # not a FIFO: reading its head must not block
        try:
            with path.open("rb") as f:
                return f.read(len(ROS1_MAGIC)) == ROS1_MAGIC
        except OSError:
            return False
    return False


def is_ros2(path: Path) -> bool:
    """Whether the bag at ``path`` is a ROS 2 bag (a directory, a .db3 or .mcap file)."""
    return not (path.is_file() and path.suffix not in (".db3", ".mcap"))


def bag_format(path: Path) -> str:
    """``rosbag1``, or ``rosbag2 (STORAGE)``: sqlite3 (the default before Iron) or mcap."""
    if not is_ros2(path):
        return "rosbag1"
    files = list(path.iterdir()) if path.is_dir() else [path]
    return f"rosbag2 ({'mcap' if any(p.suffix == '.mcap' for p in files) else 'sqlite3'})"


def open_bag(path: Path) -> Any:
    """The opened rosbags reader of the bag at ``path``; BagError says how to fix what is
    wrong (checked before rosbags is trusted with it)."""
    ros2 = is_ros2(path)
    _check_bag(path, ros2)
    install()  # rosbags inflates with our bounds (baginflate.py)
    try:
        if ros2:
            from rosbags.rosbag2 import Reader as Reader2

            reader: Any = Reader2(path)
        else:
            from rosbags.rosbag1 import Reader as Reader1

            reader = Reader1(path)
        reader.open()
    except Exception as e:  # rosbags raises many kinds on damaged input: say which bag
        hint = (f"'ros2 bag reindex {path.parent if path.is_file() else path}'" if ros2
                else f"'rosbag reindex {path}' (a recording that was cut off has no index)")
        raise BagError(f"{path}: cannot read this {bag_format(path)} bag: {reason(e)}. "
                       f"Fix: {hint}, or record it again") from None
    return reader


def _check_bag(path: Path, ros2: bool) -> None:
    """What is wrong with the bag at ``path`` before rosbags reads it, as a BagError that says
    how to fix it: missing, not a regular file, a ROS 2 directory without metadata.yaml or with
    metadata or a store that cannot be trusted, a file that is no ROS 1 bag."""
    if not path.exists():
        raise BagError(f"{path}: no such file or directory (pass a ROS 1 .bag file, a ROS 2 "
                       f"bag directory holding metadata.yaml, or a JSON Lines recording)")
    for part in ([path] if not path.is_dir() else sorted(path.iterdir())[:MAX_DIR_ENTRIES]):
        if not part.is_dir() and not part.is_file():  # rosbags seeks: a FIFO would block
            raise BagError(f"{part} is not a regular file (a FIFO, a socket or a device), "
                           f"and a bag is read by seeking in it. Fix: copy it to a file "
                           f"first; a recording can be piped into '--from -'")
    if ros2 and path.is_dir() and not (path / "metadata.yaml").is_file():
        stores = sorted(p.name for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
        if stores:
            raise BagError(
                f"{path}: a ROS 2 bag directory without metadata.yaml (a recording that was "
                f"cut off?). Fix: 'ros2 bag reindex {path}', or pass its storage file "
                f"({path / stores[0]})")
        raise BagError(
            f"{path} is a directory but not a ROS 2 bag (no metadata.yaml, no .db3 or .mcap "
            f"file). Pass the directory 'ros2 bag record -o NAME' made, a ROS 1 .bag file, "
            f"or a JSON Lines recording")
    if ros2 and path.is_dir() and (why := check_metadata(path / "metadata.yaml")):
        raise BagError(why)
    if not ros2:
        with path.open("rb") as f:
            head = f.read(len(ROS1_MAGIC))
        if head != ROS1_MAGIC:
            raise BagError(
                f"{path} is not a ROS 1 bag (it does not start with '#ROSBAG V2.0'). Pass a "
                f"bag written by 'rosbag record' (format 2.0), or a JSON Lines recording "
                f"(name it .jsonl)")
    for store in ([path] if path.is_file() else sorted(path.glob("*.db3"))[:MAX_DIR_ENTRIES]):
        if ros2 and store.suffix == ".db3" and (why := check_sqlite(store)):
            raise BagError(f"{why}. Fix: record it again with 'ros2 bag record'")


def reason(e: BaseException) -> str:
    """What rosbags said, on one line and at most 200 characters."""
    text = " ".join(str(e).split()).rstrip(".") or type(e).__name__
    return text if len(text) <= 200 else text[:199] + "…"

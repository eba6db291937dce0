"""Fuzz target: a ROS 2 bag's ``metadata.yaml`` (the text rosbag2 writes beside its storage),
with the good bag's sqlite3 storage, read by ``BagReader`` as ``lint --from`` does.

Invariant (``fuzz.bags``): read whole, or refused with a one-line ``BagError`` (a count that is
not a number, an alias, a billion laughs: one line, never a TypeError or a hang); a message
that cannot be deserialized refuses the bag; time proportional to the input.
"""

from __future__ import annotations

from fuzz.bags import check, copy_of, good_bag

STORAGE = "sqlite3"


def prepare() -> None:
    """Write the good bag once."""
    good_bag(STORAGE)


def test_one_input(data: bytes) -> None:
    bag = copy_of(STORAGE)
    (bag / "metadata.yaml").write_bytes(data)
    check(bag, len(data))

"""Bounded decompression and storage for the ROS bags rosbags reads: our bounds, enforced
before bytes are produced.

rosbags inflates a ROS 1 chunk (bz2, lz4), an MCAP chunk (zstd, lz4) and a ROS 2 message or
file (zstd) whole, trusting the sizes the bag declares: a 10 KB bag whose chunk inflates to
1 GiB took 2 GB of memory before it was refused. ``install`` gives rosbags decompressors that
check a declared size against ``MAX_INFLATED`` before inflating and stop inflating one byte
past it (or past the declared size), so a bag that lies is refused in bounded time and memory.
``check_sqlite`` reads a ROS 2 sqlite3 store's schema before rosbags does: ``messages`` must be
a table of stored columns (a generated column ``raw || zeroblob(200000000)`` made 43 KB take
41 s and 2.4 GB), every message at most ``MAX_INFLATED`` bytes.
"""

from __future__ import annotations

import bz2
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

from conformance.bounds import MAX_PAYLOAD_BYTES

MAX_INFLATED = MAX_PAYLOAD_BYTES
"""What one chunk, message or compressed store of a bag may inflate to (64 MiB: the most a
recorded message may take; rosbag's chunks are 768 KiB, MCAP's 4 MiB)."""


MAX_STORE_BYTES = 2 << 30
"""What a ROS 2 store compressed whole ('file' mode) may inflate to: rosbags copies it into a
temporary file (disk, not memory); past it a few KB cannot fill a disk."""


class InflateError(ValueError):
    """A compressed part of a bag past the bounds (rosbags reports it as a damaged bag)."""


def _limit(declared: int | None) -> int:
    if declared is not None and declared > MAX_INFLATED:
        raise InflateError(f"a chunk declares {declared} bytes inflated, over the "
                           f"{MAX_INFLATED >> 20} MiB a chunk may take")
    return MAX_INFLATED if declared is None else declared


STEP = 1 << 20
"""Bytes inflated at a time: a bomb is stopped within a step of the bound, never past it."""


def _inflate(make: Callable[[], Any], data: bytes, declared: int | None, what: str) -> bytes:
    """``data`` inflated by a fresh decompressor of ``make``, a step at a time, at most the
    declared size (or ``MAX_INFLATED``): one byte more is refused without producing the rest;
    data that ends before its stream does is refused as the decompressor's own would."""
    limit = _limit(declared)
    inflater = make()
    pieces: list[bytes] = []
    total = 0
    rest = data
    while True:
        piece = inflater.decompress(rest, max_length=STEP)
        rest = b""
        total += len(piece)
        if total > limit:
            raise InflateError(f"a {what} chunk inflates past "
                               + (f"the {declared} bytes it declares" if declared is not None
                                  else f"the {MAX_INFLATED >> 20} MiB a chunk may take"))
        pieces.append(piece)
        if inflater.eof:
            break
        if inflater.needs_input:
            raise EOFError(f"a {what} chunk ends before its compressed stream does")
    return pieces[0] if len(pieces) == 1 else b"".join(pieces)


def bz2_bounded(data: bytes, declared: int | None = None) -> bytes:
    return _inflate(bz2.BZ2Decompressor, data, declared, "bz2")


def lz4_bounded(data: bytes, declared: int | None = None) -> bytes:
    from lz4.frame import LZ4FrameDecompressor  # type: ignore[import-untyped]

    return _inflate(LZ4FrameDecompressor, data, declared, "lz4")


def _zstd() -> Any:
    try:
        from compression import zstd  # type: ignore[import-not-found,unused-ignore]
    except ImportError:
        # Installed on some machines (typed), absent on others: each ignore may go unused.
        from backports import zstd  # type: ignore[import-not-found,no-redef,unused-ignore]
    return zstd


def zstd_bounded(data: bytes, declared: int | None = None) -> bytes:
    return _inflate(_zstd().ZstdDecompressor, data, declared, "zstd")


class _BoundedZstd:
    """What rosbags' ROS 2 reader calls of its zstd module (a message, a whole store), bounded."""

    @staticmethod
    def decompress(data: bytes) -> bytes:
        return zstd_bounded(data)

    @staticmethod
    def open(stream: Any, mode: str = "rb") -> Any:
        return _BoundedReader(_zstd().open(stream, mode))


class _BoundedReader:
    """A compressed store read at most ``MAX_STORE_BYTES`` bytes (rosbags copies it to a
    temporary file)."""

    def __init__(self, inner: Any) -> None:
        self.inner, self.read_so_far = inner, 0

    def read(self, size: int = -1) -> bytes:
        left = MAX_STORE_BYTES + 1 - self.read_so_far
        data = self.inner.read(max(min(size, left) if size >= 0 else min(left, 1 << 20), 1))
        self.read_so_far += len(data)
        if self.read_so_far > MAX_STORE_BYTES:
            raise InflateError(f"a zstd-compressed store inflates past the "
                               f"{MAX_STORE_BYTES >> 30} GiB a store may take")
        return bytes(data)

    def __enter__(self) -> _BoundedReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.inner.close()


_installed = False


def install() -> None:
    """Give rosbags our bounded decompressors (once per process; idempotent)."""
    global _installed
    if _installed:
        return
    from rosbags.rosbag1 import reader as ros1
    from rosbags.rosbag2 import reader as ros2
    from rosbags.rosbag2 import storage_mcap as mcap

    ros1.decompressors.update({"bz2": bz2_bounded, "lz4": lz4_bounded})
    mcap.DECOMPRESSORS.update({"lz4": lz4_bounded, "zstd": zstd_bounded})
    ros2.zstd = _BoundedZstd  # type: ignore[assignment]  # a module's name, our class
    _installed = True


def check_sqlite(path: Path) -> str:
    """Why the sqlite3 store at ``path`` is refused before rosbags reads it, or ''."""
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    except sqlite3.Error:
        return ""
    try:
        con.execute("PRAGMA trusted_schema = OFF")  # no function of the file's making runs
        kinds = dict(con.execute("SELECT name, type FROM sqlite_master WHERE name IN "
                                 "('messages', 'topics')").fetchall())
        sql = con.execute("SELECT sql FROM sqlite_master WHERE name = 'messages'").fetchone()
        if kinds.get("messages") != "table" or kinds.get("topics") != "table" or (
                sql and " ".join(str(sql[0]).upper().split()).startswith(
                    "CREATE VIRTUAL TABLE")):
            return (f"{path}: 'messages' and 'topics' are not plain tables (a view or a "
                    f"virtual table): not a store 'ros2 bag record' writes")
        for table in ("messages", "topics"):
            generated = [str(row[1]) for row in con.execute(f"PRAGMA table_xinfo({table})")
                         if row[6] != 0]  # hidden: 2 and 3 are generated columns
            if generated:
                return (f"{path}: the {table} table has generated column(s) "
                        f"{', '.join(generated)[:100]}: computed on reading, not stored (not "
                        f"a store 'ros2 bag record' writes)")
        longest = con.execute("SELECT max(length(data)) FROM messages").fetchone()[0]
        if longest is not None and longest > MAX_INFLATED:
            return (f"{path}: a message of {longest} bytes, over the "
                    f"{MAX_INFLATED >> 20} MiB a message may take")
    except sqlite3.Error:  # damaged: rosbags says so, with the fix (bagfile.open_bag)
        return ""
    finally:
        con.close()
    return ""

"""Compressed and stored parts of a bag that lie: refused in bounded time and memory, before
the bytes are produced (conformance/baginflate.py). The bombs are built small: a chunk or a
message a few KB long that inflates to 100 MiB, a generated column of 200 MB."""

from __future__ import annotations

import sqlite3
import struct
import sys
from pathlib import Path

import pytest
from ros_bags import unit_entries, write_bag

sys.path.insert(0, str(Path(__file__).parent.parent / "lint"))
from hostile import run_bounded  # noqa: E402

BOMB_BYTES = 100 << 20
"""What each bomb inflates to: past the 64 MiB a chunk may take."""
MAX_PEAK_MB = 250
"""Peak memory of a refusal (lint of a good bag takes about 100 MB)."""


def _zeros(compressor: object, total: int = BOMB_BYTES) -> bytes:
    """``total`` zero bytes compressed in pieces (never all in memory)."""
    piece = bytes(1 << 20)
    out = [compressor.compress(piece) for _ in range(total >> 20)]  # type: ignore[attr-defined]
    return b"".join(out) + compressor.flush()  # type: ignore[attr-defined]


def _zstd_bomb(total: int = BOMB_BYTES) -> bytes:
    try:
        from compression import zstd  # type: ignore[import-not-found]
    except ImportError:
        from backports import zstd  # type: ignore[import-not-found,no-redef]
    return _zeros(zstd.ZstdCompressor(), total)


def _ros1_records(data: bytes) -> list[tuple[int, dict[bytes, bytes], int, int]]:
    """(start, header fields, data start, data end) of each record of a ROS 1 bag."""
    out, at = [], len(b"#ROSBAG V2.0\n")
    while at < len(data):
        (header_len,) = struct.unpack_from("<I", data, at)
        fields, pos = {}, at + 4
        while pos < at + 4 + header_len:
            (n,) = struct.unpack_from("<I", data, pos)
            name, _, value = data[pos + 4:pos + 4 + n].partition(b"=")
            fields[name] = value
            pos += 4 + n
        (data_len,) = struct.unpack_from("<I", data, pos)
        out.append((at, fields, pos + 4, pos + 4 + data_len))
        at = pos + 4 + data_len
    return out


def _padded(bomb: bytes, length: int) -> bytes:
    """``bomb`` in place of ``length`` bytes: what follows its stream is zeros (read only by a
    decompressor that goes on past the first stream, after inflating it whole)."""
    assert len(bomb) <= length, (len(bomb), length)
    return bomb + bytes(length - len(bomb))


def ros1_bz2_bomb(tmp: Path) -> Path:
    import bz2

    bag = write_bag(tmp / "bomb.bag", unit_entries(seconds=3), compression="bz2")
    data = bytearray(bag.read_bytes())
    for _, fields, start, end in _ros1_records(bytes(data)):
        if fields.get(b"op") == b"\x05":  # a chunk: its data inflate to 100 MiB
            data[start:end] = _padded(_zeros(bz2.BZ2Compressor(9)), end - start)
            break
    bag.write_bytes(bytes(data))
    return bag


def mcap_zstd_bomb(tmp: Path) -> Path:
    bag = write_bag(tmp / "bomb", unit_entries(seconds=12, ros2=True), ros2=True,
                    storage="mcap", compression="storage")
    (store,) = bag.glob("*.mcap")
    data = bytearray(store.read_bytes())
    at = 8  # the magic
    while at < len(data):
        op, length = data[at], struct.unpack_from("<Q", data, at + 1)[0]
        if op == 0x06:  # a chunk: times, uncompressed size, crc, compression, records
            body = at + 9
            (size,) = struct.unpack_from("<Q", data, body + 16)
            (name_len,) = struct.unpack_from("<I", data, body + 28)
            records = body + 32 + name_len
            (records_len,) = struct.unpack_from("<Q", data, records)
            assert data[body + 32:records] == b"zstd" and size < BOMB_BYTES
            struct.pack_into("<I", data, body + 24, 0)  # no crc to check
            # 40 MiB (1.3 KB: an MCAP chunk is small), past the few KB the chunk declares.
            data[records + 8:records + 8 + records_len] = _padded(_zstd_bomb(40 << 20),
                                                                  records_len)
            break
        at += 9 + length
    store.write_bytes(bytes(data))
    return bag


def message_zstd_bomb(tmp: Path) -> Path:
    bag = write_bag(tmp / "bomb", unit_entries(seconds=3, ros2=True), ros2=True,
                    compression="message")
    (store,) = bag.glob("*.db3")
    with sqlite3.connect(store) as con:
        con.execute("UPDATE messages SET data = ? WHERE id = 1", (_zstd_bomb(),))
    return bag


def sqlite_generated(tmp: Path, *, view: bool = False) -> Path:
    """A ROS 2 bag whose messages' data is computed on reading: a generated column, or a
    view, ``raw || zeroblob(200000000)`` (43 KB took 41 s and 2.4 GB)."""
    bag = write_bag(tmp / "computed", unit_entries(seconds=3, ros2=True), ros2=True)
    (store,) = bag.glob("*.db3")
    with sqlite3.connect(store) as con:
        con.execute("ALTER TABLE messages RENAME TO raw_messages")
        if view:
            con.execute("CREATE VIEW messages AS SELECT id, topic_id, timestamp, "
                        "data || zeroblob(200000000) AS data FROM raw_messages")
        else:
            con.execute("CREATE TABLE messages (id INTEGER PRIMARY KEY, topic_id INTEGER, "
                        "timestamp INTEGER, raw BLOB, data BLOB GENERATED ALWAYS AS "
                        "(raw || zeroblob(200000000)) VIRTUAL)")
            con.execute("INSERT INTO messages (id, topic_id, timestamp, raw) "
                        "SELECT id, topic_id, timestamp, data FROM raw_messages")
            con.execute("DROP TABLE raw_messages")
    return bag


@pytest.mark.parametrize(("make", "says"), [
    (ros1_bz2_bomb, "a bz2 chunk inflates past the 64 MiB a chunk may take"),
    (mcap_zstd_bomb, "a zstd chunk inflates past the"),
    (message_zstd_bomb, "a zstd chunk inflates past the 64 MiB"),
    (sqlite_generated, "the messages table has generated column(s) data"),
    (lambda tmp: sqlite_generated(tmp, view=True), "'messages' and 'topics' are not plain"),
], ids=["ros1-bz2", "mcap-zstd", "message-zstd", "sqlite-generated", "sqlite-view"])
def test_a_bag_that_inflates_past_the_bounds_is_refused_in_bounded_memory(
        tmp_path: Path, make, says: str) -> None:
    bag = make(tmp_path)
    run = run_bounded("bomb", ["lint", "--from", str(bag), "--plain", "--format", "none"],
                      tmp_path)
    assert not run.killed, f"still running after {run.seconds:.0f} s"
    assert run.code == 3, run.out + run.err
    assert says in run.err, run.err
    assert "Traceback" not in run.err and "MemoryError" not in run.err
    assert run.peak_mb < MAX_PEAK_MB, f"peak {run.peak_mb:.0f} MB"


def test_a_compressed_bag_within_the_bounds_is_read(tmp_path: Path) -> None:
    """The bounded decompressors read what rosbags' own did: each compression linted whole."""
    bags = [write_bag(tmp_path / "c.bag", unit_entries(seconds=3), compression="bz2"),
            write_bag(tmp_path / "l.bag", unit_entries(seconds=3), compression="lz4"),
            write_bag(tmp_path / "m", unit_entries(seconds=3, ros2=True), ros2=True,
                      storage="mcap", compression="storage"),
            write_bag(tmp_path / "s", unit_entries(seconds=3, ros2=True), ros2=True,
                      compression="message"),
            write_bag(tmp_path / "f", unit_entries(seconds=3, ros2=True), ros2=True,
                      compression="file")]
    for i, bag in enumerate(bags):
        run = run_bounded(f"good{i}", ["lint", "--from", str(bag), "--plain", "--format",
                                       "none"], tmp_path)
        assert run.code in (0, 1, 4), (bag, run.out, run.err)
        assert "messages" in run.out and "cannot read" not in run.err, (bag, run.err)

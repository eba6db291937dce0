"""Fuzz target: the bounded decompressors rosbags inflates a bag's chunks, messages and
stores with (``baginflate``: bz2, lz4, zstd), with a declared size or none.

Input: one byte choosing the compression, four bytes of declared size (0xffffffff: none),
then compressed data (the seeds are real compressed chunks).

Invariant: the output is at most the declared size (or ``MAX_INFLATED``), or the data is
refused: ``InflateError``, or the decompressor's own error on damaged data (``OSError``,
``EOFError``, ``RuntimeError``, ``ValueError``; rosbags reports either as a damaged bag). Time
proportional to the input, memory within the fuzzer's bound.
"""

from __future__ import annotations

import struct

from conformance.baginflate import (
    MAX_INFLATED,
    InflateError,
    bz2_bounded,
    lz4_bounded,
    zstd_bounded,
)
from fuzz.harness import Broken, within_time

INFLATE = (bz2_bounded, lz4_bounded, zstd_bounded)
DAMAGED = (OSError, EOFError, RuntimeError, ValueError)
"""What bz2, lz4 and zstd raise on data that is not theirs (InflateError is a ValueError)."""


def prepare() -> None:
    """Nothing to build."""


def _zstd_error() -> type[BaseException]:
    try:
        from compression import zstd  # type: ignore[import-not-found]
    except ImportError:
        from backports import zstd  # type: ignore[import-not-found,no-redef]
    return zstd.ZstdError  # type: ignore[no-any-return]


def test_one_input(data: bytes) -> None:
    if len(data) < 5:
        return
    inflate = INFLATE[data[0] % 3]
    (declared,) = struct.unpack_from("<I", data, 1)
    size = None if declared == 0xFFFFFFFF else declared
    with within_time(len(data)):
        try:
            out = inflate(data[5:], size)
        except InflateError:
            return
        except (*DAMAGED, _zstd_error()):
            return
    limit = MAX_INFLATED if size is None else min(size, MAX_INFLATED)
    if len(out) > limit:
        raise Broken(f"{inflate.__name__} gave {len(out)} bytes past {limit}")

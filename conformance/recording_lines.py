"""A recording's binary stream cut into lines, a chunk at a time, each line bounded
(``bounds.MAX_LINE_BYTES``): a line past the bound is reported and skipped without ever being
held whole, so a 10 GB line costs no more memory than a short one."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import IO

from conformance.bounds import MAX_LINE_BYTES

CHUNK_BYTES = 1 << 20


class Lines:
    """Iterates (number of the first line, lines without their newlines), a chunk's worth at
    a time. ``read1`` returns what is there, so a live pipe from mosquitto_sub is not held
    back until a chunk fills. A line over ``limit`` bytes is skipped: ``overlong`` is told
    its number and its size in bytes. ``count``: the lines numbered so far."""

    def __init__(self, stream: IO[bytes], overlong: Callable[[int, int], None],
                 limit: int = MAX_LINE_BYTES) -> None:
        self.stream = stream
        self._overlong = overlong
        self.limit = limit
        self.count = 0

    def __iter__(self) -> Iterator[tuple[int, list[bytes]]]:
        read = getattr(self.stream, "read1", None) or self.stream.read
        limit = self.limit
        number = 0  # lines numbered so far
        parts: list[bytes] = []  # the start of a line that has not ended yet
        size = 0
        skipping = False
        while chunk := read(CHUNK_BYTES):
            start = 0
            if parts or skipping:
                end = chunk.find(b"\n")
                if end < 0:
                    size += len(chunk)
                    if not skipping:
                        parts.append(chunk)
                        if size > limit:
                            skipping, parts = True, []
                    continue
                number += 1
                size += end + 1
                if skipping or size > limit:
                    self._overlong(number, size)
                else:
                    parts.append(chunk[:end])
                    yield number, [b"".join(parts)]
                parts, size, skipping = [], 0, False
                start = end + 1
            lines = (chunk[start:] if start else chunk).split(b"\n")
            tail = lines.pop()
            if len(chunk) > limit:  # only a chunk this long can hold an overlong line
                done = 0
                for i, line in enumerate(lines):
                    if len(line) > limit:
                        if i > done:
                            yield number + done + 1, lines[done:i]
                        self._overlong(number + i + 1, len(line) + 1)
                        done = i + 1
                if done < len(lines):
                    yield number + done + 1, lines[done:]
            elif lines:
                yield number + 1, lines
            number += len(lines)
            if tail:
                parts, size = [tail], len(tail)
                if size > limit:
                    skipping, parts = True, []
        if parts or skipping:
            number += 1
            if skipping:
                self._overlong(number, size)
            else:
                yield number, [b"".join(parts)]
        self.count = number

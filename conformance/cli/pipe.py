"""Standard output whose reader may leave (``waraps-conformance lint --from F | head -n 1``):
the command goes on and ends as it would have (its reports written, its exit status its
own); only what it prints goes nowhere once the reader is gone."""

from __future__ import annotations

import os
from typing import IO, Any


def reader_left(stream: IO[str]) -> None:
    """The reader of ``stream`` left: what is still buffered for it, and anything printed
    later, goes to /dev/null instead of raising BrokenPipeError again, at exit too (the
    Python documentation's way, 'Note on SIGPIPE')."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # not a file descriptor (a test's StringIO)
        pass


class PipeOut:
    """``stream`` (standard output) as the commands write to it, where a reader that leaves
    is no error: the first BrokenPipeError sends the rest to /dev/null."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.left = False
        """The reader left (the command's output was cut short)."""

    def write(self, text: str) -> int:
        if not self.left:
            try:
                return self.stream.write(text)
            except BrokenPipeError:
                self._leave()
        return len(text)

    def flush(self) -> None:
        if not self.left:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self._leave()

    def _leave(self) -> None:
        self.left = True
        reader_left(self.stream)

    def __getattr__(self, name: str) -> Any:  # isatty, fileno, buffer, encoding, ...
        return getattr(self.stream, name)

"""What every target shares: running it under libFuzzer, and the invariant's checks.

The invariant: only the documented errors escape, each one line; time within a
bound proportional to the input (``within_time``; libFuzzer's ``-timeout`` catches a hang);
memory within ``-rss_limit_mb`` (``RSS_LIMIT_MB``) and, where a target can see it, output
proportional to the input (``proportional``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

RSS_LIMIT_MB = 1536
"""libFuzzer's ``-rss_limit_mb`` for every target: numpy and rosbags alone take ~150 MB."""
TIMEOUT_S = 20
"""libFuzzer's ``-timeout`` per input: past it the input is kept as a hang."""
BASE_SECONDS = 4.0
SECONDS_PER_MB = 40.0
"""``within_time``: an input may take BASE_SECONDS + SECONDS_PER_MB per MB of input
(instrumented code runs 3-5 times slower than plain; the machine is shared)."""
MAX_ERROR_CHARS = 2000
"""A documented error is one line of at most this many characters."""


class Broken(AssertionError):
    """The invariant does not hold for this input."""


def one_line(error: BaseException | object, what: str = "error", shown: bool = False) -> str:
    """The error's text, checked to be one line of bounded length; ``shown``: as the tool
    prints it (through ``conformance.display.printable``, which shows wire text visibly)."""
    text = str(error)
    if shown:
        from conformance.display import printable

        text = printable(text)
    if not text or "\n" in text or "\r" in text or len(text) > MAX_ERROR_CHARS:
        raise Broken(f"{what} is not one line of at most {MAX_ERROR_CHARS} characters: "
                     f"{text[:300]!r}")
    return text


@contextmanager
def within_time(size: int) -> Iterator[None]:
    """The body must finish within a time proportional to ``size`` bytes of input."""
    t0 = time.process_time()
    yield
    spent = time.process_time() - t0
    allowed = BASE_SECONDS + SECONDS_PER_MB * size / 1e6
    if spent > allowed:
        raise Broken(f"{spent:.1f} s of CPU for {size} bytes of input (bound {allowed:.1f} s)")


def proportional(produced: int, size: int, factor: int = 64, base: int = 1 << 20,
                 what: str = "output") -> None:
    """``produced`` bytes from ``size`` bytes of input: no amplification past ``factor``."""
    if produced > base + factor * size:
        raise Broken(f"{what} of {produced} bytes from {size} bytes of input (bound "
                     f"{base} + {factor} x input)")


def run(test_one_input: Callable[[bytes], None], argv: list[str] | None = None) -> None:
    """libFuzzer on ``test_one_input`` with the shared bounds (options given win)."""
    import atheris

    args = list(sys.argv if argv is None else argv)
    given = {a.split("=", 1)[0] for a in args[1:] if a.startswith("-")}
    for option, value in (("-rss_limit_mb", RSS_LIMIT_MB), ("-timeout", TIMEOUT_S),
                          ("-max_len", 1 << 16)):
        if option not in given:
            args.insert(1, f"{option}={value}")
    atheris.Setup(args, test_one_input)
    atheris.Fuzz()

"""Recording live traffic to JSON Lines (``waraps-conformance record``): what ``lint --from``
judges later, with the capture's own events (start, connection losses, what it could not keep
up with, end) so that silences and gaps are read right."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import IO

from conformance.display import shown
from conformance.lint.capture import CaptureOptions, LiveCapture
from conformance.recording import Event, RecordingWriter


def record(options: CaptureOptions, open_output: Callable[[], IO[bytes]], *, name: str,
           log: IO[str]) -> int:
    """Record what ``options`` capture to the output ``open_output`` opens (called ``name``
    in the messages on ``log``) until their duration is over or Ctrl-C. Returns 0; raises
    ``BrokerError`` when the broker cannot be reached: the output is then never opened (no
    empty file, and a file ``--force`` would replace is left as it was)."""
    assert options.broker is not None
    capture = LiveCapture(options.broker, options.topics)
    capture.start()
    try:
        out = open_output()
    except BaseException:
        capture.stop()
        raise
    try:
        return _record(options, capture, RecordingWriter(out), name=name, log=log)
    finally:
        if out is not sys.stdout.buffer:
            out.close()


def _record(options: CaptureOptions, capture: LiveCapture, writer: RecordingWriter, *,
            name: str, log: IO[str]) -> int:
    try:  # from here on, Ctrl-C (or SIGTERM) ends the recording with its end event
        print(shown(f"recording {', '.join(options.topics)} from {options.broker} to {name}"
                    + (f" for {options.duration:g} s" if options.duration else
                       " until Ctrl-C")), file=log)
        writer.write(Event(time.time(), "start", "subscribed"))
        deadline = None if not options.duration else time.monotonic() + options.duration
        while deadline is None or time.monotonic() < deadline:
            left = 0.5 if deadline is None else max(0.0, min(0.5, deadline - time.monotonic()))
            batch, events = capture.take(timeout=left)
            for event in events:
                writer.write(event)
                if event.kind != "unexamined":
                    print(shown(f"{time.strftime('%H:%M:%S', time.localtime(event.time))} "
                                f"{event.kind}{': ' + event.detail if event.detail else ''}"),
                          file=log)
            for message in batch:
                if options.wants(message.topic):
                    writer.write(message)
            if len(batch) < capture.wake_at:  # not a burst: a pipe reader sees it now
                writer.flush()
    except KeyboardInterrupt:
        pass
    finally:
        capture.stop()
        batch, events = capture.take(timeout=0, max_messages=10**9)  # all that is left
        for event in events:
            writer.write(event)
        for message in batch:
            if options.wants(message.topic):
                writer.write(message)
        # Lint judges up to here: a unit silent since its last message until now has died.
        writer.write(Event(time.time(), "end", "stopped"))
        writer.flush()
    print(shown(f"recorded {writer.messages} messages ({writer.bytes} bytes) to {name}"
                + (f"; {capture.dropped} could not be kept up with (recorded as unexamined)"
                   if capture.dropped else "")), file=log)
    return 0

"""Recorded traffic: the JSON Lines format ``lint --from`` reads and ``record`` writes, and the
output of ``mosquitto_sub -F %j`` / ``-F %J``.

One JSON object per line and per message::

    {"ts": 1763706393.546275, "topic": "waraps/unit/air/real/dji0/heartbeat",
     "payload": "{\\"name\\": \\"dji0\\", ...}", "qos": 0, "retain": false}

``ts`` is the receive time in Unix seconds (float); ``payload`` is the payload as text, or
``payload_b64`` (base64) when it is not UTF-8; ``qos`` and ``retain`` are optional. A line
with ``event`` instead of ``topic`` records what happened to the capture itself, so that a
recording judged later knows what the recorder could not see::

    {"ts": ..., "event": "disconnected", "detail": "connection lost"}
    {"ts": ..., "event": "connected"}
    {"ts": ..., "event": "unexamined", "count": 120}   # dropped by a recorder that fell behind

The output of ``mosquitto_sub`` (``-F %j``, ``-F %J``, ``-v``) is undone in
``conformance/mosquitto_sub.py``; a stream is cut into bounded lines by
``conformance/recording_lines.py``.

Every line is bounded (``conformance.bounds``): its length, the payload received and declared,
its nesting, its time. A line past a bound is a problem of that line; reading goes on.
"""

from __future__ import annotations

import base64
import binascii
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import orjson

from conformance.bounds import (
    MAX_LINE_BYTES,
    MAX_LINE_VALUES,
    MAX_NESTING,
    MAX_TIME,
    MIN_TIME,
    check_time,
)
from conformance.display import shorten
from conformance.jsontext import dumps
from conformance.message import Message
from conformance.mosquitto_sub import (
    FORMAT_MOSQUITTO_J,
    FORMAT_MOSQUITTO_JJ,
    FORMAT_MOSQUITTO_V,
    VERBOSE,
    MosquittoLines,
    loads_not_utf8,
    parse_tst,
    utf8,
    verbose_message,
)
from conformance.recording_lines import Lines
from conformance.violation import clock

BIG_LINE_BYTES = 1 << 20
"""A line longer than this has its JSON values counted before it is parsed (MAX_LINE_VALUES)."""
PROBLEM_CHARS = 300
"""A problem's text is kept up to this (it may quote the line: a 64 MiB 'tst', found by
fuzz/recording_mixed, was kept whole, and 100 problems are kept)."""
MAX_PROBLEMS_KEPT = 100
"""Malformed lines kept with their text; beyond this they are only counted (bounded memory)."""

BACKWARDS_SECONDS = 2.0
"""How far a recorded time may run back behind the latest before it (a recording host's clock
stepped by NTP) before the recording is refused: further back, two captures were joined (``cat
a.jsonl b.jsonl``), and judged as one they would tell a death or a silence that never was."""

FORMAT_JSONL = "jsonl"
UNTIMED_RULES = ("HB-003", "SI-002", "DEI-002", "TEI-002", "HB-010", "HB-011", "HB-012",
                 "MSG-005", "MSG-007", "MSG-008", "SENS-005", "EXEC-010", "EXEC-PING-001",
                 "EXEC-ROBUST-001")
"""Rules judged on arrival times (rates, silences, stamps against arrival, deadlines): not
judged on a capture without times (``mosquitto_sub -v``), a could-not-test with
``UNTIMED_REASON``, never a pass or a fail."""
UNTIMED_REASON = "not judged: no timestamps (a mosquitto_sub -v capture)"


@dataclass(frozen=True)
class Event:
    """Something that happened to the capture, not a message: ``kind`` is ``disconnected``,
    ``connected``, ``unexamined`` (``count`` messages dropped by a recorder that fell
    behind), ``start`` or ``end`` (when the recorder began and stopped listening: silence
    until the end is part of the observation, HB-012). ``time`` is in Unix seconds."""

    time: float
    kind: str
    detail: str = ""
    count: int = 0


EVENT_KINDS = ("disconnected", "connected", "unexamined", "start", "end")
UNTIMED_NOTE = "a mosquitto_sub -v capture has no times"
"""How the note on such a capture starts (lint prints it first)."""
CUT = "cut"
"""The kind of the ``Event`` a reader yields instead of a message whose payload the capturing
tool cut to its first line (``cut_payload``; never read from a line): what it said is unknown,
as over a gap of the observer, and it is the capture's fault, never the unit's."""
UNTIMED = "untimed"
"""The kind of the ``Event`` a reader yields before the first message without a recorded time
(never read from a line): the consumer judges no rule of ``UNTIMED_RULES``."""


def cut_payload(payload: bytes | str) -> bool:
    """Whether a payload is only the first line of a pretty-printed JSON text ('{' or '['):
    a tool that records line by line cut it there (``mosquitto_sub -v`` prints the rest as
    lines of their own)."""
    return len(payload) < 8 and payload.strip() in (b"{", b"[", "{", "[")


@dataclass(frozen=True)
class LineProblem:
    """A line of a recording that could not be read: where, what, and an excerpt."""

    line: int
    problem: str
    text: str = ""

    def __str__(self) -> str:
        return f"line {self.line}: {self.problem}" + (f": {self.text}" if self.text else "")


class RecordingError(ValueError):
    """A recording that cannot be opened at all."""


_BOM = b"\xef\xbb\xbf"
_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")


def _excerpt(line: bytes, limit: int = 120) -> str:
    text = line[: limit * 2].decode("utf-8", "backslashreplace")
    return text if len(text) <= limit else text[: limit - 1] + "…"


class RecordingReader:
    """Reads a recording (a binary stream) as ``Message`` and ``Event`` items, in file order.

    Never stops at a bad line: each becomes a ``LineProblem`` (the first 100 are kept, the rest
    counted) and reading goes on. After iterating, ``formats`` says which formats were seen and
    ``unprintable`` how many messages ``mosquitto_sub -F %J`` could not print (empty lines).
    """

    def __init__(self, stream: IO[bytes], name: str = "<stdin>") -> None:
        self.stream = stream
        self.name = name
        self.lines = 0
        self.messages = 0
        self.problems: list[LineProblem] = []
        self.problem_count = 0
        self.blank_lines = 0
        self.bom_lines = 0
        """Lines after the first that began with a UTF-8 byte order mark (read without it)."""
        self.formats: set[str] = set()
        self.notes: list[str] = []
        self._latest = (float("-inf"), 0)  # the latest recorded time, and its line
        self.backwards = ""
        """Why reading stopped early: a recorded time ran backwards (``BACKWARDS_SECONDS``);
        the consumer judges nothing of such a recording."""
        self.cut = 0
        """Messages whose payload the capture cut to its first line (``cut_payload``)."""
        self._cut_lines = False  # the lines after a cut -v payload are its rest
        self._mosquitto = MosquittoLines(self.formats)

    @property
    def unprintable(self) -> int:
        """Blank lines in ``-F %J`` output: messages whose payload was not JSON, topic lost."""
        return self.blank_lines if FORMAT_MOSQUITTO_JJ in self.formats else 0

    def problem(self, line: int, problem: str, raw: bytes = b"") -> None:
        self.problem_count += 1
        if len(self.problems) < MAX_PROBLEMS_KEPT:  # bounded whatever the text quotes
            self.problems.append(LineProblem(line, shorten(problem, PROBLEM_CHARS),
                                             _excerpt(raw) if raw else ""))

    def __iter__(self) -> Iterator[Message | Event]:
        """Every item, in file order; long because the common line (our JSON Lines, a text
        payload) is read inline: a call per line costs more than the rest of its reading."""
        loads = orjson.loads
        decode_error = orjson.JSONDecodeError
        new = tuple.__new__  # Message(...) without its Python-level __new__: once per line
        message = Message
        count = 0
        timed = False  # a line of our own JSON Lines was read (the fast path)
        try:
            batches = Lines(self.stream, self._overlong, MAX_LINE_BYTES)
            for first, lines in batches:
                for number, line in enumerate(lines, first):
                    if len(line) > BIG_LINE_BYTES and self._too_many_values(number, line):
                        continue
                    try:
                        obj = loads(line)  # JSON whitespace (a trailing CR) is fine
                    except decode_error as e:
                        if not line.strip():
                            self.blank_lines += 1
                            continue
                        line = line.rstrip(b"\r")
                        obj = loads_not_utf8(line)
                        if obj is None and line.startswith(_BOM):
                            obj = self._without_bom(line, number)
                        if obj is None:
                            for item in self._verbose_or_problem(number, line, e, timed):
                                count += isinstance(item, Message)
                                yield item
                            continue
                    # The common case first: one of our own lines with a text payload.
                    if type(obj) is dict:
                        ts = obj.get("ts")
                        topic = obj.get("topic")
                        payload = obj.get("payload")
                        if (type(ts) is float and type(topic) is str and type(payload) is str
                                and "payload_b64" not in obj and MIN_TIME <= ts <= MAX_TIME):
                            qos = obj.get("qos", 0)
                            retain = obj.get("retain", False)
                            if (qos == 0 or qos == 1 or qos == 2) and type(qos) is int and \
                                    type(retain) is bool:
                                timed = True
                                if ts < self._latest[0] and self._backwards(number, ts):
                                    return
                                self._latest = max(self._latest, (ts, number))
                                if len(payload) < 8 and cut_payload(payload):
                                    yield self._cut(ts, topic)
                                    continue
                                count += 1
                                yield new(message, (ts, topic, payload.encode(
                                    "utf-8", "surrogateescape"), qos, retain))
                                continue
                    try:
                        item = self._item(obj)
                    except (ValueError, OverflowError, OSError) as e:  # dates past any bound
                        self.problem(number, str(e), line)
                        continue
                    if item.time < self._latest[0] and self._backwards(number, item.time):
                        return
                    self._latest = max(self._latest, (item.time, number))
                    if isinstance(item, Message):
                        if cut_payload(item.payload):
                            yield self._cut(item.time, item.topic)
                            continue
                        count += 1
                    yield item
                self.messages += count  # counted per chunk (a shared counter costs per line)
                count = 0
            self.lines = batches.count
        finally:
            self.messages += count
            if timed:
                self.formats.add(FORMAT_JSONL)
        self._add_notes()

    def _without_bom(self, line: bytes, number: int) -> Any:
        """A line that begins with a byte order mark (an editor's, a Windows tool's) read
        without it, never dropped (nor its unit with it); None when it is no JSON even so."""
        obj = loads_not_utf8(line[3:], strict=False)
        self.bom_lines += obj is not None and number > 1
        return obj

    def _too_many_values(self, number: int, line: bytes) -> bool:
        """Whether a line over 1 MiB holds more JSON values than it may (a problem, skipped)."""
        if _values(line) <= MAX_LINE_VALUES:
            return False
        self.problem(number, f"line of {len(line)} bytes holds more than the {MAX_LINE_VALUES} "
                     f"JSON values a line over 1 MiB may take; skipped", line)
        return True

    def _overlong(self, number: int, size: int) -> None:
        self.problem(number, f"line of {size} bytes is longer than the {MAX_LINE_BYTES >> 20} "
                     f"MiB a recorded message may take; skipped")

    def _verbose_or_problem(self, number: int, line: bytes, error: Exception,
                            timed: bool) -> Iterator[Message | Event]:
        """A line that is not JSON: a ``mosquitto_sub -v`` message, told from its content only
        in a capture that has shown no line with times (one odd line must not untime it),
        after an ``UNTIMED`` event the first time; else a problem of the line."""
        verbose = (None if timed or self.formats - {FORMAT_MOSQUITTO_V}
                   else verbose_message(line))
        if verbose is None:
            if not self._cut_lines:  # else the rest of a cut payload: said in the note
                self.problem(number, _not_json(error, line, number), line)
            return
        if FORMAT_MOSQUITTO_V not in self.formats:
            self.formats.add(FORMAT_MOSQUITTO_V)
            yield Event(verbose.time, UNTIMED)
        if cut_payload(verbose.payload):
            yield self._cut(verbose.time, verbose.topic)
            self._cut_lines = True
            return
        self._cut_lines = False
        yield verbose

    def _backwards(self, number: int, t: float) -> bool:
        """A recorded time before the latest one: a step of the recording host's clock within
        ``BACKWARDS_SECONDS`` (False: read on), else reading stops there and ``backwards``
        says why, naming the line (True): joined captures would tell a death or a silence
        that never was, so nothing of it may be judged."""
        latest, where = self._latest
        if latest - t <= BACKWARDS_SECONDS:
            return False
        self.backwards = (
            f"{self.name}: line {number}: time runs backwards: {clock(t)} is "
            f"{latest - t:.1f} s before line {where}'s {clock(latest)}. Two captures joined "
            f"end to end (cat a.jsonl b.jsonl)? Lint each on its own; nothing was judged.")
        return True

    def _cut(self, t: float, topic: str) -> Event:
        self.cut += 1
        return Event(float(t), CUT, utf8(topic))

    def _add_notes(self) -> None:
        """What a person must know of the recording as a whole (after the last line)."""
        if self.bom_lines:
            self.notes.append(
                f"{self.bom_lines} line(s) after the first began with a UTF-8 byte order mark: "
                f"read without it (a file was joined from pieces, or written by a tool that "
                f"marks every line)")
        if self._mosquitto.truncated:
            self.notes.append(
                f"{self._mosquitto.truncated} payload(s) were cut at a NUL byte by mosquitto_sub "
                f"-F %j (payloadlen is longer than the payload); the cut is marked by a NUL byte (a "
                f"payload declared over 1 MiB: NUL bytes to that bound). Record with 'waraps-conformance record' for byte-exact payloads.")
        if self.cut:
            self.notes.append(
                f"{self.cut} payload(s) were cut to their first line ('{{' or '[') by the "
                f"capturing tool, which recorded a pretty-printed JSON payload line by line: the "
                f"capture's fault, not the units'. They are not judged, nor is a command they "
                f"may have answered judged unanswered. Record with 'waraps-conformance record' "
                f"or mosquitto_sub -F %j for whole payloads.")
        if FORMAT_MOSQUITTO_V in self.formats:
            self.notes.append(
                f"{UNTIMED_NOTE}: {', '.join(UNTIMED_RULES)} are "
                f"could-not-test ({UNTIMED_REASON}). Record with 'waraps-conformance record' "
                f"or mosquitto_sub -F %j to have them judged.")
        if self.unprintable:
            self.notes.append(
                f"{self.unprintable} message(s) are missing from this mosquitto_sub -F %J "
                f"recording (empty lines): mosquitto_sub prints nothing for a payload that is "
                f"not JSON, so their topics are unknown. Record with -F %j or "
                f"'waraps-conformance record' to have them judged.")

    def _item(self, obj: Any) -> Message | Event:
        """One line's object as a message or event; ValueError says what is wrong."""
        if not isinstance(obj, dict):
            raise ValueError(f"a {type(obj).__name__}, not an object with ts, topic and payload")
        if "ts" in obj:
            return self._jsonl(obj)
        if "tst" in obj:
            return self._mosquitto.message(obj)
        raise ValueError("neither 'ts' (JSON Lines, as 'waraps-conformance record' writes) nor "
                         "'tst' (mosquitto_sub -F %j or -F %J)")

    def _jsonl(self, obj: dict[str, Any]) -> Message | Event:
        self.formats.add(FORMAT_JSONL)
        ts = obj["ts"]
        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or ts != ts:
            raise ValueError(f"'ts' is {ts!r}, not a receive time in Unix seconds")
        check_time(ts)
        if "event" in obj and "topic" not in obj:
            kind = obj["event"]
            if kind not in EVENT_KINDS:
                raise ValueError(f"event {kind!r} is not one of {', '.join(EVENT_KINDS)}")
            count = obj.get("count", 0)
            if isinstance(count, bool) or not isinstance(count, int) or count < 0:
                raise ValueError(f"event count {count!r} is not a non-negative whole number")
            detail = obj.get("detail", "")
            if type(detail) is not str:  # any depth (a line nests up to 1024): no str()
                detail = shorten(dumps(detail).decode("utf-8", "replace"), PROBLEM_CHARS)
            return Event(float(ts), kind, utf8(detail), count)
        topic = obj.get("topic")
        if not isinstance(topic, str):
            raise ValueError("'topic' is missing or not a string")
        topic = utf8(topic)
        if isinstance(obj.get("payload"), str):
            payload = obj["payload"].encode("utf-8", "surrogateescape")
        elif isinstance(obj.get("payload_b64"), str):
            try:
                payload = base64.b64decode(obj["payload_b64"], validate=True)
            except (binascii.Error, ValueError):
                raise ValueError("'payload_b64' is not base64") from None
        else:
            raise ValueError("neither 'payload' (text) nor 'payload_b64' (base64) is a string")
        qos, retain = obj.get("qos", 0), obj.get("retain", False)
        if qos not in (0, 1, 2) or isinstance(qos, bool):
            raise ValueError(f"'qos' is {qos!r}, not 0, 1 or 2")
        if retain not in (True, False, 0, 1):
            raise ValueError(f"'retain' is {retain!r}, not true or false")
        return Message(float(ts), topic, payload, int(qos), bool(retain))

def _values(line: bytes) -> int:
    """At least the JSON values a line holds beyond its first (a bound counted without parsing:
    ',' '[' '{' inside strings count too, which only errs towards reading less)."""
    return line.count(b",") + line.count(b"[") + line.count(b"{")


def _not_json(e: Exception, line: bytes, number: int) -> str:
    if "recursion" in str(e).lower() or "depth" in str(e).lower():
        return f"not JSON: nested deeper than the {MAX_NESTING} levels a line may take"
    if VERBOSE.match(line):
        return ("a mosquitto_sub -v line (TOPIC PAYLOAD) among lines with times: not read "
                "(a capture is one format)")
    if number == 1 and line.startswith(_UTF16_BOMS):
        return ("not JSON: the file is UTF-16 (it starts with a UTF-16 byte order mark); a "
                "recording is UTF-8: convert it with 'iconv -f UTF-16 -t UTF-8'")
    return f"not JSON ({e})"


def open_recording(source: str, stdin: IO[bytes] | None = None) -> tuple[IO[bytes], str]:
    """The binary stream for ``--from SOURCE`` (``-`` is standard input) and its name."""
    if source == "-":
        return (stdin or sys.stdin.buffer), "<stdin>"
    path = Path(source)
    if not path.is_file():
        raise RecordingError(f"recording {source!r} does not exist or is not a file "
                             f"(make one with 'waraps-conformance record -o FILE', or pipe "
                             f"'mosquitto_sub -t waraps/# -F %j' into '--from -')")
    return path.open("rb"), str(path)


# --- writing ------------------------------------------------------------------------------------

def encode_message(message: Message) -> bytes:
    """One JSON Lines line (with its newline) for a message."""
    line: dict[str, Any] = {"ts": message.time, "topic": message.topic}
    try:
        line["payload"] = message.payload.decode("utf-8")
    except UnicodeDecodeError:
        line["payload_b64"] = base64.b64encode(message.payload).decode("ascii")
    line["qos"] = message.qos
    line["retain"] = message.retain
    try:
        return orjson.dumps(line, option=orjson.OPT_APPEND_NEWLINE)
    except orjson.JSONEncodeError:  # a topic with lone surrogates (read back from %j)
        line["topic"] = message.topic.encode("utf-8", "backslashreplace").decode("ascii")
        return orjson.dumps(line, option=orjson.OPT_APPEND_NEWLINE)


def encode_event(event: Event) -> bytes:
    """One JSON Lines line for a capture event."""
    line: dict[str, Any] = {"ts": event.time, "event": event.kind}
    if event.detail:
        line["detail"] = event.detail
    if event.count:
        line["count"] = event.count
    return orjson.dumps(line, option=orjson.OPT_APPEND_NEWLINE)


class RecordingWriter:
    """Writes messages and events as JSON Lines to a binary stream; counts what it wrote."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.stream = stream
        self.messages = 0
        self.bytes = 0

    def write(self, item: Message | Event) -> None:
        line = encode_message(item) if isinstance(item, Message) else encode_event(item)
        self.stream.write(line)
        self.bytes += len(line)
        if isinstance(item, Message):
            self.messages += 1

    def flush(self) -> None:
        self.stream.flush()


__all__ = ["FORMAT_JSONL", "FORMAT_MOSQUITTO_J", "FORMAT_MOSQUITTO_JJ", "FORMAT_MOSQUITTO_V",
           "UNTIMED", "UNTIMED_NOTE", "UNTIMED_REASON", "UNTIMED_RULES", "Event", "LineProblem",
           "RecordingError", "RecordingReader", "RecordingWriter", "check_time", "encode_event",
           "encode_message", "open_recording", "parse_tst"]

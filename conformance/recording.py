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

mosquitto_sub 2.0.11 (measured here, see ``tests/lint/test_recording.py``):

- ``-F %j`` prints ``{"tst": "2026-11-21T07:26:55.807087Z+0100", "topic": ..., "qos": 0,
  "retain": 0, "payloadlen": 7, "payload": "<text>"}``. ``tst`` is *local* time followed by a
  stray ``Z`` and then the real UTC offset. The payload is copied into the JSON string byte for
  byte (bytes that are not UTF-8 included, so the line itself is not UTF-8), and it is cut at
  the first NUL byte; ``payload`` is null for an empty payload.
- ``-F %J`` embeds the payload as a JSON value (re-serialised: whitespace is lost) and prints
  an *empty line* (plus an error on stderr) for a payload that is not JSON: that message, and
  its topic, are lost to the recording.
- ``-v`` prints ``TOPIC PAYLOAD`` per message (``(null)`` for an empty payload): no time. Such a line is told from JSON by
  its content (a topic with a '/', a space, the payload); its message gets the time the line
  was read, and the rules that need arrival times are not judged (``UNTIMED_RULES``).

Every line is bounded (``conformance.bounds``): its length, the payload received and declared,
its nesting, its time. A line past a bound is a problem of that line; reading goes on.
"""

from __future__ import annotations

import base64
import binascii
import json
import re
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import IO, Any

import orjson

from conformance.bounds import (
    MAX_LINE_BYTES,
    MAX_NESTING,
    MAX_PAYLOAD_BYTES,
    MAX_TIME,
    MIN_TIME,
)
from conformance.message import Message

CHUNK_BYTES = 1 << 20
MAX_PROBLEMS_KEPT = 100
"""Malformed lines kept with their text; beyond this they are only counted (bounded memory)."""

FORMAT_JSONL = "jsonl"
FORMAT_MOSQUITTO_J = "mosquitto_sub -F %j"
FORMAT_MOSQUITTO_JJ = "mosquitto_sub -F %J"
FORMAT_MOSQUITTO_V = "mosquitto_sub -v"
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
"""How the note on such a capture starts (lint prints it first: issue 27, 4)."""
UNTIMED = "untimed"
"""The kind of the ``Event`` a reader yields before the first message without a recorded time
(never read from a line): the consumer judges no rule of ``UNTIMED_RULES``."""


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


# mosquitto_sub's tst: local time, a stray 'Z', then the offset ("...33.546275Z+0100").
_TST = re.compile(r"^(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d{1,9})?)Z?([+-]\d\d:?\d\d)?$")


def parse_tst(text: str) -> float:
    """Unix seconds of a mosquitto_sub ``tst`` value; ValueError if it is not one."""
    m = _TST.match(text)
    if m is None:
        raise ValueError(f"tst {text!r} is not an ISO 8601 time like 2026-11-21T06:26:33.546275Z+0000")
    stamp, offset = m.groups()
    if "." in stamp:  # fromisoformat takes 3 or 6 fraction digits only
        whole, frac = stamp.split(".")
        stamp = f"{whole}.{(frac + '000000')[:6]}"
    if offset is None:
        offset = "+00:00"
    elif ":" not in offset:
        offset = f"{offset[:3]}:{offset[3:]}"
    return datetime.fromisoformat(stamp + offset).timestamp()


def check_time(ts: float, what: str = "ts") -> float:
    """``ts`` if it is a time within the bounds (1970..2100), else ValueError naming them."""
    if not MIN_TIME <= ts <= MAX_TIME:  # NaN fails too
        raise ValueError(f"'{what}' {ts!r} is outside the times a recording may hold "
                         f"({MIN_TIME:.0f}..{MAX_TIME:.0f} Unix seconds, 1970 to 2100)")
    return ts


# mosquitto_sub -v: TOPIC, one space, PAYLOAD (a topic holds no space and no wildcard).
_VERBOSE = re.compile(rb"^([^\x00-\x20\x7f{}\[\]\"#+]*/[^\x00-\x20\x7f#+]*) (.*)$", re.DOTALL)
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
        self.formats: set[str] = set()
        self.notes: list[str] = []
        self._truncated = 0

    @property
    def unprintable(self) -> int:
        """Blank lines in ``-F %J`` output: messages whose payload was not JSON, topic lost."""
        return self.blank_lines if FORMAT_MOSQUITTO_JJ in self.formats else 0

    def problem(self, line: int, problem: str, raw: bytes = b"") -> None:
        self.problem_count += 1
        if len(self.problems) < MAX_PROBLEMS_KEPT:
            self.problems.append(LineProblem(line, problem, _excerpt(raw) if raw else ""))

    def _batches(self) -> Iterator[tuple[int, list[bytes]]]:
        """(number of the first line, lines without their newlines), a chunk's worth at a
        time, read in chunks. ``read1`` returns what is there, so a live pipe from
        mosquitto_sub is not held back until a chunk fills. A line over ``MAX_LINE_BYTES`` is
        skipped (a problem) without ever being held whole."""
        read = getattr(self.stream, "read1", None) or self.stream.read
        limit = MAX_LINE_BYTES
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
        self.lines = number

    def _overlong(self, number: int, size: int) -> None:
        self.problem(number, f"line of {size} bytes is longer than the {MAX_LINE_BYTES >> 20} "
                     f"MiB a recorded message may take; skipped")

    def __iter__(self) -> Iterator[Message | Event]:
        loads = orjson.loads
        decode_error = orjson.JSONDecodeError
        new = tuple.__new__  # Message(...) without its Python-level __new__: once per line
        message = Message
        count = 0
        timed = False  # a line of our own JSON Lines was read (the fast path)
        try:
            for first, lines in self._batches():
                for number, line in enumerate(lines, first):
                    try:
                        obj = loads(line)  # JSON whitespace (a trailing CR) is fine
                    except decode_error as e:
                        if not line.strip():
                            self.blank_lines += 1
                            continue
                        line = line.rstrip(b"\r")
                        obj = self._loads_not_utf8(line)
                        if obj is None and number == 1 and line.startswith(_BOM):
                            obj = self._loads_not_utf8(line[3:], strict=False)
                        if obj is None:
                            # mosquitto_sub -v, told from content: only in a capture that has
                            # shown no line with times (one odd line must not untime it)
                            verbose = (None if timed or self.formats - {FORMAT_MOSQUITTO_V}
                                       else self._verbose(line))
                            if verbose is not None:
                                if FORMAT_MOSQUITTO_V not in self.formats:
                                    self.formats.add(FORMAT_MOSQUITTO_V)
                                    yield Event(verbose.time, UNTIMED)
                                count += 1
                                yield verbose
                                continue
                            self.problem(number, _not_json(e, line, number), line)
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
                                count += 1
                                timed = True
                                yield new(message, (ts, topic, payload.encode(
                                    "utf-8", "surrogateescape"), qos, retain))
                                continue
                    try:
                        item = self._item(obj)
                    except (ValueError, OverflowError, OSError) as e:  # dates past any bound
                        self.problem(number, str(e), line)
                        continue
                    if isinstance(item, Message):
                        count += 1
                    yield item
                self.messages += count  # counted per chunk (a shared counter costs per line)
                count = 0
        finally:
            self.messages += count
            if timed:
                self.formats.add(FORMAT_JSONL)
        if self._truncated:
            self.notes.append(
                f"{self._truncated} payload(s) were cut at a NUL byte by mosquitto_sub -F %j "
                f"(payloadlen is longer than the payload); the missing bytes were replaced by "
                f"NUL bytes. Record with 'waraps-conformance record' for byte-exact payloads.")
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

    @staticmethod
    def _verbose(line: bytes) -> Message | None:
        """A ``mosquitto_sub -v`` line (``TOPIC PAYLOAD``) as a message read now, else None."""
        m = _VERBOSE.match(line)
        if m is None:
            return None
        try:
            topic = m[1].decode("utf-8")  # a topic is UTF-8 text (MQTT 3.1.1, 1.5.3)
        except UnicodeDecodeError:
            return None
        # mosquitto_sub 2.0 prints an empty payload (a retained message cleared) as "(null)"
        return Message(time.time(), topic, b"" if m[2] == b"(null)" else m[2])

    @staticmethod
    def _loads_not_utf8(line: bytes, strict: bool = True) -> Any:
        """mosquitto_sub -F %j copies non-UTF-8 payload bytes into the line as they are; read
        them back as surrogate escapes, so the payload's bytes are recovered exactly.
        ``strict`` False: valid UTF-8 too (a first line after its byte order mark)."""
        try:
            line.decode("utf-8")
            if strict:
                return None  # valid UTF-8: the line is simply not JSON
        except UnicodeDecodeError:
            pass
        try:
            obj = json.loads(line.decode("utf-8", "surrogateescape"))
        except (ValueError, RecursionError):
            return None
        if type(obj) is dict:
            if type(obj.get("topic")) is str:
                obj["topic"] = _utf8(obj["topic"])
            payload = obj.get("payload")
            if type(payload) is str:  # the bytes of the line, or a lone surrogate: not a payload
                try:
                    payload.encode("utf-8", "surrogateescape")
                except UnicodeEncodeError:
                    return None
        return obj

    def _item(self, obj: Any) -> Message | Event:
        """One line's object as a message or event; ValueError says what is wrong."""
        if not isinstance(obj, dict):
            raise ValueError(f"a {type(obj).__name__}, not an object with ts, topic and payload")
        if "ts" in obj:
            return self._jsonl(obj)
        if "tst" in obj:
            return self._mosquitto(obj)
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
            return Event(float(ts), kind, _utf8(str(obj.get("detail", ""))), count)
        topic = obj.get("topic")
        if not isinstance(topic, str):
            raise ValueError("'topic' is missing or not a string")
        topic = _utf8(topic)
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

    def _mosquitto(self, obj: dict[str, Any]) -> Message:
        tst = obj["tst"]
        if not isinstance(tst, str):
            raise ValueError(f"'tst' is {tst!r}, not an ISO 8601 time")
        ts = check_time(parse_tst(tst), "tst")
        topic = obj.get("topic")
        if not isinstance(topic, str):
            raise ValueError("'topic' is missing or not a string")
        topic = _utf8(topic)
        length = obj.get("payloadlen")
        if isinstance(length, bool) or not isinstance(length, int) or length < 0:
            raise ValueError(f"'payloadlen' is {length!r}, not a byte count")
        if length > MAX_PAYLOAD_BYTES:  # declared: nothing of that size is allocated
            raise ValueError(f"'payloadlen' {length} is over the {MAX_PAYLOAD_BYTES >> 20} MiB "
                             f"a recorded payload may take; skipped")
        if "payload" not in obj:
            raise ValueError("'payload' is missing")
        value = obj["payload"]
        if value is None:
            payload = b"" if length == 0 else b"null"
            if length:
                self.formats.add(FORMAT_MOSQUITTO_JJ)
        elif isinstance(value, str):
            raw = value.encode("utf-8", "surrogateescape")
            try:
                as_json = orjson.dumps(value)
            except orjson.JSONEncodeError:  # surrogate escapes: raw bytes, so -F %j
                as_json = b""
            if len(raw) == length and FORMAT_MOSQUITTO_JJ not in self.formats:
                payload = raw  # -F %j: the payload as it was
                self.formats.add(FORMAT_MOSQUITTO_J)
            elif len(as_json) == length or FORMAT_MOSQUITTO_JJ in self.formats:
                payload = as_json  # -F %J: the payload was a JSON string
                self.formats.add(FORMAT_MOSQUITTO_JJ)
            elif len(raw) < length:
                # -F %j cut the payload at a NUL byte; what followed it is unknown. A NUL can
                # never stand in JSON text (RFC 8259), so padding keeps the verdict right.
                payload = raw + b"\x00" * (length - len(raw))
                self._truncated += 1
                self.formats.add(FORMAT_MOSQUITTO_J)
            else:
                payload = raw
                self.formats.add(FORMAT_MOSQUITTO_J)
        else:
            try:
                payload = orjson.dumps(value)
            except orjson.JSONEncodeError:
                payload = json.dumps(value, separators=(",", ":")).encode()
            self.formats.add(FORMAT_MOSQUITTO_JJ)
        qos, retain = obj.get("qos", 0), obj.get("retain", 0)
        if qos not in (0, 1, 2) or isinstance(qos, bool):
            raise ValueError(f"'qos' is {qos!r}, not 0, 1 or 2")
        return Message(ts, topic, payload, int(qos), bool(retain))


def _utf8(text: str) -> str:
    """``text`` as UTF-8 can carry it: bytes that were not UTF-8 in the line (surrogate escapes)
    or lone surrogates shown as backslash escapes, which the topic rules then judge (TOPIC-008)
    and every report can write."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _not_json(e: Exception, line: bytes, number: int) -> str:
    if "recursion" in str(e).lower() or "depth" in str(e).lower():
        return f"not JSON: nested deeper than the {MAX_NESTING} levels a line may take"
    if _VERBOSE.match(line):
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

"""What ``mosquitto_sub`` prints that a recording reader must undo (``conformance.recording``):
its ``tst`` times (local time, a stray 'Z', then the offset), its lines that are not UTF-8,
with ``-F %j`` payloads cut at their first NUL byte, and ``-v`` lines without times (measured
with mosquitto_sub 2.0.11, ``tests/lint/test_recording.py``):

- ``-F %j`` prints ``{"tst": "2026-11-21T07:26:55.807087Z+0100", "topic": ..., "qos": 0,
  "retain": 0, "payloadlen": 7, "payload": "<text>"}``. ``tst`` is *local* time followed by a
  stray ``Z`` and then the real UTC offset. The payload is copied into the JSON string byte for
  byte (bytes that are not UTF-8 included, so the line itself is not UTF-8), and it is cut at
  the first NUL byte; ``payload`` is null for an empty payload.
- ``-F %J`` embeds the payload as a JSON value (re-serialised: whitespace is lost) and prints
  an *empty line* (plus an error on stderr) for a payload that is not JSON: that message, and
  its topic, are lost to the recording.
- ``-v`` prints ``TOPIC PAYLOAD`` per message (``(null)`` for an empty payload): no time. Such a
  line is told from JSON by its content (a topic with a '/', a space, the payload); its message
  gets the time the line was read, and the rules that need arrival times are not judged
  (``recording.UNTIMED_RULES``).
"""

from __future__ import annotations

import json
import re
import time
from datetime import datetime
from typing import Any

import orjson

from conformance.bounds import MAX_PAYLOAD_BYTES, check_time
from conformance.jsontext import dumps as json_text
from conformance.message import Message

MAX_EXAMINED_BYTES = 1 << 20
"""A payload is examined up to this (``validator.MAX_PAYLOAD_BYTES``, MSG-004)."""

FORMAT_MOSQUITTO_J = "mosquitto_sub -F %j"
FORMAT_MOSQUITTO_JJ = "mosquitto_sub -F %J"
FORMAT_MOSQUITTO_V = "mosquitto_sub -v"

# mosquitto_sub -v: TOPIC, one space, PAYLOAD (a topic holds no space and no wildcard).
VERBOSE = re.compile(rb"^([^\x00-\x20\x7f{}\[\]\"#+]*/[^\x00-\x20\x7f#+]*) (.*)$", re.DOTALL)

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


def cut_at_nul(raw: bytes, length: int) -> bytes:
    """The payload ``mosquitto_sub -F %j`` cut at a NUL byte: what is known of it, then one NUL
    (which JSON text never holds: MSG-002 fails on it, as on the payload itself). A payload
    declared longer than a message is examined (MSG-004) is padded to one byte past that
    bound, no further: the declared length is never materialised."""
    if length > MAX_EXAMINED_BYTES:
        return raw + bytes(MAX_EXAMINED_BYTES + 1 - len(raw)) if len(raw) <= MAX_EXAMINED_BYTES \
            else raw
    return raw + b"\x00"


def verbose_message(line: bytes) -> Message | None:
    """A ``mosquitto_sub -v`` line (``TOPIC PAYLOAD``) as a message read now, else None."""
    m = VERBOSE.match(line)
    if m is None:
        return None
    try:
        topic = m[1].decode("utf-8")  # a topic is UTF-8 text (MQTT 3.1.1, 1.5.3)
    except UnicodeDecodeError:
        return None
    # mosquitto_sub 2.0 prints an empty payload (a retained message cleared) as "(null)"
    return Message(time.time(), topic, b"" if m[2] == b"(null)" else m[2])


def loads_not_utf8(line: bytes, strict: bool = True) -> Any:
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
            obj["topic"] = utf8(obj["topic"])
        payload = obj.get("payload")
        if type(payload) is str:  # the bytes of the line, or a lone surrogate: not a payload
            try:
                payload.encode("utf-8", "surrogateescape")
            except UnicodeEncodeError:
                return None
    return obj


def utf8(text: str) -> str:
    """``text`` as UTF-8 can carry it: bytes that were not UTF-8 in the line (surrogate escapes)
    or lone surrogates shown as backslash escapes, which the topic rules then judge (TOPIC-008)
    and every report can write."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


class MosquittoLines:
    """Reads the lines of ``mosquitto_sub -F %j`` and ``-F %J`` (their ``tst`` says which) as
    messages; ``formats`` (the reader's, shared) gains the format each line shows,
    ``truncated`` counts the payloads cut at a NUL byte."""

    def __init__(self, formats: set[str]) -> None:
        self.formats = formats
        self.truncated = 0

    def message(self, obj: dict[str, Any]) -> Message:
        """One line's object as a message; ValueError says what is wrong."""
        tst = obj["tst"]
        if not isinstance(tst, str):
            raise ValueError(f"'tst' is {tst!r}, not an ISO 8601 time")
        ts = check_time(parse_tst(tst), "tst")
        topic = obj.get("topic")
        if not isinstance(topic, str):
            raise ValueError("'topic' is missing or not a string")
        topic = utf8(topic)
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
            payload = self._text_payload(value, length)
        else:
            payload = json_text(value)  # any depth a line may take, without recursion
            self.formats.add(FORMAT_MOSQUITTO_JJ)
        qos, retain = obj.get("qos", 0), obj.get("retain", 0)
        if qos not in (0, 1, 2) or isinstance(qos, bool):
            raise ValueError(f"'qos' is {qos!r}, not 0, 1 or 2")
        return Message(ts, topic, payload, int(qos), bool(retain))

    def _text_payload(self, value: str, length: int) -> bytes:
        """A payload written as a JSON string: the bytes themselves (-F %j), or a JSON string
        (-F %J), or cut at a NUL byte. Told per line (a -F %J line among -F %j lines must not
        turn them all into JSON strings): the lengths decide; only a line they leave open
        follows the format seen before it."""
        raw = value.encode("utf-8", "surrogateescape")
        try:
            as_json = orjson.dumps(value)
        except orjson.JSONEncodeError:  # surrogate escapes: raw bytes, so -F %j
            as_json = b""
        if len(raw) == length:
            self.formats.add(FORMAT_MOSQUITTO_J)
            return raw  # -F %j: the payload as it was
        if len(as_json) == length or (FORMAT_MOSQUITTO_JJ in self.formats
                                      and FORMAT_MOSQUITTO_J not in self.formats):
            self.formats.add(FORMAT_MOSQUITTO_JJ)
            return as_json  # -F %J: the payload was a JSON string
        self.formats.add(FORMAT_MOSQUITTO_J)
        if len(raw) < length:
            self.truncated += 1
            return cut_at_nul(raw, length)
        return raw

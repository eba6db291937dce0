"""JSON text of a parsed value without recursion (issue 26 §4: no recursion over input).

orjson writes at most 255 levels (and no string holding surrogates), and ``json.dumps``
recurses (a ``-F %J`` payload of 999 nested arrays raised RecursionError); a recording line
may nest ``bounds.MAX_NESTING`` levels.
``dumps`` writes what orjson can, and anything deeper with an explicit stack: compact, as
orjson writes it, so both give the same bytes where both can.
"""

from __future__ import annotations

import json
from typing import Any

import orjson

_OPEN_LIST, _CLOSE_LIST, _OPEN_DICT, _CLOSE_DICT, _COMMA, _COLON = (
    b"[", b"]", b"{", b"}", b",", b":")


def dumps(value: Any) -> bytes:
    """Compact JSON text of ``value`` (what ``orjson.loads`` returns: dict, list, str, int,
    float, bool, None), at any depth; orjson.JSONEncodeError for what JSON cannot hold."""
    try:
        return orjson.dumps(value)
    except orjson.JSONEncodeError:
        pass
    out: list[bytes] = []
    stack: list[Any] = [value]  # values to write, and bytes to write as they are
    while stack:
        item = stack.pop()
        kind = type(item)
        if kind is bytes:
            out.append(item)
        elif kind is list:
            out.append(_OPEN_LIST)
            stack.append(_CLOSE_LIST)
            for i in range(len(item) - 1, -1, -1):
                stack.append(item[i])
                if i:
                    stack.append(_COMMA)
        elif kind is dict:
            out.append(_OPEN_DICT)
            stack.append(_CLOSE_DICT)
            entries = list(item.items())
            for i in range(len(entries) - 1, -1, -1):
                key, member = entries[i]
                stack.append(member)
                stack.append(_scalar(key) + _COLON)
                if i:
                    stack.append(_COMMA)
        else:
            out.append(_scalar(item))
    return b"".join(out)


def _scalar(item: Any) -> bytes:
    """A number, string, true, false or null. A string read from a line that was not UTF-8
    holds surrogate escapes (``mosquitto_sub.loads_not_utf8``): written back as the bytes they
    stand for, so the payload is the one received; any other lone surrogate as an escape."""
    try:
        return orjson.dumps(item)
    except orjson.JSONEncodeError:
        if type(item) is not str:
            raise
    text = json.dumps(item, ensure_ascii=False)
    try:
        return text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:
        return json.dumps(item).encode()

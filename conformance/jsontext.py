"""JSON text of a parsed value without recursion (no recursion over input).

orjson writes at most 255 levels (and no string holding surrogates), and ``json.dumps``
recurses (a ``-F %J`` payload of 999 nested arrays raised RecursionError); a recording line
may nest ``bounds.MAX_NESTING`` levels.
``dumps`` writes what orjson can, and anything deeper with an explicit stack: compact, as
orjson writes it, so both give the same bytes where both can.
"""

from __future__ import annotations

import json
import re
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


_TOKEN = re.compile(rb'"(?:[^"\\]|\\.)*"|[\[\]{},]', re.S)
"""What decides nesting: strings (skipped whole: they may hold brackets), brackets and the
commas between members."""


def shallow_members(raw: bytes, max_depth: int) -> tuple[dict[str, Any], int] | None:
    """The members of the JSON object ``raw`` whose values nest at most ``max_depth - 1``
    levels, parsed, and how many members were left out for nesting deeper; None when ``raw``
    is not an object or a member cannot be read. Without recursion and without parsing what
    nests too deep: a message over the nesting bound is still judged on its top-level fields
    (what a reader can take from it safely)."""
    start = len(raw) - len(raw.lstrip())
    if raw[start:start + 1] != b"{":
        return None
    members: dict[str, Any] = {}
    left_out = 0
    depth = deepest = 0
    begin = start + 1
    for token in _TOKEN.finditer(raw, start):
        kind = token.group()[:1]
        if kind in (b"[", b"{"):
            depth += 1
            deepest = max(deepest, depth)
        elif kind in (b"]", b"}"):
            depth -= 1
        if depth == 1 and kind == b"," or depth == 0:
            member = raw[begin:token.start()]
            if not member.strip():
                if kind != b"}" or begin != start + 1:  # only '{}' has an empty member
                    return None
            elif deepest - 1 < max_depth:
                try:
                    members.update(orjson.loads(b"{" + member + b"}"))
                except orjson.JSONDecodeError:
                    return None
            else:
                left_out += 1
            begin, deepest = token.end(), 1
            if depth == 0:
                return (members, left_out) if not raw[token.end():].strip() else None
    return None

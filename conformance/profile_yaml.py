"""A profile file's text read as a YAML subset that cannot be forged into a bomb.

A profile decides verdicts, so what reads it refuses what YAML allows but a profile never
needs: anchors and aliases (billion laughs), tags (``!!python/object``, ``!!binary``), more
than ``MAX_BYTES`` bytes or ``MAX_DEPTH`` levels of nesting (the composer recurses), numbers
that are not finite (``.inf``, ``.nan``) or too large for a float, and text that is not UTF-8.
Each refusal is a one-line ``ProfileError`` naming the file, the line and the fix. The event
scan runs before anything is composed, so a refusal costs time proportional to the text read
so far, never to what an alias would expand to.
"""

from __future__ import annotations

import math
from typing import Any

import yaml

MAX_BYTES = 1024 * 1024
"""A profile larger than this is refused (the largest real one is about 4 KiB)."""
MAX_DEPTH = 32
"""Nesting deeper than this is refused (a profile needs 4: tasks, a task, params, a value)."""
MAX_NUMBER = 1e15
"""Numbers beyond this magnitude are refused: no profile value needs them, and a float of a
larger integer may overflow."""


MAX_NUMBER_CHARS = 40
"""A number written in more characters than this is refused before it is converted: Python
refuses an int of over 4300 digits with words of its own, and a base-60 integer of 3000 parts
('1:2:3:...') converts into one it cannot even print."""
_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")


class YamlRefused(ValueError):
    """What a profile's text may not contain, and how to fix it (without the file's name)."""


def decode(data: bytes) -> str:
    """The text of a profile file, which must be UTF-8."""
    if len(data) > MAX_BYTES:
        raise YamlRefused(f"{len(data)} bytes, over the {MAX_BYTES}-byte bound of a profile; "
                          f"a profile needs a few KiB")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise YamlRefused(f"line {line}: byte 0x{data[e.start]:02x} is not UTF-8; save the "
                          f"file as UTF-8") from None


def _line(event: yaml.Event) -> int:
    mark = event.start_mark
    return mark.line + 1 if mark is not None else 0


def _scan(text: str) -> None:
    """Refuse anchors, aliases, tags and deep nesting, from the parser's events (streamed:
    nothing is composed or expanded yet)."""
    depth = 0
    resolver = yaml.resolver.Resolver()  # what the loader will read a plain scalar as
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, yaml.AliasEvent):
            raise YamlRefused(f"line {_line(event)}: an alias (*{event.anchor}); write the "
                              f"value out instead (a profile takes no anchors or aliases)")
        if isinstance(event, yaml.NodeEvent) and event.anchor is not None:
            raise YamlRefused(f"line {_line(event)}: an anchor (&{event.anchor}); remove it "
                              f"(a profile takes no anchors or aliases)")
        if isinstance(event, (yaml.ScalarEvent, yaml.CollectionStartEvent)) \
                and event.tag is not None:
            raise YamlRefused(f"line {_line(event)}: a tag ({event.tag}); remove it (a "
                              f"profile takes plain values only)")
        if isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_NUMBER_CHARS \
                and event.implicit[0] and resolver.resolve(
                    yaml.ScalarNode, event.value, event.implicit) in _NUMBER_TAGS:
            raise YamlRefused(f"line {_line(event)}: a number written in {len(event.value)} "
                              f"characters; a profile's numbers are short (at most "
                              f"{MAX_NUMBER:g})")
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                raise YamlRefused(f"line {_line(event)}: nested deeper than {MAX_DEPTH} "
                                  f"levels; a profile needs a few")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


def _check_numbers(data: Any) -> None:
    """Refuse numbers that are not finite or too large (iterative: depth is bounded above,
    but no recursion over input all the same)."""
    stack: list[tuple[Any, str]] = [(data, "")]
    while stack:
        value, where = stack.pop()
        if isinstance(value, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k)) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, f"{where}[{i}]") for i, v in enumerate(value))
        elif isinstance(value, float) and not math.isfinite(value):
            raise YamlRefused(f"{where or 'the document'}: {value!r} is not a finite number; "
                              f"write a number")
        elif isinstance(value, (int, float)) and not isinstance(value, bool) \
                and abs(value) > MAX_NUMBER:
            raise YamlRefused(f"{where or 'the document'}: {value!r} is beyond "
                              f"{MAX_NUMBER:g}; write a smaller number")


def read(text: str) -> Any:
    """The document of a profile's ``text``, within the subset above; raises ``YamlRefused``
    (what is refused and how to fix it) or ``yaml.YAMLError`` (not YAML)."""
    if len(text) > MAX_BYTES:
        raise YamlRefused(f"{len(text)} characters, over the {MAX_BYTES} bound of a profile")
    _scan(text)
    data = yaml.safe_load(text)
    _check_numbers(data)
    return data

"""What the reference unit reads of a command on ``exec/command``: decoded within a bound
(``decode``), its com-uuid read even from a malformed one so the refusal can name it
(``readable_com_uuid``, EXEC-ROBUST-002), and, under variant strict, its fields held to the
spec's examples (``unlike_examples``). Never raises on hostile input."""

from __future__ import annotations

import re
from typing import Any

import orjson

MAX_COMMAND_BYTES = 1 << 20
"""A command larger than this is refused unread (no WARA-PS command comes near 1 MiB)."""
EXAMPLE_FIELDS = {  # variant strict: the fields of the spec's examples, per command
    "ping": frozenset({"com-uuid", "command", "sender"}),  # 12.2.1
    "signal-task": frozenset({"com-uuid", "command", "signal", "sender", "task-uuid"}),  # 12.2.2
    "start-task": frozenset({"com-uuid", "command", "execution-unit", "sender", "task",
                             "task-uuid"}),  # 10's examples (12.2.3)
    # 12.1 names query-status without an example: signal-task's fields but the signal.
    "query-status": frozenset({"com-uuid", "command", "sender", "task-uuid"}),
}
OPTIONAL_FIELDS = frozenset({"task-uuid"})
"""12.1: 'task-uuid should be optionally sent in start-task'; every other field of an example
is required by variant strict."""
_COM_UUID = re.compile(rb'"com-uuid"\s*:\s*"([^"\\\x00-\x1f]{1,128})"')


def decode(payload: bytes, size: int) -> tuple[Any, str | None]:
    """The command (``size`` bytes, ``payload`` its head when too large) as a dict with a
    string com-uuid, or what is wrong with it."""
    if size > MAX_COMMAND_BYTES:
        return None, f"a command of {size} bytes is larger than {MAX_COMMAND_BYTES}"
    try:
        msg = orjson.loads(payload)
    except orjson.JSONDecodeError as e:
        return None, f"the command is not valid JSON (UTF-8, RFC 8259): {str(e)[:120]}"
    if not isinstance(msg, dict):
        return msg, f"a command is a JSON object, not a JSON {type(msg).__name__}"
    com = msg.get("com-uuid")
    if not isinstance(com, str) or not com or len(com) > 128:
        return msg, "the command has no com-uuid string"
    return msg, None


def unlike_examples(command: str, msg: dict[str, Any], me: str) -> str | None:
    """Variant strict: why ``msg`` is not shaped like the spec's examples of ``command``, or
    None."""
    allowed = EXAMPLE_FIELDS[command]
    extra = sorted(set(msg) - allowed)
    if extra:
        return (f"field {str(extra[0])[:64]!r} is in no example of {command} (this unit reads "
                f"only {', '.join(sorted(allowed))})")
    optional = OPTIONAL_FIELDS if command == "start-task" else frozenset()
    missing = sorted(allowed - optional - set(msg))
    if missing:
        return f"{command} without {', '.join(missing)} (the spec's examples have it)"
    if command == "start-task":
        unit, task = msg["execution-unit"], msg["task"]
        if unit != me:
            return f"execution-unit {str(unit)[:64]!r} is not this unit ({me})"
        if not isinstance(task, dict) or set(task) != {"name", "params"}:
            return "task is {'name': ..., 'params': {...}} in every example of section 10"
    return None


def readable_com_uuid(payload: bytes, msg: Any) -> str | None:
    """A com-uuid that can be read from a malformed command, if any (EXEC-ROBUST-002)."""
    if isinstance(msg, dict):
        com = msg.get("com-uuid")
        return com if isinstance(com, str) and 0 < len(com) <= 128 else None
    if msg is not None:
        return None  # valid JSON but not an object: nothing to read it from
    m = _COM_UUID.search(payload, 0, 65536)
    if m is None:
        return None
    try:
        return m.group(1).decode("utf-8")
    except UnicodeDecodeError:
        return None

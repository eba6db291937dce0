"""A deserialized ROS message as the JSON value the API carries (7 -> 6; 13.3.2): a GeoPoint
tagged ``rostype`` (ERR-010), a std_msgs wrapper as its value, any other message as an object
of its fields without ``header``."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import orjson


def converter(kind: str, cls: type) -> Callable[[Any], Any]:
    """The JSON value of a deserialized message of class ``cls``: 7 -> 6, a GeoPoint -> a
    GeoPoint tagged rostype (ERR-010), a one-field ``data`` wrapper (std_msgs) -> its value,
    any other message -> an object of its fields without header. exec_command: its ``data``."""
    if kind == "exec_command":
        return lambda m: getattr(m, "data", None)
    names = field_names(cls)
    if {"latitude", "longitude", "altitude"} <= set(names):
        return lambda m: {"latitude": m.latitude, "longitude": m.longitude,
                          "altitude": m.altitude, "rostype": "GeoPoint"}
    if names == ["data"]:
        return lambda m: json_value(m.data)
    return json_value


_PLAIN = (float, int, str, bool)


def json_value(m: Any) -> Any:
    """A deserialized value as JSON: messages as objects of their fields without header,
    arrays as lists."""
    if type(m) in _PLAIN:
        return m
    if not dataclasses.is_dataclass(m):
        return m.tolist() if hasattr(m, "tolist") else m
    return {n: json_value(getattr(m, n)) for n in field_names(type(m)) if n != "header"}


def field_names(cls: type) -> list[str]:
    """The fields of a message class, in order."""
    return [f.name for f in dataclasses.fields(cls) if not f.name.startswith("__")]


def dumps(value: Any) -> bytes:
    """A JSON value as the payload's bytes."""
    # orjson writes NaN as null: ROS's "not measured" (BatteryState) is not invalid JSON.
    return orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY)

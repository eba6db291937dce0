"""Fuzz target: the option parsers a person's text goes through: the unit address
(``topics.UnitAddress.parse``), the topic filter and unit list (``lint.capture
.capture_options``), the broker URL (``client.BrokerURL.parse``), durations
(``cli.options.parse_duration``, every ``--duration``/``--max-duration``/``--observe``), and
the sim's rate (``sim --rate``, a float that must be positive and finite).

Invariant: each parser returns a value or raises its documented error (``TopicError``,
``CaptureOptionsError``, ``ValueError``) with a one-line message; a value returned is usable:
a unit address whose parts hold no MQTT wildcard, no '/', and whose reports' file name
(``reporting.bounds.file_stem``) fits a file system's 255 bytes; a filter MQTT accepts ('+' and '#' whole levels); a broker host
without empty labels, spaces, controls or URL delimiters (an IDN name may hold any letters); a duration finite and positive. Time proportional to the
input.
"""

from __future__ import annotations

import math
import re

import atheris

from conformance.cli.options import parse_duration
from conformance.client import BrokerURL
from conformance.lint.capture import CaptureOptionsError, capture_options
from conformance.reporting.bounds import file_stem
from conformance.topics import TopicError, UnitAddress
from fuzz.harness import Broken, one_line, within_time

NAME_BYTES = 255
"""A file name's length on Linux: the reports are named after a unit."""
_NOT_IN_HOST = re.compile(r"[\s/\\@#?\x00-\x1f\x7f]")
"""What no host name or address holds (an IDN name may hold letters of any script)."""
SEEDS = ["waraps/unit/air/simulation/dji0", "waraps/#", "mqtt://127.0.0.1:1883",
         "mqtts://broker.example:8883", "embedded", "10m", "1h30m", "90s", "0.5", "a/+/b"]


def prepare() -> None:
    """Nothing to build."""


def _unit(text: str) -> None:
    try:
        unit = UnitAddress.parse(text)
    except TopicError as e:
        one_line(e, "--unit error", shown=True)
        return
    for part in (unit.prefix, unit.agent_type, unit.role, unit.name):
        if not part or any(c in part for c in "/+#\x00"):
            raise Broken(f"unit address {text!r} accepted with part {part!r}")
    stem = f"{file_stem(unit.name)}-20261126-120000.json"  # as the session names its reports
    if len(stem.encode("utf-8", "surrogatepass")) > NAME_BYTES:
        raise Broken(f"unit address accepted whose reports' file name takes {len(stem)} chars")


def _filter(text: str) -> None:
    try:
        options = capture_options(None, topics=[text], need_broker=False)
    except CaptureOptionsError as e:
        one_line(e, "--topic error", shown=True)
        return
    for level in options.topics[0].split("/"):
        if ("+" in level or "#" in level) and level not in ("+", "#"):
            raise Broken(f"filter {text!r} accepted: a wildcard that is not a whole level")


def _broker(text: str) -> None:
    try:
        url = BrokerURL.parse(text, env={})
    except ValueError as e:
        one_line(e, "--broker error", shown=True)
        return
    labels = url.host.rstrip(".").split(".")
    if url.scheme != "embedded" and (_NOT_IN_HOST.search(url.host) or not all(labels)) \
            and ":" not in url.host:  # an IPv6 address has no dots
        raise Broken(f"broker {text!r} accepted with host {url.host!r}")
    if not 0 < url.port < 65536:
        raise Broken(f"broker {text!r} accepted with port {url.port}")


def _duration(text: str) -> None:
    try:
        seconds = parse_duration(text)
    except ValueError as e:
        one_line(e, "duration error", shown=True)
        return
    if not (math.isfinite(seconds) and seconds > 0):
        raise Broken(f"duration {text!r} accepted as {seconds!r}")



def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    which = fdp.ConsumeIntInRange(0, 3)
    text = (fdp.PickValueInList(SEEDS) if fdp.ConsumeProbability() < 0.2 else "") \
        + fdp.ConsumeUnicode(fdp.remaining_bytes())
    with within_time(len(data)):
        (_unit, _filter, _broker, _duration)[which](text)

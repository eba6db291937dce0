"""Fuzz target: ``lint --serve`` (``lint.serve.parse_address``), whether a bound address is
loopback (``lint.serve.bound_loopback``), and the metrics' label values (``lint.metrics
.label``).

Invariant: an address whose port is 0..65535, or a one-line ``ServeError``; a bound address is
loopback only when it parses as a loopback IP address; two different unit names never share a
label value, and a label value is printable and bounded. Time proportional to the input.
"""

from __future__ import annotations

import ipaddress

import atheris

from conformance.display import NAME_CHARS, printable
from conformance.lint.metrics import label
from conformance.lint.serve import ServeError, bound_loopback, parse_address
from fuzz.harness import Broken, one_line, within_time


def prepare() -> None:
    """Nothing to build."""


def _address(text: str) -> None:
    try:
        address = parse_address(text)
    except ServeError as e:
        one_line(e, "--serve error", shown=True)
        return
    if not 0 <= address.port <= 65535:
        raise Broken(f"--serve {text[:80]!r} accepted with port {address.port}")
    try:
        loopback = ipaddress.ip_address(address.host.partition("%")[0]).is_loopback
    except ValueError:
        loopback = False
    if bound_loopback([(address.host, address.port)]) != loopback:
        raise Broken(f"bound address {address.host[:80]!r} judged loopback wrongly")


def _labels(a: str, b: str) -> None:
    la, lb = label(a), label(b)
    if a != b and la == lb:
        raise Broken(f"two names share the label value {la[:80]!r}")
    for value in (la, lb):
        if printable(value) != value or len(value) > NAME_CHARS + 48:  # its length, a digest
            raise Broken(f"a label value that is not printable or bounded: {value[:80]!r}")


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    with within_time(len(data)):
        if fdp.ConsumeBool():
            _address(fdp.ConsumeUnicode(fdp.remaining_bytes()))
        else:
            _labels(fdp.ConsumeUnicode(fdp.ConsumeIntInRange(0, 400)),
                    fdp.ConsumeUnicode(fdp.remaining_bytes()))

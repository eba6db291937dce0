"""Fuzz target: the arena's environment (``client.BrokerURL.from_env``): ``WARAPS_BROKER``,
``WARAPS_PORT``, ``WARAPS_TLS_CONNECTION``, ``WARAPS_USERNAME``, ``WARAPS_PASSWORD``, each any
bytes (read as ``os.environ`` reads them: undecodable bytes as surrogate escapes).

Invariant: a broker URL or a one-line ``ValueError``; the environment fails closed: a URL is
plaintext (``mqtt``) only where the TLS variable says off (unset, 0, false, no, off), and
``mqtts`` only where it says on; the user name and password kept are UTF-8 text; an error
never holds the password. Time proportional to the input.
"""

from __future__ import annotations

from conformance.broker_url import TLS_OFF, TLS_ON, BrokerURL
from fuzz.harness import Broken, one_line, within_time

MARK = "pw-MARK-7d1c"
"""The start of every password: an error holding it shows the password."""
NAMES = ("WARAPS_BROKER", "WARAPS_PORT", "WARAPS_TLS_CONNECTION", "WARAPS_USERNAME",
         "WARAPS_PASSWORD")


def prepare() -> None:
    """Nothing to build."""


def test_one_input(data: bytes) -> None:
    values = data.split(b"\x00")
    env = {name: value.decode("utf-8", "surrogateescape")
           for name, value in zip(NAMES, values, strict=False) if value}
    if "WARAPS_PASSWORD" in env:  # a password no other variable, nor a default, can spell
        env["WARAPS_PASSWORD"] = MARK + env["WARAPS_PASSWORD"]
    with within_time(len(data)):
        try:
            url = BrokerURL.from_env(env)
        except ValueError as e:
            text = one_line(e, "environment error", shown=True)
            quoted = [env.get(n, "") for n in NAMES[:4]]  # what an error may quote
            if "WARAPS_PASSWORD" in env and MARK in str(e) and not any(
                    MARK in value for value in quoted):
                raise Broken("an error shows the password") from None
            del text
            return
    if url is None:
        return
    tls = env.get("WARAPS_TLS_CONNECTION", "").strip().lower()
    if (url.scheme == "mqtt") != (tls in TLS_OFF) or (url.scheme == "mqtts") != (tls in TLS_ON):
        raise Broken(f"WARAPS_TLS_CONNECTION={tls[:40]!r} connects with {url.scheme}")
    for credential in (url.username, url.password):
        if credential is not None:
            credential.encode("utf-8")  # UnicodeEncodeError escapes: the invariant broken

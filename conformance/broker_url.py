"""Where the broker is: ``BrokerURL``, parsed and checked (scheme, host, port, TLS files),
its user name and password only from the environment, never shown. Free of paho, so what
only names a broker (options, headers, reports) does not load the MQTT client."""

from __future__ import annotations

import ipaddress
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from urllib.parse import urlsplit

from conformance.display import printable, shorten
from conformance.masking import mask_password

SCHEMES = ("mqtt", "mqtts", "embedded")
LOOPBACK = ("127.", "localhost", "::1")


class BrokerError(RuntimeError):
    """The broker cannot be reached or refused us; the message says which and how to fix it."""


_LABEL = re.compile(r"[a-z0-9_](?:[a-z0-9_-]{0,61}[a-z0-9_])?", re.I)
"""One label of a host name (RFC 1123 2.1; '_' as resolvers accept it)."""


def _is_host(host: str) -> bool:
    """``host`` is an IP address or a host name a resolver can be asked about (labels of 1 to
    63 characters, 253 in all, after IDNA): ``a..b`` is not."""
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    try:
        name = host.encode("idna").decode("ascii")
    except UnicodeError:
        return False
    labels = name.removesuffix(".").split(".")
    return len(name) <= 253 and all(_LABEL.fullmatch(label) for label in labels)


TLS_ON = ("1", "true", "yes", "on")
TLS_OFF = ("", "0", "false", "no", "off")


def tls_connection(value: str) -> bool:
    """``WARAPS_TLS_CONNECTION`` read (any case, spaces around): on, off, or a ValueError
    naming the accepted values. Never a guess: 'ture' or 'required' read as off would connect
    in plaintext and send the password."""
    word = value.strip().lower()
    if word in TLS_ON or word in TLS_OFF:
        return word in TLS_ON
    raise ValueError(f"WARAPS_TLS_CONNECTION={shorten(printable(value), 40)!r} is neither on "
                     f"({', '.join(TLS_ON)}) nor off ({', '.join(w for w in TLS_OFF if w)}, or "
                     f"unset)")


def _credential(value: str | None, name: str) -> str | None:
    """A user name or password, None when unset or empty; ValueError when it is not UTF-8
    text (MQTT strings are UTF-8, 3.1.3.5), which never shows the value."""
    value = value or None
    if value is not None:
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:  # bytes that are not UTF-8 (os.environ's surrogate escapes)
            raise ValueError(f"{name} is not UTF-8 text (its value is not shown): MQTT sends "
                             f"user names and passwords as UTF-8; set it again as UTF-8") from None
    return value


@dataclass(frozen=True)
class BrokerURL:
    """Where the broker is: ``mqtt://host:port``, ``mqtts://host:port`` or ``embedded``.

    Username and password come from the environment (``WARAPS_USERNAME``,
    ``WARAPS_PASSWORD``), never from the URL or the command line; ``repr`` hides the password.
    """

    scheme: str
    host: str = "127.0.0.1"
    port: int = 1883
    username: str | None = None
    password: str | None = field(default=None, repr=False)
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    insecure: bool = False
    """mqtts without verifying the broker's certificate (a test broker with its own CA)."""

    @classmethod
    def parse(cls, text: str, env: Mapping[str, str] | None = None) -> BrokerURL:
        """Parse a broker URL; credentials are read from ``env`` (default ``os.environ``)."""
        env = os.environ if env is None else env
        text = text.strip()
        if text in ("embedded", "virtual"):  # virtual: the tests' in-memory double (sim/virtual)
            return cls(text)
        # What an error may say: never a password it wrongly has, a long URL excerpted.
        # Escaped first, then cut: an escaped code point may take 10 characters.
        shown = "'" + shorten(printable(mask_password(text, url=True)), 200) + "'"
        try:
            parts = urlsplit(text if "://" in text else f"mqtt://{text}")
        except ValueError:  # urllib's own words quote the whole host (NFKC, brackets)
            raise ValueError(f"broker URL {shown} is not a URL (for example "
                             f"mqtt://127.0.0.1:1883)") from None
        if parts.scheme not in ("mqtt", "mqtts"):
            raise ValueError(
                f"broker URL {shown}: scheme {parts.scheme!r} is not one of mqtt, mqtts, "
                f"embedded (for example mqtt://127.0.0.1:1883)")
        if parts.password:
            raise ValueError(
                f"broker URL {shown} carries a password: put it in WARAPS_PASSWORD instead, "
                f"so it never appears on a command line or in a report")
        try:
            port = parts.port or (8883 if parts.scheme == "mqtts" else 1883)
        except ValueError:
            raise ValueError(
                f"broker URL {shown}: the port is not a number from 1 to 65535") from None
        if not parts.hostname:
            raise ValueError(f"broker URL {shown} has no host (for example mqtt://127.0.0.1:1883)")
        if not _is_host(parts.hostname):
            raise ValueError(f"broker URL {shown}: {shorten(parts.hostname, 100)!r} is not a "
                             f"host name or an IP address (for example mqtt://127.0.0.1:1883)")
        return cls(parts.scheme, parts.hostname, port,
                   username=_credential(parts.username or env.get("WARAPS_USERNAME"),
                                        "the URL's user name" if parts.username
                                        else "WARAPS_USERNAME"),
                   password=_credential(env.get("WARAPS_PASSWORD"), "WARAPS_PASSWORD"))

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> BrokerURL | None:
        """The arena's own variables: WARAPS_BROKER, WARAPS_PORT, WARAPS_TLS_CONNECTION, ..."""
        env = os.environ if env is None else env
        host = env.get("WARAPS_BROKER")
        if not host:
            return None
        tls = tls_connection(env.get("WARAPS_TLS_CONNECTION", ""))
        port = env.get("WARAPS_PORT") or ("8883" if tls else "1883")
        if not (port.isascii() and port.isdigit()):
            raise ValueError(f"WARAPS_PORT={shorten(printable(port), 40)!r} is not a port "
                             f"number")
        return cls.parse(f"{'mqtts' if tls else 'mqtt'}://{host}:{port}", env)

    def with_tls_files(self, ca_file: str | None = None, cert_file: str | None = None,
                       key_file: str | None = None, insecure: bool = False) -> BrokerURL:
        return replace(self, ca_file=ca_file, cert_file=cert_file, key_file=key_file,
                       insecure=insecure)

    def tls_arguments(self) -> list[str]:
        """The command-line options that give this broker's TLS files and checks, shell-quoted
        (for a "repeat this run" line; '=' so that a path is never read as a test path)."""
        import shlex

        out = [f"{option}={shlex.quote(path)}" for option, path in (
            ("--ca-file", self.ca_file), ("--cert-file", self.cert_file),
            ("--key-file", self.key_file)) if path]
        return out + ["--tls-insecure"] if self.insecure else out

    @property
    def is_loopback(self) -> bool:
        return self.scheme in ("embedded", "virtual") or self.host.startswith(LOOPBACK)

    def __str__(self) -> str:
        if self.scheme in ("embedded", "virtual"):
            return self.scheme
        user = f"{self.username}@" if self.username else ""
        return f"{self.scheme}://{user}{self.host}:{self.port}"

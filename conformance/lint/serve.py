"""``lint --serve [HOST:]PORT``: the live fleet page, ``/metrics`` and ``/report.json``.

A small read-only WSGI application served by waitress (an established pure-Python production
server) in threads of its own. It only reads the latest ``fleetview.Snapshot`` (made in lint's
loop), never the Monitor: nothing it does changes the run, and nothing publishes.

- ``/``: a row per unit and commander, updated every second by a short poll of
  ``/fragment/fleet`` (the table made here, escaped by the templates: the page's script only
  swaps it in; a poll, not a stream, so no connection stays open);
- ``/unit/<address>``: a unit's findings with their evidence and their basis;
- ``/metrics``: Prometheus text (``lint.metrics``); ``/report.json``: the report as it stands.

Loopback unless a host is named (and then only asked for by a loopback name: a page elsewhere
cannot read it through DNS rebinding, 421); every method but GET and HEAD is refused (405);
requests are bounded by waitress's limits (headers 8 KiB, no body, 128 connections) and by
deadlines no trickle renews (a request whole within 5 s of its first part, a connection
without a request closed after 30 s).
"""

from __future__ import annotations

import functools
import ipaddress
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote

from conformance.display import NAME_CHARS, printable, shorten
from conformance.lint.fleetview import FleetView, Snapshot
from conformance.rules import CATALOGUE

LOOPBACK = "127.0.0.1"
MAX_PATH = 2048
"""The longest request path answered (a unit address is at most a few hundred characters)."""
LIMITS: dict[str, Any] = {"threads": 4, "connection_limit": 128,
                          "max_request_header_size": 8192, "max_request_body_size": 0,
                          "channel_timeout": 30, "cleanup_interval": 1,
                          "ident": "waraps-conformance", "asyncore_loop_timeout": 1}
"""waitress's bounds (its adjustments): the page, its fragments and scrapes are small GETs.
Room for 128 connections, the deadlines below checked every second: a few dozen slow clients
leave room for a scrape."""
HEADER_SECONDS = 5.0
"""A request must arrive whole within this many seconds of when it was first seen in part
(a GET is one packet): a connection that trickles a header line every 10 s is closed however
often it sends (slowloris), where waitress's idle timeout is renewed by every byte."""
IDLE_SECONDS = 30.0
"""A connection that holds no request is closed this long after it was last seen holding one
(or opened), whatever it sends that is not a whole request."""
_WAITING = "_waraps_waiting"
MAX_ROWS_SHOWN = 500
"""Rows on the fleet page, worst first (a page of 4096 units would be some 6 MB a second)."""
MAX_CACHED = 16
"""Answers kept per snapshot (pages of the units being looked at, /metrics)."""
STATIC = {"fleet.css": "text/css; charset=utf-8", "fleet.js": "text/javascript; charset=utf-8"}
HEADERS = [("X-Content-Type-Options", "nosniff"), ("Cache-Control", "no-store"),
           ("Referrer-Policy", "no-referrer"),
           # Nothing from outside the package, no inline script: a name that slipped through
           # escaping still could not run.
           ("Content-Security-Policy", "default-src 'none'; script-src 'self'; "
            "style-src 'self'; img-src 'self' data:; connect-src 'self'; "
            "frame-ancestors 'none'; base-uri 'none'; form-action 'none'")]


class ServeError(ValueError):
    """A ``--serve`` value that cannot be used; the message says why."""


@dataclass(frozen=True)
class Address:
    host: str
    port: int

    @property
    def loopback(self) -> bool:
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return self.host == "localhost"


def parse_address(text: str) -> Address:
    """``PORT`` (loopback), ``HOST:PORT`` or ``[V6]:PORT``; ServeError names the form."""
    host, sep, port = text.strip().rpartition(":")
    if not sep:
        host = LOOPBACK
    host = host.strip("[]") or LOOPBACK
    # ASCII digits only: '²' is a digit to str.isdigit and no number to int().
    if not (port.isascii() and port.isdigit() and len(port) <= 5) or int(port) > 65535:
        raise ServeError(f"--serve {shorten(printable(text), 80)!r}: use PORT (on 127.0.0.1), "
                         f"or HOST:PORT to serve on another address, e.g. --serve 8080")
    return Address(host, int(port))


def warnings(address: Address, loopback: bool | None = None) -> list[str]:
    """What the header of every page (and the terminal) says about where it is served;
    ``loopback``: what the bound socket says (else the address's spelling)."""
    if address.loopback if loopback is None else loopback:
        return []
    return [f"served on {printable(address.host)}: anyone who can reach this address can read "
            f"this page (--serve PORT serves on loopback only)"]


def bound_loopback(listening: list[tuple[str, int]]) -> bool:
    """Whether every address the server is bound to is a loopback one: decided from the bound
    sockets, not from how the host was spelt ('127.1', 'LOCALHOST', '0x7f000001' all bind
    127.0.0.1, and must keep the Host guard on)."""
    try:
        return bool(listening) and all(
            ipaddress.ip_address(str(host).partition("%")[0]).is_loopback
            for host, _ in listening)
    except ValueError:
        return False


LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})


def _host_name(host: str) -> str:
    """The name in a Host header, without its port (``[::1]:8080`` -> ``::1``)."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:].partition("]")[0]
    return host.rpartition(":")[0] if host.count(":") == 1 else host


def _escape_unit(unit: str) -> str:
    return quote(unit, safe="/")


@functools.cache
def environment() -> Any:
    """The pages' templates (``lint/templates``), autoescape on: wire text is escaped."""
    from jinja2 import Environment, PackageLoader, StrictUndefined

    env = Environment(loader=PackageLoader("conformance.lint", "templates"), autoescape=True,
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                      finalize=_finalize)
    env.filters.update(unit_url=_escape_unit, clock=_clock, hz=_hz, ago=_ago, short=_short,
                       breakable=_breakable)
    from conformance.lint.plots import sparkline
    from conformance.lint.rows import STATUS_WORDS

    env.globals.update(sparkline=sparkline, rule_of=_rule_of, max_rows=MAX_ROWS_SHOWN,
                       status_words=STATUS_WORDS)
    return env


def _finalize(value: Any) -> Any:
    if type(value) in (int, float) or hasattr(value, "__html__"):  # numbers: most of a page
        return value
    return "" if value is None else printable(shorten(value))


def _short(value: Any, limit: int = NAME_CHARS) -> str:
    return printable(shorten(value, limit))


def _breakable(value: Any, limit: int = NAME_CHARS) -> Any:
    """A unit address (escaped) that wraps after a '/', not inside a word."""
    from markupsafe import Markup

    return Markup("/<wbr>").join(_short(value, limit).split("/"))


def _clock(t: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) if t is not None else ""


def _ago(t: float | None, now: float | None) -> str:
    if t is None:
        return "never"
    if now is None:
        return _clock(t)
    d = max(0.0, now - t)
    return "now" if d < 1 else f"{d:.0f} s ago" if d < 120 else f"{d / 60:.0f} min ago"


def _hz(rate: float | None) -> str:
    return "–" if rate is None else f"{rate:.3g} Hz"


def _rule_of(rule_id: str) -> Any:
    return CATALOGUE.get(rule_id)


class App:
    """The WSGI application over ``view``'s snapshots. ``header``: lines for the top of
    every page (the address, a warning when it is not loopback)."""

    def __init__(self, view: FleetView, header: Iterable[str] = (),
                 hosts: frozenset[str] | None = None) -> None:
        self.view = view
        self.header = tuple(header)
        self.hosts = hosts
        """Host names a request may name (None: any); on loopback only loopback names, so
        that a web page elsewhere cannot read the fleet through DNS rebinding."""
        self._made: dict[tuple[int, str], tuple[str, bytes, str]] = {}
        self._lock = threading.Lock()

    def __call__(self, environ: dict[str, Any], start: Callable[..., Any]) -> list[bytes]:
        method = environ.get("REQUEST_METHOD", "")
        if method not in ("GET", "HEAD"):
            return self._send(start, "405 Method Not Allowed", b"read-only: GET only\n",
                              "text/plain; charset=utf-8", [("Allow", "GET, HEAD")])
        if self.hosts is not None and _host_name(environ.get("HTTP_HOST", "")) not in self.hosts:
            return self._send(start, "421 Misdirected Request",
                              b"ask for this page by a loopback address\n")
        raw = environ.get("PATH_INFO", "") or "/"
        if len(raw) > MAX_PATH:
            return self._send(start, "414 URI Too Long", b"path too long\n")
        # WSGI hands the path as latin-1 text of its bytes: the unit names are UTF-8.
        path = raw.encode("latin-1", "replace").decode("utf-8", "replace")
        status, body, ctype = self.route(path)
        return self._send(start, status, body, ctype, head=method == "HEAD")

    def route(self, path: str) -> tuple[str, bytes, str]:
        """The answer to GET ``path``: made once per snapshot and path, whoever asks (each
        viewer polls every second; a page of 200 units takes some 100 ms to make)."""
        if path == "/report.json" or path.startswith("/static/"):
            return self._route(path, self.view.snapshot)
        with self._lock:
            snap = self.view.snapshot
            key = (snap.version, path)
            made = self._made.get(key)
            if made is None:
                made = self._route(path, snap)
                if len(self._made) >= MAX_CACHED:
                    self._made = {k: v for k, v in self._made.items() if k[0] == snap.version}
                    if len(self._made) >= MAX_CACHED:
                        self._made.clear()
                self._made[key] = made
            return made

    def _route(self, path: str, snap: Snapshot) -> tuple[str, bytes, str]:
        html = "text/html; charset=utf-8"
        if path == "/":
            return "200 OK", self._page("fleet.html.j2", snap), html
        if path == "/fragment/fleet":
            return "200 OK", self._page("fleet_rows.html.j2", snap), html
        if path.startswith(("/unit/", "/fragment/unit/")):
            unit = path.split("/unit/", 1)[1]
            row = snap.row(unit)
            if row is None:
                return "404 Not Found", self._page("missing.html.j2", snap, unit=unit), html
            name = "unit.html.j2" if path.startswith("/unit/") else "unit_body.html.j2"
            return "200 OK", self._page(name, snap, row=row), html
        if path == "/metrics":
            from conformance.lint.metrics import CONTENT_TYPE, exposition

            return "200 OK", exposition(lambda: snap), CONTENT_TYPE
        if path == "/report.json":
            data = self.view.report_json()
            if data is None:
                return "503 Service Unavailable", b"no report yet: retry\n", "text/plain"
            return "200 OK", data, "application/json"
        if path.startswith("/static/") and path[8:] in STATIC:
            from importlib.resources import files

            body = files("conformance.lint").joinpath("templates", path[8:]).read_bytes()
            return "200 OK", body, STATIC[path[8:]]
        return "404 Not Found", b"not found\n", "text/plain; charset=utf-8"

    def _page(self, name: str, snap: Snapshot, **extra: Any) -> bytes:
        template = environment().get_template(name)
        return template.render(s=snap, header=self.header, **extra).encode("utf-8")

    @staticmethod
    def _send(start: Callable[..., Any], status: str, body: bytes,
              ctype: str = "text/plain; charset=utf-8",
              extra: list[tuple[str, str]] | None = None, head: bool = False) -> list[bytes]:
        start(status, [("Content-Type", ctype), ("Content-Length", str(len(body))),
                       *HEADERS, *(extra or [])])
        return [b""] if head else [body]


class Server:
    """waitress serving ``App`` in a thread; ``stop()`` closes every connection."""

    def __init__(self, view: FleetView, address: Address) -> None:
        import logging

        from waitress.server import create_server

        # 'Task queue depth is N' (a few viewers at once) is no news for the person at the
        # terminal, whose scorecard it would break into.
        logging.getLogger("waitress.queue").setLevel(logging.ERROR)
        self.address = address
        self.app = App(view)  # its header and Host guard once bound: from what was bound
        try:
            self._server = create_server(self.app, host=address.host, port=address.port,
                                         **LIMITS)
        except OSError as e:
            raise ServeError(f"--serve {printable(address.host)}:{address.port}: "
                             f"{e.strerror or e}") from e
        except ValueError as e:  # waitress: a host that resolves to nothing
            raise ServeError(f"--serve {printable(address.host)}:{address.port}: "
                             f"{printable(str(e))}") from e
        server: Any = self._server
        listening = list(getattr(server, "effective_listen", None)
                         or [(server.effective_host, server.effective_port)])
        self.loopback = bound_loopback(listening)
        self.app.header = tuple(warnings(address, self.loopback))
        self.app.hosts = (LOOPBACK_NAMES | {address.host.lower()} | {
            str(h).lower() for h, _ in listening}) if self.loopback else None
        self.port = int(listening[0][1])
        for one in getattr(server, "map", {}).values() or [server]:
            if hasattr(one, "active_channels"):  # each listening socket's server
                one.maintenance = functools.partial(_close_the_slow, one)
        self._thread = threading.Thread(target=self._server.run, name="lint-serve", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.address.host}]" if ":" in self.address.host else self.address.host
        return f"http://{host}:{self.port}/"

    def start(self) -> Server:
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Close the listening socket and every connection (in the server's own loop, through
        its trigger), then stop the worker threads; bounded by ``timeout`` seconds."""
        from waitress import wasyncore

        # Its own loop's trigger and socket map are not in waitress's typed interface.
        server: Any = self._server
        server.task_dispatcher.shutdown(cancel_pending=True, timeout=timeout)
        try:
            server.trigger.pull_trigger(lambda: wasyncore.close_all(server._map))
        except OSError:  # already closed
            pass
        self._thread.join(timeout)


def _close_the_slow(server: Any, now: float) -> None:
    """waitress's maintenance (every ``cleanup_interval``), with deadlines a trickle cannot
    renew: a request seen in part for ``HEADER_SECONDS``, or no request for ``IDLE_SECONDS``,
    closes its connection; one being answered is left alone."""
    for channel in list(server.active_channels.values()):
        if channel.requests:  # being answered: its time is the answer's
            channel.__dict__.pop(_WAITING, None)
            continue
        partial = channel.request
        state = id(partial) if partial is not None else None
        seen = channel.__dict__.get(_WAITING)
        if seen is None or seen[0] != state:
            seen = channel.__dict__[_WAITING] = (state, now)
        if now - seen[1] > (HEADER_SECONDS if partial is not None else IDLE_SECONDS):
            channel.will_close = True


class Watched:
    """A scorecard that also hands the linter to the fleet view on each ``update`` (before the
    scorecard takes the fresh violations); everything else is the scorecard's."""

    def __init__(self, scorecard: Any, view: FleetView) -> None:
        self._scorecard = scorecard
        self._view = view
        view.title = scorecard.title

    def update(self, linter: Any, *, elapsed: float | None = None,
               connected: bool | None = None, force: bool = False) -> None:
        self._view.observe(linter, connected=connected, force=force)
        self._scorecard.update(linter, elapsed=elapsed, connected=connected, force=force)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._scorecard, name)


class Serving:
    """``lint --serve`` around a lint run: starts the server (its URL on ``out``), and at the
    end, once the last snapshot is made, keeps serving ``linger`` seconds (None: until
    Ctrl-C) before it stops. A run that ended without a final snapshot does not linger."""

    def __init__(self, address: Address, linger: float | None, out: Any, *, live: bool) -> None:
        self.view = FleetView("", live=live)
        self.linger = linger
        self.out = out
        self.server = Server(self.view, address)

    def __enter__(self) -> Serving:
        self.server.start()
        for line in self.server.app.header:
            print(f"warning: {line}", file=self.out)
        print(f"serving {printable(self.server.url)} (the fleet page; /metrics, /report.json; read-only)",
              file=self.out, flush=True)
        return self

    def watch(self, scorecard: Any) -> Watched:
        return Watched(scorecard, self.view)

    def __exit__(self, *exc: object) -> None:
        try:
            if exc[0] is None and self.view.snapshot.finished and self.linger != 0:
                self._linger()
        finally:
            self.server.stop()

    def _linger(self) -> None:
        until = "until Ctrl-C" if self.linger is None else f"for {self.linger:g} s"
        print(f"serving the final fleet page on {printable(self.server.url)} {until}", file=self.out,
              flush=True)
        end = None if self.linger is None else time.monotonic() + self.linger
        try:
            while end is None or time.monotonic() < end:
                time.sleep(0.2 if end is None else max(0.0, min(0.2, end - time.monotonic())))
        except KeyboardInterrupt:
            pass

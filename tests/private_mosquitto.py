"""A Mosquitto of the test's own: a free loopback port, its own config, optional users and ACL,
TLS with a self-signed certificate, and a log to read. ``stop()`` and ``start()`` again on the same
port drop every connection (a broker that goes down and comes back).

Import it from any test: ``from private_mosquitto import PrivateMosquitto`` (tests/ is on
sys.path through tests/conftest.py).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

from machine import deadline

from conformance.broker import free_port
from conformance.client import BrokerURL, MqttClient


def listening(port: int, host: str = "127.0.0.1") -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False


class PrivateMosquitto:
    """Mosquitto on 127.0.0.1:<free port>. ``users`` (name -> password) turns anonymous access
    off; ``acl`` is the text of an ACL file; ``tls`` makes it speak only TLS with a self-signed
    certificate for 127.0.0.1 (``ca_file``); ``extra`` is appended to the config verbatim."""

    def __init__(self, workdir: Path, *, users: dict[str, str] | None = None,
                 acl: str | None = None, tls: bool = False, extra: str = "",
                 max_queued_messages: int = 1000) -> None:
        self.exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.dir = workdir
        self.dir.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        self.log = self.dir / f"mosquitto-{self.port}.log"
        self.users = dict(users or {})
        lines = [f"listener {self.port} 127.0.0.1", f"log_dest file {self.log}", "log_type all",
                 "persistence false", f"max_queued_messages {max_queued_messages}"]
        if self.users:
            passwd = self.dir / "passwd"
            passwd.write_text("")
            for user, pw in self.users.items():
                subprocess.run(["mosquitto_passwd", "-b", str(passwd), user, pw], check=True,
                               capture_output=True)
            lines += ["allow_anonymous false", f"password_file {passwd}"]
        elif "allow_anonymous" not in extra:
            lines.append("allow_anonymous true")
        if acl is not None:
            (self.dir / "acl").write_text(acl)
            lines.append(f"acl_file {self.dir / 'acl'}")
        self.tls = tls
        if tls:
            self.ca_file = self.dir / "cert.pem"
            key = self.dir / "key.pem"
            subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes",
                            "-keyout", str(key), "-out", str(self.ca_file), "-days", "1",
                            "-subj", "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1"],
                           check=True, capture_output=True)
            lines += [f"certfile {self.ca_file}", f"keyfile {key}"]
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            lines.append("user root")  # else it drops to 'mosquitto', which cannot read our files
        self.conf = self.dir / f"mosquitto-{self.port}.conf"
        self.conf.write_text("\n".join(lines) + "\n" + extra)
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://127.0.0.1:{self.port}"

    def start(self, timeout: float = 10.0) -> PrivateMosquitto:
        self.proc = subprocess.Popen([self.exe, "-c", str(self.conf)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        due = time.monotonic() + deadline(timeout)
        while not listening(self.port):
            if self.proc.poll() is not None or time.monotonic() > due:
                raise RuntimeError(f"mosquitto did not start: {self.log_text()[-2000:]}")
            time.sleep(0.02)  # polling a port that is about to open: bounded by the deadline
        return self

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.thaw()  # a frozen process would not act on SIGTERM
            self.proc.terminate()
            try:
                self.proc.wait(deadline(10))
            except subprocess.TimeoutExpired:  # seen once at a load of 8: never left behind
                self.proc.kill()
                self.proc.wait(10)
        self.proc = None

    def freeze(self) -> None:
        """Stop the broker's process (SIGSTOP) without closing a socket: a broker that stalls."""
        assert self.proc is not None and self.proc.poll() is None
        os.kill(self.proc.pid, signal.SIGSTOP)

    def thaw(self) -> None:
        """Let a frozen broker run again (SIGCONT): it delivers what it held, in a burst."""
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGCONT)

    def log_text(self) -> str:
        return self.log.read_text(errors="replace") if self.log.exists() else ""

    def env(self, user: str) -> dict[str, str]:
        """The environment that gives a client ``user``'s credentials (never argv)."""
        return {**os.environ, "WARAPS_USERNAME": user, "WARAPS_PASSWORD": self.users[user]}

    def client(self, user: str | None = None) -> MqttClient:
        """A connected client that may publish anywhere (the test's own traffic)."""
        url = BrokerURL.parse(self.url, self.env(user) if user else {})
        if self.tls:
            url = url.with_tls_files(ca_file=str(self.ca_file))
        return MqttClient(url, may_publish=lambda t: True).connect()

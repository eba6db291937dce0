"""The local Mosquitto that every test process on the machine shares (127.0.0.1:1883): started
when none is listening, stopped by the last process that used it, and only if one of them
started it (a daemon that was already running is left alone).

The processes are xdist workers or other test runs: the first to need a broker may be done long
before the others. Each one registers under a run folder (one file named by its pid); the folder
is locked while a process joins or leaves, and holds the pid of the daemon started here.
Linux only (``fcntl``, ``/proc``), like the rest of the suite's brokers.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

RUN = Path(tempfile.gettempdir()) / "waraps-conformance-mosquitto"


def listening(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


@contextlib.contextmanager
def _locked(run: Path) -> Iterator[Path]:
    (run / "users").mkdir(parents=True, exist_ok=True)
    with (run / "lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        yield run


def _start(run: Path, host: str, port: int) -> None:
    """A daemon on ``host:port`` that writes its pid into ``run``."""
    exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not os.path.exists(exe):
        return
    pid_file, conf = run / "mosquitto.pid", run / "mosquitto.conf"
    pid_file.unlink(missing_ok=True)
    lines = [f"listener {port} {host}", "allow_anonymous true", "persistence false",
             f"pid_file {pid_file}"]
    if os.geteuid() == 0:
        lines.append("user root")  # else it drops to 'mosquitto', which cannot write the pid
    conf.write_text("\n".join(lines) + "\n")
    subprocess.run([exe, "-d", "-c", str(conf)], check=False)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and not (listening(host, port) and pid_file.exists()):
        time.sleep(0.05)  # polling a port that is about to open: bounded by the deadline


def _stop(run: Path) -> None:
    """Stop the daemon ``_start`` started, if it still runs."""
    pid_file = run / "mosquitto.pid"
    try:
        pid = int(pid_file.read_text())
    except (OSError, ValueError):
        return  # none was started here
    pid_file.unlink()
    try:  # the pid is ours only while its command line names our config (pids are reused)
        ours = str(run / "mosquitto.conf").encode() in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return  # gone already
    if ours:
        os.kill(pid, signal.SIGTERM)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and alive(pid):
            time.sleep(0.05)  # a daemon is not our child: no wait(); bounded by the deadline


@contextlib.contextmanager
def shared_mosquitto(host: str = "127.0.0.1", port: int = 1883,
                     run: Path = RUN) -> Iterator[bool]:
    """Use the Mosquitto on ``host:port`` in the block, starting it if none listens; whether it
    listens. On leaving, the last user (users that died without leaving do not count) stops
    the one started here."""
    me = run / "users" / f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    with _locked(run):
        me.touch()
        if not listening(host, port):
            _start(run, host, port)
    try:
        yield listening(host, port)
    finally:
        with _locked(run):
            me.unlink(missing_ok=True)
            users = 0
            for user in (run / "users").iterdir():
                pid = user.name.split("-")[0]
                if pid.isdigit() and alive(int(pid)):
                    users += 1
                else:
                    user.unlink(missing_ok=True)
            if not users:
                _stop(run)

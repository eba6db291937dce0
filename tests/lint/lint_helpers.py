"""Helpers for the linter's tests (imported as ``lint_helpers``): synthetic fleet traffic with controlled times, recordings,
and running ``waraps-conformance lint`` in-process."""

from __future__ import annotations

import io
import json
import subprocess
import time
import uuid
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import orjson
from machine import deadline
from private_mosquitto import PrivateMosquitto as SharedMosquitto

from conformance.cli.lint import main as lint_main
from conformance.client import Message, MqttClient
from conformance.recording import Event, RecordingWriter

T0 = 1_763_700_000.0  # a fixed start: recordings replay at their recorded times


def unit_traffic(prefix: str, name: str, *, seconds: float, t0: float = T0, rate: float = 1.0,
                 agent_type: str = "air", heartbeat_every: int = 1, agent_uuid: str | None = None,
                 skip: tuple[float, float] | None = None) -> list[Message]:
    """The messages of one conformant unit (heartbeat, the three info messages' two it claims,
    the four mandatory sensors), every ``1/rate`` seconds for ``seconds``.

    Faults: ``heartbeat_every=2`` sends only every second heartbeat while declaring ``rate``
    (HB-003); ``skip=(a, b)`` sends nothing between ``t0+a`` and ``t0+b``.
    """
    base = f"{prefix}/unit/{agent_type}/simulation/{name}"
    uid = agent_uuid or str(uuid.uuid4())
    out: list[Message] = []
    for i in range(int(seconds * rate)):
        t = t0 + i / rate
        if skip and skip[0] <= t - t0 < skip[1]:
            continue
        payloads: list[tuple[str, object]] = []
        if i % heartbeat_every == 0:
            payloads.append(("heartbeat", {
                "agent-type": agent_type, "agent-uuid": uid, "levels": ["sensor", "direct execution"],
                "name": name, "rate": rate, "stamp": t, "type": "HeartBeat"}))
        payloads += [
            ("sensor_info", {"name": name, "rate": rate, "agent-uuid": uid, "stamp": t,
                             "sensor-data-provided": ["position", "heading", "course", "speed"],
                             "type": "SensorInfo"}),
            ("direct_execution_info", {
                "name": name, "rate": rate, "agent-uuid": uid, "stamp": t,
                "type": "DirectExecutionInfo", "tasks-executing": [],
                "tasks-available": [{"name": "move-to",
                                     "signals": ["$abort", "$enough", "$pause", "$continue"]}]}),
            ("sensor/position", {"latitude": 58.3945 + i * 1e-6, "longitude": 15.5645,
                                 "altitude": 100.0, "rostype": "GeoPoint"}),
            ("sensor/heading", 90.0), ("sensor/course", 90.0), ("sensor/speed", 0.1),
        ]
        for k, (sub, payload) in enumerate(payloads):
            out.append(Message(t + 0.005 * k, f"{base}/{sub}", orjson.dumps(payload)))
    return out


def fleet_traffic(prefix: str, names: Iterable[str], **kw: object) -> list[Message]:
    """Several conformant units' traffic merged in arrival order."""
    msgs = [m for n in names for m in unit_traffic(prefix, n, **kw)]  # type: ignore[arg-type]
    return sorted(msgs, key=lambda m: m.time)


def write_recording(path: Path, items: Iterable[Message | Event]) -> Path:
    with path.open("wb") as f:
        w = RecordingWriter(f)
        for item in sorted(items, key=lambda i: i.time):
            w.write(item)
    return path


@dataclass
class LintRun:
    code: int
    out: str
    report: dict | None
    reports: list[Path]


def run_lint(args: list[str], reports_dir: Path, stdin: bytes | None = None) -> LintRun:
    """``waraps-conformance lint ARGS --plain --reports-dir DIR`` in-process; its exit code,
    output, and the JSON report if one was written."""
    out = io.StringIO()
    code = lint_main([*args, "--plain", "--reports-dir", str(reports_dir)], stdout=out,
                     stdin=io.BytesIO(stdin) if stdin is not None else None)
    reports = sorted(reports_dir.glob("*")) if reports_dir.exists() else []
    js = [p for p in reports if p.suffix == ".json"]
    report = json.loads(js[-1].read_text()) if js else None
    return LintRun(code, out.getvalue(), report, reports)


def failed_rules(report: dict, unit: str) -> set[str]:
    return {r for r, res in report["units"][unit]["rules"].items() if res["verdict"] == "fail"}


def verdicts(report: dict, unit: str) -> dict[str, str]:
    return {r: res["verdict"] for r, res in report["units"][unit]["rules"].items()}


# --- a Mosquitto of the test's own ---------------------------------------------------------------

class PrivateMosquitto(SharedMosquitto):
    """The shared private Mosquitto with two users: ``fleet`` may publish, ``linter`` may only
    read (its ACL), so a test can prove the linter never publishes."""

    USERS = {"fleet": "fleet-pw", "linter": "linter-pw"}

    def __init__(self, workdir: Path, *, max_queued_messages: int = 1000, tls: bool = False) -> None:
        super().__init__(workdir, users=self.USERS, tls=tls,
                         acl="user fleet\ntopic readwrite #\n\nuser linter\ntopic read #\n",
                         max_queued_messages=max_queued_messages)

    def client(self, user: str | None = "fleet") -> MqttClient:
        return super().client(user)


class Process:
    """A console-script subprocess whose output lines are collected by a thread, so a test
    can wait for a line with a deadline."""

    def __init__(self, argv: list[str], env: dict[str, str] | None = None) -> None:
        import queue
        import sys
        import threading

        self.lines: list[str] = []
        self._new = threading.Condition()
        self.proc = subprocess.Popen([sys.executable, "-m", "conformance.cli", *argv],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     env=env, text=True, bufsize=1)
        del queue

        def pump() -> None:
            assert self.proc.stdout is not None
            for line in self.proc.stdout:
                with self._new:
                    self.lines.append(line.rstrip("\n"))
                    self._new.notify_all()

        self._thread = threading.Thread(target=pump, daemon=True)
        self._thread.start()

    @property
    def output(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, text: str, timeout: float = 15.0) -> str:
        """The first output line containing ``text``; AssertionError after ``timeout`` s (on
        an idle machine: more on a busy one, ``machine.deadline``)."""
        timeout = deadline(timeout)
        due = time.monotonic() + timeout
        with self._new:
            while True:
                for line in self.lines:
                    if text in line:
                        return line
                left = due - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._thread.is_alive()):
                    raise AssertionError(f"no line with {text!r} within {timeout} s; output:\n"
                                         f"{self.output}")
                self._new.wait(min(left, 0.5))

    def interrupt(self, timeout: float = 30.0, sig: int = 2) -> int:
        """Ctrl-C (or signal ``sig``: 15, SIGTERM, as a service manager stops it), then the
        exit code, within ``timeout`` s (more on a busy machine: the reports are written and
        synced to disk on the way out)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        due = deadline(timeout)
        try:
            code = self.proc.wait(due)
        except subprocess.TimeoutExpired:
            self.kill()  # never left behind, serving or subscribed, after the test
            raise AssertionError(f"still running {due:.0f} s after signal {sig} (killed); "
                                 f"output:\n{self.output}") from None
        self._thread.join(5)
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)


def publish_live(client: MqttClient, messages: list[Message], *, speed: float = 1.0) -> None:
    """Publish ``messages`` paced at their own relative times (a unit's schedule, not a wait)."""
    if not messages:
        return
    t0, start = messages[0].time, time.monotonic()
    for m in messages:
        due = start + (m.time - t0) / speed
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        client.publish(m.topic, m.payload, qos=0)

"""The hostile corpus, generated into a folder, and a bounded run of the console
script on each case: a subprocess under an address-space cap (``ulimit -v``), its time and peak
memory measured. Imported by ``test_hostile_inputs.py`` and ``bench/bench_hostile.py``.

Nothing here is committed as a large file: every case is written when it is needed.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import orjson

T0 = 1_763_700_000.0
UNIT = "waraps/unit/air/simulation/dji0"
ADDRESS_SPACE = 3 << 30
"""The ``ulimit -v`` of every run: 3 GiB (numpy and rosbags map ~1 GiB of address space
before reading anything; a 2e9-byte payloadlen once needed 3.9 GB)."""
MAX_SECONDS = 60.0
"""A run killed past this (on an idle machine; more on a busy one: ``machine.deadline``) is a
hang (a case takes under 5 s on an idle machine)."""
MAX_PEAK_MB = 400
"""Peak resident memory of any run (the 100k-unit fleet takes ~250 MB)."""
EXIT_TABLE = {"lint": {0, 1, 2, 3, 4}, "validate": {0, 1, 2}}
"""The documented exit statuses (README, ``--help``): anything else is a crash."""


@dataclass
class Run:
    """One bounded run: exit code, output, wall time, peak resident memory."""

    name: str
    code: int
    out: str
    err: str
    seconds: float
    peak_mb: float
    killed: bool = False

    @property
    def traceback(self) -> bool:
        return "Traceback (most recent call last)" in self.err + self.out


PEAK_WRAPPER = r"""
import atexit, sys
peak, script = sys.argv.pop(1), sys.argv.pop(1)

def report():  # this process's own high-water mark (wait4's counts the parent's, forked)
    with open("/proc/self/status") as status:
        kb = next((ln.split()[1] for ln in status if ln.startswith("VmHWM")), "")
    with open(peak, "w") as out:
        out.write(kb)

atexit.register(report)
if script:
    exec(compile(script, "<case>", "exec"))
else:
    from conformance.cli import main
    sys.exit(main(sys.argv[1:]))
"""


def _cap() -> None:  # in the child, before exec
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def run_bounded(name: str, args: list[str], cwd: Path, *, stdin: str | Path | None = None,
                script: str | None = None, timeout: float | None = None) -> Run:
    """``waraps-conformance ARGS`` (or ``python -c SCRIPT ARGS``) in a subprocess under the
    address-space cap; its peak memory from the kernel (its own VmHWM at exit); killed as
    hung past ``timeout`` (``MAX_SECONDS`` as this machine's load allows)."""
    from machine import deadline  # here: the cases' own processes import this module too

    timeout = deadline(MAX_SECONDS) if timeout is None else timeout
    out_path, err_path = cwd / f"{name}.out", cwd / f"{name}.err"
    peak_path = cwd / f"{name}.peak"
    command = [sys.executable, "-c", PEAK_WRAPPER, str(peak_path), script or "", *args]
    with open(out_path, "wb") as out, open(err_path, "wb") as err, \
            open(stdin if stdin is not None else os.devnull, "rb") as inp:
        start = time.monotonic()
        proc = subprocess.Popen(command, stdin=inp, stdout=out, stderr=err, cwd=cwd,
                                preexec_fn=_cap, env={**os.environ, "COLUMNS": "200"})
        killed = threading.Event()

        def kill() -> None:
            killed.set()
            proc.kill()

        timer = threading.Timer(timeout, kill)
        timer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            timer.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)
        seconds = time.monotonic() - start
    try:  # VmHWM, else (killed: no atexit) wait4's, which counts the forked parent too
        peak_kb = float(peak_path.read_text())
    except (OSError, ValueError):
        peak_kb = float(usage.ru_maxrss)
    return Run(name, proc.returncode, out_path.read_text("utf-8", "replace"),
               err_path.read_text("utf-8", "replace"), seconds, peak_kb / 1024,
               killed.is_set())


# --- the corpus ----------------------------------------------------------------------------

def heartbeat(t: float, name: str = "dji0", number: int = 0, **extra: object) -> bytes:
    return orjson.dumps({"agent-type": "air", "agent-uuid": f"3f1c2a4e-1b2c-4d5e-8f90-{number:012d}",
                         "levels": ["sensor"], "name": name, "rate": 1.0, "stamp": t,
                         "type": "HeartBeat", **extra})


def good_lines(seconds: int = 4, t0: float = T0) -> list[bytes]:
    """A unit's heartbeats and mandatory sensors as JSON Lines."""
    lines = []
    for i in range(seconds):
        t = t0 + i
        lines.append(line(t, f"{UNIT}/heartbeat", heartbeat(t)))
        for k, (sensor, value) in enumerate((
                ("position", {"latitude": 58.4, "longitude": 15.6, "altitude": 100.0,
                              "rostype": "GeoPoint"}),
                ("heading", 90.0), ("course", 90.0), ("speed", 0.1))):
            lines.append(line(t + 0.01 * (k + 1), f"{UNIT}/sensor/{sensor}", orjson.dumps(value)))
    return lines


def line(ts: float, topic: str, payload: bytes) -> bytes:
    return orjson.dumps({"ts": ts, "topic": topic, "payload": payload.decode("utf-8")})


def mosquitto_j(payloadlen: int, payload: str = "x",
                tst: str = "2026-11-21T07:26:55.807087Z+0100", subtopic: str = "heartbeat"
                ) -> bytes:
    """A ``mosquitto_sub -F %j`` line declaring ``payloadlen`` (153 bytes for 2e9)."""
    return (b'{"tst":"' + tst.encode() + b'","topic":"' + UNIT.encode() + b'/'
            + subtopic.encode() + b'","qos":0,"retain":0,"payloadlen":' + str(payloadlen).encode()
            + b',"payload":"' + payload.encode() + b'"}')


def mosquitto_jj(topic: str, value: bytes, payloadlen: int, t: str = "05:40:00.500000") -> bytes:
    """A ``mosquitto_sub -F %J`` line: the payload ``value`` embedded as JSON."""
    return (b'{"tst":"2025-11-21T' + t.encode() + b'Z+0100","topic":"' + topic.encode()
            + b'","qos":0,"retain":0,"payloadlen":' + str(payloadlen).encode() + b',"payload":'
            + value + b"}")


def as_mosquitto_j(jsonl: bytes) -> bytes:
    """A JSON Lines line of ours as ``mosquitto_sub -F %j`` prints the same message."""
    obj = orjson.loads(jsonl)
    tst = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(obj["ts"])) + \
        f".{int(obj['ts'] % 1 * 1e6):06d}Z+0000"
    payload = obj["payload"].encode()
    return orjson.dumps({"tst": tst, "topic": obj["topic"], "qos": 0, "retain": 0,
                         "payloadlen": len(payload), "payload": obj["payload"]})


def _empty_objects(path: Path, count: int = 22_000_000) -> Path:
    """A -F %J line of 66 MB, ``[{},{},...]`` (2.1 GB as Python objects: once a
    SIGSEGV in orjson.dumps), among good lines; written in pieces, never held."""
    good = good_lines()
    head, tail = mosquitto_jj(f"{UNIT}/sensor/speed", b"@", 3 * count).split(b"@")
    with path.open("wb") as f:
        f.write(b"\n".join(good[:6]) + b"\n" + head + b"[{}")
        for _ in range(count // 100_000):
            f.write(b",{}" * 100_000)
        f.write(b"]" + tail + b"\n" + b"\n".join(good[6:]) + b"\n")
    return path


def mixed_j_and_jj(tmp: Path) -> Path:
    """One ``-F %J`` line, then a conformant unit's ``-F %j`` lines (30 false
    MSG-003 findings when the first line's format was taken for the whole file)."""
    path = tmp / "mixed.txt"
    first = as_mosquitto_j(line(T0 - 0.1, f"{UNIT}/sensor/speed", b"0.1")).replace(
        b'"payload":"0.1"', b'"payload":0.1')  # -F %J: the payload embedded as JSON
    path.write_bytes(b"\n".join([first, *map(as_mosquitto_j, good_lines(12))]) + b"\n")
    return path


@dataclass
class Case:
    """A recording (lines, or raw bytes) linted, or a command run, and what must follow."""

    name: str
    data: bytes = b""
    args: tuple[str, ...] = ()
    """Default: ``lint --from FILE``; ``{file}`` stands for the case's file."""
    codes: frozenset[int] = frozenset({4})
    """Default: partial (the hostile line was not examined: never clean)."""
    says: tuple[str, ...] = ()
    """Text the output or the errors must hold (what, where, which bound)."""
    suffix: str = ".jsonl"
    stdin: bool = False
    make: Callable[[Path], Path] | None = None
    """Makes the case's input itself (a FIFO, a bag); returns its path."""
    extra: dict[str, str] = field(default_factory=dict)


def _recording(hostile: bytes | list[bytes], at: int = 6) -> bytes:
    good = good_lines()
    bad = hostile if isinstance(hostile, list) else [hostile]
    return b"\n".join(good[:at] + bad + good[at:]) + b"\n"


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _v_capture(tmp: Path) -> Path:
    """A ``mosquitto_sub -v`` capture: TOPIC PAYLOAD per line, no times; every second heartbeat
    missing (HB-003 with times) and one heartbeat of the wrong type (HB-002: judged)."""
    out = []
    for i in range(30):
        t = T0 + i
        if i % 2 == 0:
            out.append(f"{UNIT}/heartbeat ".encode() + heartbeat(t))
        out.append(f"{UNIT}/sensor/speed 0.1".encode())
    out.append(f"{UNIT}/heartbeat ".encode() + heartbeat(T0 + 31, type="Heartbeat"))
    path = tmp / "capture.txt"
    path.write_bytes(b"\n".join(out) + b"\n")
    return path


def fleet(tmp: Path, units: int = 100_000) -> Path:
    """A generated recording of ``units`` units, one heartbeat each; only the last unit is
    faulty (its heartbeat's type is wrong: HB-002), so that a fleet past the unit bound
    would pass if what lies past the bound were not judged. All within 1 s: none falls silent
    at its declared 1 Hz (HB-010, HB-012)."""
    path = tmp / f"fleet{units}.jsonl"
    with open(path, "wb") as f:
        for i in range(units):
            name = f"u{i}"
            bad = {"type": "Heartbeat"} if i == units - 1 else {}
            f.write(line(T0 + i * 1e-5, f"waraps/unit/air/simulation/{name}/heartbeat",
                         heartbeat(T0, name, i, **bad)) + b"\n")
    return path


def long_names(tmp: Path, units: int = 100, chars: int = 100_000) -> Path:
    """``units`` units whose names take ``chars`` characters, one heartbeat each
    (800 such units once took gigabytes: the name repeated in each rule's reason)."""
    path = tmp / "long-names.jsonl"
    with open(path, "wb") as f:
        for i in range(units):
            name = f"u{i}" + "n" * chars
            f.write(line(T0 + i * 1e-3, f"waraps/unit/air/simulation/{name}/heartbeat",
                         heartbeat(T0, name, i)) + b"\n")
    return path


NOT_JSON_SAYS = ("malformed line 7",)
RECORDING_CASES = [
    Case("ts-1e17", _recording(b'{"ts": 1e17, "topic": "' + UNIT.encode() + b'/heartbeat", '
                               b'"payload": "{}"}'),
         says=("malformed line 7: 'ts' 1e+17 is outside the times", "1970 to 2100")),
    Case("ts-1e308", _recording(b'{"ts": 1e308, "topic": "a/b", "payload": "{}"}'),
         says=("malformed line 7: 'ts' 1e+308 is outside",)),
    Case("event-ts-1e308", _recording(b'{"ts": 1e308, "event": "disconnected"}'),
         says=("malformed line 7: 'ts' 1e+308",)),
    Case("ts-negative", _recording(b'{"ts": -5.0, "topic": "a/b", "payload": "{}"}'),
         says=("malformed line 7: 'ts' -5.0",)),
    Case("ts-nan", _recording(b'{"ts": NaN, "topic": "a/b", "payload": "{}"}'),
         says=NOT_JSON_SAYS),
    Case("tst-year-9999", _recording(mosquitto_j(1).replace(b"2026-11-21T07:26:55.807087Z+0100",
                                                            b"9999-12-31T23:59:59Z-2359")),
         says=("malformed line 7: 'tst'",)),
    Case("payloadlen-2e9", _recording(mosquitto_j(2_000_000_000)),
         says=("'payloadlen' 2000000000 is over the 64 MiB",)),
    Case("payloadlen-1e12", _recording(mosquitto_j(10**12)),
         says=("'payloadlen' 1000000000000 is over the 64 MiB",)),
    Case("line-nested-100k", _recording(b"[" * 100_000),
         says=("malformed line 7: not JSON: nested deeper than the 1024 levels",)),
    Case("payload-nested-100k", _recording(line(T0 + 0.5, f"{UNIT}/heartbeat",
                                                b"[" * 100_000 + b"]" * 100_000)),
         # MSG-004 is a decided rule (rules.toml): it warns by default, and what it did not
         # examine makes the run partial, never clean.
         codes=frozenset({4}), says=("MSG-004",)),
    Case("payload-nan-infinity", _recording(line(T0 + 0.5, f"{UNIT}/heartbeat",
                                                 b'{"stamp": NaN, "rate": Infinity}')),
         codes=frozenset({1}), says=("MSG-002",)),
    Case("payload-stamp-1e308", _recording(line(T0 + 0.5, f"{UNIT}/heartbeat",
                                                heartbeat(T0, stamp=1e308))),
         codes=frozenset({0}), says=("MSG-005",)),
    Case("topic-not-utf8", _recording(b'{"ts": 1763700000.5, "topic": "waraps/unit/ai\xdd/'
                                      b'simulation/dji0/heartbeat", "payload": "{}"}'),
         codes=frozenset({1}), says=("TOPIC-005",)),
    Case("line-lone-surrogate-escape", _recording(
        b'{"ts": 1763700000.5, "topic": "' + UNIT.encode() + b'/heartbeat", '
        b'"payload": "{\\"name\\": \\"\\ud800\\"}"}'), says=NOT_JSON_SAYS),
    Case("payload-lone-surrogate-bytes", _recording(
        b'{"tst":"2025-11-21T04:40:00.5Z+0000","topic":"' + UNIT.encode() + b'/heartbeat",'
        b'"qos":0,"retain":0,"payloadlen":9,"payload":"\xed\xa0\x80abcdef"}'),
         codes=frozenset({1}), says=("MSG-001",)),
    Case("bom", b"\xef\xbb\xbf" + _recording(b""), codes=frozenset({0})),
    Case("utf-16", _recording(b"").decode("utf-8").encode("utf-16"), codes=frozenset({3}),
         says=("the file is UTF-16", "iconv -f UTF-16 -t UTF-8")),
    Case("binary", bytes(range(256)) * 4096, codes=frozenset({3}),
         says=("no messages were read",)),
    Case("truncated-mid-escape", _recording(b"")[:-1] + b'\n{"ts": 1763700009.0, "topic": "'
         + UNIT.encode() + b'/heartbeat", "payload": "{\\"name\\": \\"dj\\u00', says=(
             "malformed line 22: not JSON",)),
    Case("duplicate-keys", _recording([
        b'{"ts": 1e17, "ts": 1763700000.5, "topic": "' + UNIT.encode() + b'/sensor/speed", '
        b'"payload": "0.1"}',
        line(T0 + 0.6, f"{UNIT}/sensor/speed", b'{"x": 1, "x": 2}')]), codes=frozenset({0}),
         says=("SENS-003", "MSG-002")),  # decided (rules.toml): each warns by default
    Case("overlong-line", _recording(b"x" * ((64 << 20) + 10)),
         says=("malformed line 7: line of 67108875 bytes is longer than the 64 MiB",)),
    Case("empty", b"", codes=frozenset({3}), says=("no messages were read",)),
    # Bounded by construction, not by case.
    Case("jj-nested-999", _recording(mosquitto_jj(f"{UNIT}/sensor/speed", b"[" * 999
                                                  + b"]" * 999, 1998)),
         codes=frozenset({4}), says=("MSG-004",)),  # decided: partial unless strict
    Case("jj-66mb-of-empty-objects", make=lambda tmp: _empty_objects(tmp / "jj-66mb-of-empty-objects.jsonl"),
         says=("malformed line 7: line of 66000153 bytes holds more than the 1048576 JSON "
               "values",)),
    Case("jj-key-not-utf8", _recording(mosquitto_jj(  # found by fuzz/recording_mixed
        f"{UNIT}/sensor/battery", b'{"volt\xb1age": 12.5}', 19)),
         codes=frozenset({1}), says=("MSG-001",)),
    Case("heartbeats-all-at-one-instant", _recording([  # found by fuzz/recording_mixed
        line(T0 + 0.5, "waraps/unit/air/simulation/dji9/heartbeat", heartbeat(T0, "dji9", 9))
        for _ in range(6)]), codes=frozenset({1}), says=("a mean interval of 0 s",)),
    # Among the good lines' times (a time that runs back further is refused), on a sensor's
    # topic (2000 heartbeats at one instant would be a rate of their own, HB-003).
    Case("payloadlen-64mib-2000-lines", _recording([mosquitto_j(
        64 << 20, tst="2025-11-21T04:40:01.050000Z+0000", subtopic="sensor/speed")] * 2000),
         # MSG-004 is decided (rules.toml): it warns, and the run is partial
         codes=frozenset({4}), says=("2000 payload(s) were cut at a NUL byte", "MSG-004")),
]


def _runs_of(name: str) -> Callable[[Path], Path]:
    return lambda tmp: tmp / name


COMMAND_CASES = [
    Case("mosquitto-v-capture", args=("lint", "--from", "{file}", "--plain", "--format", "json"),
         make=_v_capture, codes=frozenset({1}),
         says=("as mosquitto_sub -v", "HB-002", "FAIL: " + UNIT,
               "note: a mosquitto_sub -v capture has no times: HB-003")),
    Case("validate-dev-zero-file", args=("validate", f"{UNIT}/heartbeat", "/dev/zero"),
         codes=frozenset({2}), says=("/dev/zero holds more than the 16 MiB validate reads",)),
    Case("validate-dev-zero-stdin", args=("validate", f"{UNIT}/heartbeat", "-"),
         stdin=True, codes=frozenset({2}),
         says=("standard input holds more than the 16 MiB",)),
    Case("lint-dev-zero", args=("lint", "--from", "/dev/zero"), codes=frozenset({3}),
         says=("is not a file",)),
    Case("lint-directory-not-a-bag", args=("lint", "--from", "{file}"),
         make=lambda tmp: (tmp / "empty-dir").mkdir() or tmp / "empty-dir",
         codes=frozenset({3}), says=("is a directory but not a ROS 2 bag",)),
    *(Case(f"fifo-{suffix}", args=("lint", "--from", "{file}"),
           make=lambda tmp, s=suffix: _fifo(tmp / f"fifo.{s}"), codes=frozenset({3}),
           says=("not a regular file",) if suffix != "jsonl" else ("is not a file",))
      for suffix in ("mcap", "db3", "bag", "jsonl")),
]


def write_case(case: Case, tmp: Path) -> tuple[list[str], Path | None]:
    """The case's input in ``tmp``; its command line and its standard input."""
    if case.make is not None:
        path = case.make(tmp)
    else:
        path = tmp / f"{case.name}{case.suffix}"
        path.write_bytes(case.data)
    args = list(case.args) or ["lint", "--from", "{file}", "--plain", "--format", "json"]
    args = [a.replace("{file}", str(path)) for a in args]
    stdin = Path("/dev/zero") if case.stdin else None
    return args, stdin


# --- damaged bags ----------------------------------------------------------------------------

BAG_DRIVER = r"""
import contextlib, io, json, sys, traceback
from conformance.cli.lint import main
codes = []
for bag in sys.argv[1:]:
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            code = main(["--from", bag, "--plain", "--format", "none"], stdout=out)
    except BaseException:
        code = "traceback: " + traceback.format_exc()[-400:]
    codes.append([bag, code, err.getvalue()[-300:]])
print(json.dumps(codes))
"""
"""Lints every bag named, in one process (bounded as one run): each bag's exit code."""


def damaged_bags(tmp: Path, storage: str, copies: int) -> tuple[Path, list[Path]]:
    """A failing bag (HB-003: every second heartbeat at a declared 1 Hz) of ``storage`` (ros1,
    sqlite3, mcap), and ``copies`` damaged copies: 16 bytes overwritten at offsets spread over
    the whole file, a copy cut off midway, and (ROS 2) a metadata.yaml claiming 3 more
    messages than were stored."""
    sys.path.insert(0, str(Path(__file__).parent.parent / "ros"))
    from ros_bags import unit_entries, write_bag

    ros2 = storage != "ros1"
    src = write_bag(tmp / (f"{storage}.bag" if not ros2 else storage),
                    unit_entries(heartbeat_every=2, seconds=30, ros2=ros2), ros2=ros2,
                    storage=storage)
    store = src if not ros2 else next(p for p in src.iterdir() if p.suffix in (".db3", ".mcap"))
    data = store.read_bytes()
    out: list[Path] = []

    def copy(i: int, content: bytes) -> Path:
        if not ros2:
            path = tmp / f"{storage}-{i}.bag"
            path.write_bytes(content)
            return path
        path = tmp / f"{storage}-{i}"
        shutil.copytree(src, path)
        (path / store.name).write_bytes(content)
        return path

    for i in range(copies):
        at = len(data) * (i + 1) // (copies + 1)
        damaged = bytearray(data)
        damaged[at:at + 16] = b"\xa5" * 16
        out.append(copy(i, bytes(damaged)))
    out.append(copy(copies, data[: len(data) // 2]))
    if ros2:
        path = copy(copies + 1, data)
        meta = path / "metadata.yaml"
        text = meta.read_text()
        counted = re.search(r"- message_count: (\d+)", text)  # a topic's, then the total
        total = re.search(r"\n  message_count: (\d+)", text)
        assert counted is not None and total is not None
        text = text.replace(counted[0], f"- message_count: {int(counted[1]) + 3}", 1)
        meta.write_text(text.replace(total[0], f"\n  message_count: {int(total[1]) + 3}", 1))
        out.append(path)
    return src, out


BILLION_LAUGHS = "".join(
    [f"a0: &a0 [{', '.join(['x'] * 9)}]\n"]
    + [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10)])
"""About 1 KB of YAML that expands to 9**10 strings."""


def metadata_bags(tmp: Path) -> list[Path]:
    """ROS 2 bags whose metadata.yaml says ``message_count: lots`` (in a topic's
    count, then in the total), is a billion laughs, or nests 10,000 levels deep."""
    sys.path.insert(0, str(Path(__file__).parent.parent / "ros"))
    from ros_bags import unit_entries, write_bag

    src = write_bag(tmp / "good", unit_entries(seconds=3, ros2=True), ros2=True)
    text = (src / "metadata.yaml").read_text()
    variants = [re.sub(r"- message_count: \d+", "- message_count: lots", text, count=1),
                re.sub(r"\n  message_count: \d+", "\n  message_count: lots", text, count=1),
                text + BILLION_LAUGHS.replace("a0:", "  a0:").replace("\na", "\n  a"),
                "[" * 10_000 + "]" * 10_000]
    out = []
    for i, variant in enumerate(variants):
        path = tmp / f"meta-{i}"
        shutil.copytree(src, path)
        (path / "metadata.yaml").write_text(variant)
        out.append(path)
    return out


def bag_codes(run: Run) -> list[tuple[str, object, str]]:
    """(bag, exit code or traceback, end of its errors) of a BAG_DRIVER run."""
    return [tuple(x) for x in json.loads(run.out.strip().splitlines()[-1])]


# --- mutations of a good recording ----------------------------------------------------------

_INSERTS = (b"1e400", b"-", b'"', b"\\", b"NaN", b"[", b"{", b"\xff", b"\xdd", b"\n", b"9" * 30,
            b"null", b"\\ud800", b"\xed\xa0\x80", b"\r", b"\x00")


def mutations(seed: int, count: int) -> list[bytes]:
    """``count`` recordings, each a good one (plus a -F %j line, an event, a -v line) with a
    few random bytes overwritten, deleted, inserted or copied: deterministic for ``seed``."""
    import random

    rnd = random.Random(seed)
    base = b"\n".join(good_lines(6)) + b"\n"
    extra = [mosquitto_j(5, "hello"), b'{"ts": 1763700000.5, "event": "unexamined", "count": 5}',
             f"{UNIT}/heartbeat {{}}".encode()]
    out = []
    for _ in range(count):
        data = bytearray(base + b"\n".join(rnd.sample(extra, rnd.randint(0, 3))))
        for _ in range(rnd.randint(1, 8)):
            op, at = rnd.random(), rnd.randrange(len(data))
            if op < 0.4:
                data[at] = rnd.randrange(256)
            elif op < 0.6:
                del data[at:at + rnd.randint(1, 20)]
            elif op < 0.8:
                data[at:at] = rnd.choice(_INSERTS)
            else:
                data[at:at] = data[rnd.randrange(len(data)):][:50]
        out.append(bytes(data))
    return out


MUTATION_DRIVER = r"""
import contextlib, io, json, sys, traceback
sys.path.insert(0, sys.argv[1])
from hostile import mutations
from conformance.cli.lint import main
codes = []
for i, data in enumerate(mutations(int(sys.argv[2]), int(sys.argv[3]))):
    path = f"m{i}.jsonl"
    with open(path, "wb") as f:
        f.write(data)
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            code = main(["--from", path, "--plain", "--format", "json,html,junit",
                         "--reports-dir", f"r{i}"], stdout=out)
    except BaseException:
        code = "traceback: " + traceback.format_exc()[-600:]
    codes.append([path, code, err.getvalue()[-300:]])
print(json.dumps(codes))
"""
"""Lints each mutation in one process (bounded as one run), every report format written."""

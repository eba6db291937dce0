"""``waraps-conformance lint --serve``: the live fleet page in headless Chromium, /metrics as
Prometheus reads it, /report.json, escaping of hostile unit names, and a read-only server that
stops with lint.

Chromium: `apt-get install -y chromium` (Debian 12); the browser tests are skipped with that
hint when it is missing. Screenshots go to the test's tmp_path.
"""

from __future__ import annotations

import json
import re
import shutil
import socket
import subprocess
import time
import urllib.error
import urllib.request
import uuid
from pathlib import Path

import pytest
from lint_helpers import Process, fleet_traffic, run_lint, unit_traffic, write_recording

from conformance.client import BrokerURL, MqttClient
from conformance.lint.fleetview import FleetView
from conformance.lint.serve import ServeError, Server, parse_address, warnings
from conformance.sim.fleet import Fleet, SimUnit

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None,
                                    reason="needs chromium: apt-get install -y chromium")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-extensions"]


def chromium(tmp_path: Path, *args: str) -> str:
    done = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'chrome-profile'}",
                           *args], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def get(url: str, method: str = "GET") -> tuple[int, dict[str, str], bytes]:
    request = urllib.request.Request(url, method=method)
    try:
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()


def rows(html: str) -> dict[str, str]:
    """Unit (as shown) -> its row's status, from the fleet table."""
    return {m.group(1): m.group(2) for m in re.finditer(
        r'<tr class="row [^"]*" data-unit="([^"]*)" data-status="([^"]*)"', html)}


def wait_until(what: str, predicate, timeout: float):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout} s: {what}")
        time.sleep(0.2)  # polling a condition under a deadline, not a fixed wait


def serving(process: Process) -> str:
    line = process.wait_for("serving http://", timeout=30)
    return re.search(r"http://\S+/", line).group(0)


def test_serve_takes_a_port_for_loopback_or_an_explicit_host():
    assert parse_address("8080") == parse_address("127.0.0.1:8080")
    assert parse_address("8080").loopback
    assert parse_address("[::1]:0").loopback
    assert not parse_address("0.0.0.0:8080").loopback
    assert parse_address("192.0.2.7:9").host == "192.0.2.7"
    for bad in ("", "http", "8080x", "host:", "1:99999", "\u00b2", "127.0.0.1:\u0661\u0662",
                "9" * 5000):  # digits to str.isdigit, no number to int()
        with pytest.raises(ServeError, match="--serve"):
            parse_address(bad)


def test_metrics_cap_the_series_of_invented_unit_names(monkeypatch):
    """Past MAX_SERIES label sets a family sums the rest under '(other units)'."""
    from prometheus_client.parser import text_string_to_metric_families

    from conformance.lint import metrics
    from conformance.lint.fleetview import Row, Snapshot
    from conformance.lint.rows import Finding

    monkeypatch.setattr(metrics, "MAX_SERIES", 10)
    rows = tuple(Row(f"p/unit/air/simulation/u{i}", "unit", messages=5,
                     findings=(Finding("HB-002", "fail", 2),), by_kind=(("heartbeat", 5),))
                 for i in range(30))
    snap = Snapshot(1, 0.0, None, "", True, False, 150, 0, 0, True, rows)
    families = {f.name: f for f in text_string_to_metric_families(
        metrics.exposition(lambda: snap).decode())}
    findings = families["waraps_lint_findings"].samples
    assert len(findings) == 11
    other = [s for s in findings if s.labels["unit"] == "(other units)"]
    assert len(other) == 1 and other[0].value == 40.0  # 20 units beyond the cap, 2 each
    assert len(families["waraps_lint_unit_failing"].samples) == 11


def test_metrics_give_each_unit_its_own_series():
    """Names that differ only past 200 characters, or as an ESC and its escape written out,
    once shared one label value (duplicate series)."""
    from prometheus_client.parser import text_string_to_metric_families

    from conformance.lint import metrics
    from conformance.lint.fleetview import Row, Snapshot

    base = "p/unit/air/simulation/"
    names = [base + "u" * 300 + "a", base + "u" * 300 + "b", base + "v\x1b",
             base + "v\\x1b", base + "w"]
    rows = tuple(Row(name, "unit", messages=5, by_kind=(("heartbeat", 5),)) for name in names)
    snap = Snapshot(1, 0.0, None, "", True, False, 25, 0, 0, True, rows)
    families = {f.name: f for f in text_string_to_metric_families(
        metrics.exposition(lambda: snap).decode())}
    units = [s.labels["unit"] for s in families["waraps_lint_unit_failing"].samples]
    assert len(units) == len(set(units)) == len(names), units
    assert base + "w" in units and base + "v\\x1b" in units  # unaltered names as they are
    assert all(len(u) < 250 and "\x1b" not in u for u in units)


def test_only_a_host_named_on_purpose_is_warned_about():
    assert warnings(parse_address("8080")) == []
    assert warnings(parse_address("localhost:8080")) == []
    (line,) = warnings(parse_address("0.0.0.0:8080"))
    assert "anyone who can reach" in line and "--serve PORT" in line


@pytest.mark.parametrize("host", ["127.1", "LOCALHOST", "0x7f000001", "127.0.0.1"])
def test_the_host_guard_follows_the_bound_address_not_its_spelling(host):
    """'127.1', 'LOCALHOST' and '0x7f000001' bind 127.0.0.1: the DNS-rebinding guard stays
    on (a foreign Host gets 421) and no page warns that anyone can read it."""
    server = Server(FleetView("nothing yet", live=True), parse_address(f"{host}:0")).start()
    try:
        assert server.loopback and server.app.header == ()
        url = f"http://127.0.0.1:{server.port}/"
        rebound = urllib.request.Request(url, headers={"Host": f"evil.example:{server.port}"})
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(rebound, timeout=10)
        assert refused.value.code == 421
        assert get(url)[0] == 200
    finally:
        server.stop()


@pytest.mark.slow
def test_slow_clients_cannot_starve_a_scrape():
    """Slowloris: 40 connections, each trickling a header line (every 2 s here, faster than
    the 10 s that once starved /metrics for as long as they lasted: each line renewed
    waitress's idle timeout, and 32 connections filled it). A scrape is answered while they
    trickle, and each of them is closed within the header deadline, however often it sends."""
    from conformance.lint.serve import HEADER_SECONDS

    server = Server(FleetView("nothing yet", live=True), parse_address("0")).start()
    slow: list[socket.socket] = []
    try:
        for _ in range(40):
            conn = socket.create_connection(("127.0.0.1", server.port), timeout=10)
            conn.sendall(b"GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            slow.append(conn)
        opened = time.monotonic()
        assert get(f"{server.url}metrics")[0] == 200  # within urlopen's 10 s
        closed: set[int] = set()
        deadline = opened + HEADER_SECONDS + 6  # the deadline, checked every second
        while len(closed) < len(slow) and time.monotonic() < deadline:
            for i, conn in enumerate(slow):
                if i in closed:
                    continue
                try:
                    conn.sendall(b"X-Trickle: 1\r\n")
                    conn.settimeout(0.05)
                    if conn.recv(1) == b"":
                        closed.add(i)
                except TimeoutError:
                    pass
                except OSError:  # reset by the server: closed
                    closed.add(i)
            time.sleep(0.5)
        assert len(closed) == len(slow), f"{len(slow) - len(closed)} trickling connections open"
        assert get(f"{server.url}metrics")[0] == 200
    finally:
        for conn in slow:
            conn.close()
        server.stop()


def test_the_server_answers_gets_only_within_its_bounds_and_stops():
    """No lint run: an empty fleet view served on a free loopback port."""
    server = Server(FleetView("nothing yet", live=True), parse_address("0")).start()
    url = server.url
    try:
        status, headers, body = get(url)
        assert status == 200 and "no unit seen yet" in body.decode()
        assert "script-src 'self'" in headers["Content-Security-Policy"]
        assert get(url, "HEAD")[0] == 200
        assert get(f"{url}unit/waraps/unit/air/simulation/none")[0] == 404
        assert get(f"{url}static/fleet.js")[0] == 200
        assert get(f"{url}static/../serve.py")[0] == 404
        for method in ("POST", "PUT", "PATCH", "DELETE", "OPTIONS"):
            status, headers, _ = get(url, method)
            assert status == 405 and headers["Allow"] == "GET, HEAD", method
        huge = urllib.request.Request(url, headers={"X-Big": "x" * 20_000})
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(huge, timeout=10)
        assert refused.value.code == 431  # past waitress's max_request_header_size
        assert get(url + "x" * 3000)[0] == 414
        rebound = urllib.request.Request(url, headers={"Host": f"evil.example:{server.port}"})
        with pytest.raises(urllib.error.HTTPError) as refused:  # DNS rebinding
            urllib.request.urlopen(rebound, timeout=10)
        assert refused.value.code == 421
        assert get(f"http://localhost:{server.port}/")[0] == 200
    finally:
        server.stop()
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", server.port), timeout=2).close()


def test_the_server_stops_when_lint_ends_unless_asked_to_linger(prefix, tmp_path):
    recording = write_recording(tmp_path / "fleet.jsonl",
                                fleet_traffic(prefix, ["dji0", "dji1"], seconds=10))
    run = run_lint(["--from", str(recording), "--serve", "0", "--serve-linger", "0"],
                   tmp_path / "reports")
    assert run.code == 0, run.out
    url = re.search(r"serving (http://\S+/) \(the fleet page", run.out).group(1)
    assert "serving the final fleet page" not in run.out
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", int(url.rsplit(":", 1)[1].strip("/"))),
                                 timeout=2).close()


def test_serve_usage_errors_and_a_port_in_use(prefix, tmp_path, capsys):
    recording = write_recording(tmp_path / "fleet.jsonl", fleet_traffic(prefix, ["dji0"],
                                                                        seconds=3))
    assert run_lint(["--from", str(recording), "--serve-linger", "5"], tmp_path).code == 2
    assert "--serve-linger applies with --serve only" in capsys.readouterr().err
    assert run_lint(["--from", str(recording), "--serve", "80x"], tmp_path).code == 2
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        run = run_lint(["--from", str(recording), "--serve", str(taken.getsockname()[1])],
                       tmp_path / "reports")
    assert run.code == 3 and run.report is None  # nothing linted, no report written
    assert "--serve 127.0.0.1:" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.mosquitto
@needs_chromium
def test_the_fleet_page_shows_every_unit_and_a_faulty_one_turns_red(mosquitto, prefix, tmp_path):
    """Lint live over Mosquitto, three reference units: Chromium shows each in a row, and a
    row for a commander once it pings one (answered: clean); a unit
    sending 'Heartbeat' under dji1's name turns dji1's row red while the others stay clean;
    the page's script updates a page already loaded; /metrics parses and says dji1 fails;
    /report.json parses; a POST is refused; Ctrl-C stops the server."""
    from prometheus_client.parser import text_string_to_metric_families

    names = [f"{prefix}/unit/air/simulation/dji{i}" for i in range(3)]
    with Fleet(names[0], mosquitto, 3, rate=2.0):
        lint = Process(["lint", "--broker", mosquitto, "--topic", f"{prefix}/#", "--serve", "0",
                        "--plain", "--reports-dir", str(tmp_path / "reports")])
        try:
            url = serving(lint)
            page = wait_until("every unit clean on the page", lambda: (
                lambda r: r if all(r.get(n) == "ok" for n in names) else None)(
                rows(get(url)[2].decode())), timeout=20)
            assert set(page) == set(names)
            dom = chromium(tmp_path, "--dump-dom", url)
            assert all(rows(dom).get(n) == "ok" for n in names), rows(dom)
            assert dom.count('<svg class="spark"') >= 3  # a rate plot per unit at least
            # A commander has a row as soon as it commands, clean or not.
            command_topic = f"{names[0]}/exec/command"
            with MqttClient(BrokerURL.parse(mosquitto),
                            may_publish=lambda t: t == command_topic) as op0:
                op0.publish(command_topic, json.dumps({
                    "com-uuid": str(uuid.uuid4()), "command": "ping", "sender": "op0"}).encode())
                commander = wait_until("op0's row", lambda: rows(get(url)[2].decode()).get(
                    "commander op0"), timeout=10)
            assert commander == "ok"
            shot = tmp_path / "fleet-clean.png"
            chromium(tmp_path, "--window-size=1400,700", f"--screenshot={shot}", url)
            assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

            with SimUnit(names[1], mosquitto, faults=["heartbeat-type-case"], rate=2.0):
                def red() -> dict[str, str] | None:
                    r = rows(chromium(tmp_path, "--dump-dom", url))
                    return r if r.get(names[1]) == "FAIL" else None
                seen = wait_until("dji1's row red", red, timeout=15)
            assert seen[names[0]] == seen[names[2]] == "ok", seen
            chromium(tmp_path, "--window-size=1400,700",
                     f"--screenshot={tmp_path / 'fleet-faulty.png'}", url)
            # A page already open swaps in what changed (its script polls every second).
            dom = chromium(tmp_path, "--virtual-time-budget=4000", "--dump-dom", url)
            assert re.search(r'data-updated="[1-9]', dom), dom[:2000]
            unit_page = chromium(tmp_path, "--dump-dom", f"{url}unit/{names[1]}")
            assert "HB-002" in unit_page and "HeartBeat" in unit_page
            assert "5.1" in unit_page  # the rule's basis: its spec section at least
            chromium(tmp_path, "--window-size=1200,900",
                     f"--screenshot={tmp_path / 'unit-faulty.png'}", f"{url}unit/{names[1]}")

            status, headers, body = get(f"{url}metrics")
            assert status == 200 and headers["Content-Type"].startswith("text/plain")
            families = {f.name: f for f in text_string_to_metric_families(body.decode())}
            failing = {s.labels["unit"]: s.value
                       for s in families["waraps_lint_unit_failing"].samples}
            assert failing[names[1]] == 1.0 and failing[names[0]] == 0.0
            units = {(s.labels["party"], s.labels["status"]): s.value
                     for s in families["waraps_lint_units"].samples}
            assert units[("unit", "fail")] == 1 and units[("unit", "clean")] == 2
            assert any(s.labels["rule"] == "HB-002" and s.labels["unit"] == names[1]
                       for s in families["waraps_lint_findings"].samples)
            assert any(s.labels.get("kind") == "heartbeat"
                       for s in families["waraps_lint_unit_messages"].samples)

            status, _, body = get(f"{url}report.json")
            assert status == 200
            report = json.loads(body)
            assert "HB-002" in {r for r, res in report["units"][names[1]]["rules"].items()
                                if res["verdict"] == "fail"}

            for method in ("POST", "PUT", "DELETE"):
                status, headers, _ = get(url, method)
                assert status == 405 and headers["Allow"] == "GET, HEAD", method
            port = int(url.rsplit(":", 1)[1].strip("/"))
        finally:
            code = lint.interrupt()
    assert code == 1, lint.output  # dji1 failed HB-002
    with pytest.raises(OSError):  # the server stopped with lint
        socket.create_connection(("127.0.0.1", port), timeout=2).close()


HOSTILE = 'x"><img src=x onerror=alert(1)><script>alert(2)<\x1b]0;pwned\x07\x1b[2J\n'


@pytest.mark.slow
@needs_chromium
def test_a_hostile_unit_name_is_escaped_on_the_page_and_in_metrics(prefix, tmp_path):
    """A recording whose unit name holds markup and terminal controls: the page shows it as
    text (Chromium built no element from it), /metrics carries it escaped and parses; after
    the recording lint keeps serving until Ctrl-C."""
    from prometheus_client.parser import text_string_to_metric_families

    recording = write_recording(tmp_path / "hostile.jsonl", sorted(
        fleet_traffic(prefix, ["dji0"], seconds=20)
        + unit_traffic(prefix, HOSTILE, seconds=20), key=lambda m: m.time))
    lint = Process(["lint", "--from", str(recording), "--serve", "127.0.0.1:0", "--plain",
                    "--reports-dir", str(tmp_path / "reports")])
    try:
        url = serving(lint)
        lint.wait_for("serving the final fleet page", timeout=30)
        dom = chromium(tmp_path, "--dump-dom", url)
        assert "<script>alert" not in dom and "<img" not in dom
        assert "&lt;script&gt;alert(2)&lt;" in dom
        assert "\x1b" not in dom and "\\x1b]0;pwned\\x07" in dom
        chromium(tmp_path, "--window-size=1400,600", f"--screenshot={tmp_path / 'hostile.png'}",
                 url)
        status, _, body = get(f"{url}metrics")
        text = body.decode()
        assert status == 200 and "\x1b" not in text and "\x07" not in text
        units = {s.labels["unit"] for f in text_string_to_metric_families(text)
                 if f.name == "waraps_lint_unit_failing" for s in f.samples}
        assert any("<script>alert(2)<\\x1b]0;pwned\\x07" in u for u in units), units
        status, _, body = get(f"{url}report.json")
        assert status == 200 and json.loads(body)["kind"] == "lint"
        assert lint.proc.poll() is None  # still serving after the recording ended
    finally:
        code = lint.interrupt()
    assert code in (0, 1), lint.output

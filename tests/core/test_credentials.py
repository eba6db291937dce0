"""A password never reaches stdout, stderr or a report, whatever the command or the error:
one masking (``client.mask_password``), used by every error that shows a URL."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from private_mosquitto import PrivateMosquitto

from conformance.client import BrokerURL, mask_password

SECRET = "s3cretPW-x9"


@pytest.mark.parametrize(("text", "shown"), [
    ("mqtt://u:pw@h:1", "mqtt://u:***@h:1"),
    ("mqtt://u:p@ss@h/x", "mqtt://u:***@h/x"),           # a password holding '@'
    ("see http://a:b@c and mqtts://x:y@z", "see http://a:***@c and mqtts://x:***@z"),
    ("mqtt://h:1883", "mqtt://h:1883"),
    ("mqtt://u@h", "mqtt://u@h"),
    ("at 12:30@x", "at 12:30@x"),                        # text, not a URL
    ("--broker=mqtt://u:a b@h --seed 1", "--broker=mqtt://u:***@h --seed 1"),
    ("pytest --broker mqtt://h:1 --reboot-cmd 'ssh root@h'",  # the next option is not a password
     "pytest --broker mqtt://h:1 --reboot-cmd 'ssh root@h'"),
    ("ready broker=mqtt://h:1 faults=x@1", "ready broker=mqtt://h:1 faults=x@1"),  # next field
])
def test_mask_password(text, shown):
    assert mask_password(text) == shown


HOSTILE_PASSWORDS = ["pw", "p/w", "p#w", "p?w", "p w", "p@w", "p:w", "p@@w", "x://y@z",
                     "a/b#c?d e@f:g", "@", "/", "p --seed", "p'w\"q"]
"""Passwords holding what ends a URL's user-info in a careless reading (RFC 3986 3.2.1):
masking stopped at '/', '#', '?' or ' '."""


@pytest.mark.parametrize("password", HOSTILE_PASSWORDS)
def test_one_masking_for_every_url_form(password):
    from conformance.results import redact_broker

    secret = f"SECRET{password}SECRET"
    for url in (f"mqtt://user:{secret}@127.0.0.1:1883", f"user:{secret}@127.0.0.1",
                f"mqtts://user:{secret}@broker.example:8883/x?y#z"):
        texts = [mask_password(url, url=True), redact_broker(url)]
        # In a message or a command line a URL begins with its scheme and ends at the next
        # option at the latest (a password holding ' --' is masked whole only in a URL alone).
        if not url.startswith("user:") and " --" not in password:
            texts += [mask_password(f"broker URL {url!r}: no"),
                      mask_password(f"pytest --unit a/unit/air/real/b --broker {url} --seed 1")]
        for shown in texts:
            assert "SECRET" not in shown and "user" in shown, shown
    assert mask_password(f"pytest --broker 'mqtt://u:{secret}@h:1' --seed 1").endswith(
        "@h:1' --seed 1")  # the rest of a command line is kept


@pytest.mark.parametrize("url", [
    f"mqtt://user:{SECRET}@127.0.0.1:1",
    f"http://user:{SECRET}@127.0.0.1:1",       # a bad scheme: the error shows the URL
    f"user:{SECRET}@127.0.0.1:99999",          # no scheme, a bad port
    f"mqtt://user:{SECRET}@/",                 # no host
    f"mqtt://user:a@{SECRET}@127.0.0.1:1",     # a password holding '@'
])
def test_broker_url_errors_never_show_the_password(url):
    with pytest.raises(ValueError) as e:
        BrokerURL.parse(url, {})
    assert SECRET not in str(e.value) and "user" in str(e.value)


def _run(args: list[str], cwd: Path, env: dict[str, str] | None = None) -> str:
    done = subprocess.run([sys.executable, "-m", "conformance.cli", *args], cwd=cwd,
                          env={**os.environ, **(env or {})}, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode != 0, done.stdout + done.stderr  # an error path, every time
    return done.stdout + done.stderr


def _reports(cwd: Path) -> str:
    return "".join(p.read_text(errors="replace") for p in cwd.rglob("*") if p.is_file())


class _Silent:
    """A TCP port that accepts and never answers: a broker that does not speak MQTT."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.held: list[socket.socket] = []
        self.thread = threading.Thread(target=self._accept, daemon=True)
        self.thread.start()

    def _accept(self) -> None:
        try:
            while True:
                self.held.append(self.sock.accept()[0])
        except OSError:
            pass

    def close(self) -> None:
        self.sock.close()
        for s in self.held:
            s.close()


COMMANDS = {
    "lint": ["lint", "--duration", "1s", "--reports-dir", "reports"],
    "record": ["record", "--duration", "1s", "-o", "out.jsonl"],
    "sim": ["sim"],
}


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_no_subcommand_prints_a_password(command, tmp_path):
    args = COMMANDS[command]
    seen = []
    # The password in the URL: refused with the URL masked.
    for url in (f"mqtt://user:{SECRET}@127.0.0.1:1", f"http://user:{SECRET}@127.0.0.1:1"):
        seen.append(_run([*args, "--broker", url], tmp_path))
    # The password in the environment (where it belongs): refused, unreachable, not authorised.
    env = {"WARAPS_USERNAME": "user", "WARAPS_PASSWORD": SECRET}
    seen.append(_run([*args, "--broker", "mqtt://127.0.0.1:1"], tmp_path, env))
    seen.append(_run([*args], tmp_path, {**env, "WARAPS_BROKER": f"user:{SECRET}@127.0.0.1",
                                         "WARAPS_PORT": "1"}))
    silent = _Silent()
    try:
        seen.append(_run([*args, "--broker", f"mqtt://127.0.0.1:{silent.port}"], tmp_path, env))
    finally:
        silent.close()
    broker = PrivateMosquitto(tmp_path / "mosquitto", users={"user": "other"}).start()
    try:
        seen.append(_run([*args, "--broker", broker.url], tmp_path, env))
    finally:
        broker.stop()
    for out in seen:
        assert out.strip(), "an error says what went wrong"
        assert SECRET not in out, out
    assert SECRET not in _reports(tmp_path)


@pytest.mark.slow
def test_the_certification_never_prints_a_password(pytester, monkeypatch):
    pytester.makeini("[pytest]\naddopts = -p no:cacheprovider\n")
    for url in (f"mqtt://user:{SECRET}@127.0.0.1:1", f"http://user:{SECRET}@127.0.0.1:1"):
        result = pytester.runpytest_subprocess("--unit", "waraps/unit/air/simulation/dji0",
                                               "--broker", url)
        out = result.stdout.str() + result.stderr.str()
        assert result.ret != 0 and "***" in out and SECRET not in out
    monkeypatch.setenv("WARAPS_PASSWORD", SECRET)
    result = pytester.runpytest_subprocess("--unit", "waraps/unit/air/simulation/dji0",
                                           "--broker", "mqtt://user@127.0.0.1:1",
                                           "--reports-dir", "reports")
    out = result.stdout.str() + result.stderr.str()
    assert result.ret != 0 and SECRET not in out
    assert SECRET not in _reports(pytester.path)


@pytest.mark.slow
def test_a_lint_that_logs_in_prints_and_writes_no_password(tmp_path):
    """The working path: a broker that wants the password, the reference unit and lint both
    logged in with it (from the environment); nothing written or printed holds it."""
    broker = PrivateMosquitto(tmp_path / "mosquitto", users={"user": SECRET}).start()
    env = {**os.environ, "WARAPS_USERNAME": "user", "WARAPS_PASSWORD": SECRET}
    sim = subprocess.Popen([sys.executable, "-m", "conformance.cli", "sim", "--broker",
                            broker.url, "--unit", "pw/unit/air/simulation/dji0"],
                           cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    try:
        assert sim.stdout is not None
        ready = sim.stdout.readline()
        assert ready.startswith("ready"), ready
        done = subprocess.run([sys.executable, "-m", "conformance.cli", "lint", "--broker",
                               f"mqtt://user@127.0.0.1:{broker.port}", "--topic", "pw/#",
                               "--duration", "3s", "--plain", "--reports-dir", "reports"],
                              cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=120)
    finally:
        sim.terminate()
        out_sim = sim.communicate(timeout=20)[0]
        broker.stop()
    out = done.stdout + done.stderr + ready + out_sim
    assert "report:" in done.stdout, out  # it linted and wrote its reports
    assert "mqtt://user@127.0.0.1" in out  # the user is shown, the password never
    assert SECRET not in out and SECRET not in _reports(tmp_path / "reports")


PRINTING = {
    "lint": ["lint", "--duration", "1s", "--reports-dir", "reports"],
    "record": ["record", "--duration", "1s", "-o", "out.jsonl"],
    "profile": ["profile", "--unit", "waraps/unit/air/real/dji0", "--observe", "1s"],
    "sim": ["sim"],
}
"""Every subcommand that takes a broker URL, with what else it needs."""


@pytest.mark.parametrize("command", sorted(PRINTING))
@pytest.mark.parametrize("password", HOSTILE_PASSWORDS)
def test_no_subcommand_prints_a_hostile_password(command, password, tmp_path, monkeypatch,
                                                 capsys):
    """In the URL (refused, shown masked) and in WARAPS_BROKER, in process (fast): the
    password never reaches stdout, stderr or a file."""
    from conformance.cli import main

    monkeypatch.chdir(tmp_path)
    secret = f"SECRET{password}SECRET"
    for env, args in ((None, ["--broker", f"mqtt://user:{secret}@127.0.0.1:1"]),
                      (None, ["--broker", f"user:{secret}@127.0.0.1:1"]),
                      (f"user:{secret}@127.0.0.1", [])):
        if env is None:
            monkeypatch.delenv("WARAPS_BROKER", raising=False)
        else:
            monkeypatch.setenv("WARAPS_BROKER", env)
        try:
            status = main([*PRINTING[command], *args])
        except SystemExit as e:  # argparse's own errors
            status = e.code
        out = capsys.readouterr()
        assert status not in (0, None), out
        assert "SECRET" not in out.out + out.err and "***" in out.err, out
    assert "SECRET" not in _reports(tmp_path)


@pytest.mark.parametrize("password", ["p/w #x?y", "a@b:c@d"])
def test_the_certification_never_prints_a_hostile_password(password, pytester, monkeypatch):
    pytester.makeini("[pytest]\naddopts = -p no:cacheprovider\n")
    secret = f"SECRET{password}SECRET"
    for env, args in (("", ["--broker", f"mqtt://user:{secret}@127.0.0.1:1"]),
                      (f"user:{secret}@127.0.0.1", [])):
        monkeypatch.setenv("WARAPS_BROKER", env)
        result = pytester.runpytest_subprocess("--unit", "waraps/unit/air/simulation/dji0", *args)
        out = result.stdout.str() + result.stderr.str()
        assert result.ret == pytest.ExitCode.USAGE_ERROR and "***" in out, out
        assert "SECRET" not in out


@pytest.mark.parametrize("command", sorted(PRINTING))
@pytest.mark.parametrize("value", ["ture", "enabled", "required", "y", "2"])
def test_an_unknown_tls_setting_is_an_error_never_plaintext(command, value, tmp_path,
                                                            monkeypatch, capsys):
    """WARAPS_TLS_CONNECTION=ture once connected in plaintext and sent the password: now an
    error naming the values accepted, before any connection."""
    from conformance.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("WARAPS_BROKER", "127.0.0.1")
    monkeypatch.setenv("WARAPS_TLS_CONNECTION", value)
    monkeypatch.setenv("WARAPS_PASSWORD", SECRET)
    try:
        status = main(PRINTING[command])
    except SystemExit as e:
        status = e.code
    out = capsys.readouterr()
    assert status not in (0, None), out
    assert f"WARAPS_TLS_CONNECTION='{value}'" in out.err and "true, yes, on" in out.err, out
    assert SECRET not in out.out + out.err


@pytest.mark.parametrize("command", sorted(PRINTING))
@pytest.mark.parametrize("variable", ["WARAPS_USERNAME", "WARAPS_PASSWORD"])
def test_credentials_that_are_not_utf8_are_an_error_never_shown(command, variable, tmp_path,
                                                                monkeypatch, capsys):
    from conformance.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("WARAPS_BROKER", "127.0.0.1")
    monkeypatch.setenv("WARAPS_USERNAME", "user")
    monkeypatch.setenv(variable, "SECRET\udcffSECRET")  # the byte 0xff in the environment
    try:
        status = main(PRINTING[command])
    except SystemExit as e:
        status = e.code
    out = capsys.readouterr()
    assert status not in (0, None), out
    assert f"{variable} is not UTF-8 text (its value is not shown)" in out.err, out
    assert "SECRET" not in out.out + out.err and "Traceback" not in out.err


@pytest.mark.parametrize(("variable", "value", "says"), [
    ("WARAPS_TLS_CONNECTION", "ture", "WARAPS_TLS_CONNECTION='ture' is neither on"),
    ("WARAPS_PASSWORD", "SECRET\udcffSECRET", "WARAPS_PASSWORD is not UTF-8 text"),
])
def test_the_certification_refuses_the_environment_failing_open(variable, value, says,
                                                                pytester, monkeypatch):
    pytester.makeini("[pytest]\naddopts = -p no:cacheprovider\n")
    monkeypatch.setenv("WARAPS_BROKER", "127.0.0.1")
    monkeypatch.setenv("WARAPS_USERNAME", "user")
    monkeypatch.setenv(variable, value)
    result = pytester.runpytest_subprocess("--unit", "waraps/unit/air/simulation/dji0")
    out = result.stdout.str() + result.stderr.str()
    assert result.ret == pytest.ExitCode.USAGE_ERROR and says in out, out
    assert "SECRET" not in out and "INTERNALERROR" not in out

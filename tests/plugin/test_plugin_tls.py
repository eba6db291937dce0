"""TLS and password authentication against a Mosquitto of the test's own: its own self-signed
CA (openssl), a password file (mosquitto_passwd -b), a free port on 127.0.0.1."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from certify_helpers import FAST, PrivateMosquitto, Rebooter, certify

from conformance.client import BrokerURL
from conformance.plugin import NOT_CERTIFIED_EXIT
from conformance.sim import SimUnit

pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    not shutil.which("openssl") or not (shutil.which("mosquitto_passwd")
                                        or Path("/usr/bin/mosquitto_passwd").exists()),
    reason="needs openssl and mosquitto_passwd")]

USER, PASSWORD = "certifier", "pw-8d1f3c"


def openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


@pytest.fixture(scope="module")
def tls_broker(tmp_path_factory: pytest.TempPathFactory):
    """A Mosquitto on 127.0.0.1 speaking only TLS, with a CA of its own and a password file."""
    d = tmp_path_factory.mktemp("tls")
    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj",
            "/CN=waraps-conformance test CA", "-keyout", "ca.key", "-out", "ca.crt", cwd=d)
    openssl("req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=127.0.0.1",
            "-keyout", "server.key", "-out", "server.csr", cwd=d)
    (d / "san.ext").write_text("subjectAltName=IP:127.0.0.1\n")
    openssl("x509", "-req", "-in", "server.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
            "-CAcreateserial", "-days", "2", "-extfile", "san.ext", "-out", "server.crt", cwd=d)
    passwd = shutil.which("mosquitto_passwd") or "/usr/bin/mosquitto_passwd"
    subprocess.run([passwd, "-b", "-c", str(d / "passwd"), USER, PASSWORD], check=True,
                   capture_output=True)
    broker = PrivateMosquitto(d, extra=(
        f"allow_anonymous false\npassword_file {d / 'passwd'}\ncafile {d / 'ca.crt'}\n"
        f"certfile {d / 'server.crt'}\nkeyfile {d / 'server.key'}\n"))
    broker.conf.write_text(broker.conf.read_text().replace("allow_anonymous true\n", ""))
    broker.start()
    yield broker, d
    broker.stop()


def test_certify_over_tls_with_a_password(pytester: pytest.Pytester, tls_broker,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    broker, d = tls_broker
    url = f"mqtts://127.0.0.1:{broker.port}"
    monkeypatch.setenv("WARAPS_USERNAME", USER)
    monkeypatch.setenv("WARAPS_PASSWORD", PASSWORD)
    unit = "waraps/unit/air/simulation/dji0"
    sim_broker = BrokerURL.parse(url).with_tls_files(ca_file=str(d / "ca.crt"))
    with SimUnit(unit, sim_broker, rate=3.0) as sim:
        run = certify(pytester, "--unit", unit, "--broker", url, f"--ca-file={d / 'ca.crt'}",
                      f"--profile={FAST}", "-k", "EXEC-PING or HB-00",
                      plugins=(Rebooter(sim),))
    assert run.result.ret == 0, run.text
    assert run.outcomes["EXEC-PING-001"] == "passed"
    assert f"mqtts://{USER}@127.0.0.1:{broker.port}" in run.text
    assert PASSWORD not in run.text and PASSWORD not in str(run.report)


def test_a_wrong_password_is_one_clear_error(pytester: pytest.Pytester, tls_broker,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    broker, d = tls_broker
    monkeypatch.setenv("WARAPS_USERNAME", USER)
    monkeypatch.setenv("WARAPS_PASSWORD", "not-" + PASSWORD)
    run = certify(pytester, "--unit", "waraps/unit/air/simulation/dji0", "--broker",
                  f"mqtts://127.0.0.1:{broker.port}", f"--ca-file={d / 'ca.crt'}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert "check WARAPS_USERNAME / WARAPS_PASSWORD" in run.text
    assert PASSWORD not in run.text


def test_an_unknown_ca_is_one_clear_error(pytester: pytest.Pytester, tls_broker,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    broker, _ = tls_broker
    monkeypatch.setenv("WARAPS_USERNAME", USER)
    monkeypatch.setenv("WARAPS_PASSWORD", PASSWORD)
    run = certify(pytester, "--unit", "waraps/unit/air/simulation/dji0", "--broker",
                  f"mqtts://127.0.0.1:{broker.port}")
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert "TLS handshake with mqtts://" in run.text and "--ca-file" in run.text

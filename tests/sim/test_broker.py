"""The embedded amqtt broker: loopback only, a free port, clients talk through it, bounded stop."""

from __future__ import annotations

import socket
import subprocess
import sys
import time

import pytest

from conformance.broker import EmbeddedBroker, EmbeddedBrokerError
from conformance.client import BrokerURL, MqttClient


def test_listens_on_loopback_only_and_relays(prefix: str) -> None:
    with EmbeddedBroker() as broker:
        assert broker.url.startswith("mqtt://127.0.0.1:")
        # amqtt binds 0.0.0.0:1883 when left to itself
        # (docs/FIELD-NOTES.md 'The embedded amqtt broker'); ours is loopback only.
        with socket.socket() as s:
            s.settimeout(0.5)
            assert s.connect_ex(("127.0.0.1", broker.port)) == 0
        url = BrokerURL.parse(broker.url)
        sub = MqttClient(url).connect()
        pub = MqttClient(url, may_publish=lambda t: t.startswith(prefix)).connect()
        try:
            sub.subscribe(f"{prefix}/#")
            pub.publish(f"{prefix}/x", b"hello", qos=1)
            m = sub.get(timeout=5)
            assert m is not None and m.payload == b"hello"
        finally:
            pub.close()
            sub.close()


def test_two_brokers_run_side_by_side_on_free_ports() -> None:
    with EmbeddedBroker() as a, EmbeddedBroker() as b:
        assert a.port != b.port


def test_a_taken_port_is_one_clear_error() -> None:
    with EmbeddedBroker() as a:
        with pytest.raises(EmbeddedBrokerError, match="Is the port taken"):
            EmbeddedBroker(a.port).start()


def test_stop_is_bounded_with_clients_still_connected() -> None:
    broker = EmbeddedBroker().start()
    client = MqttClient(BrokerURL.parse(broker.url)).connect()
    t0 = time.monotonic()
    broker.stop(timeout=5.0)
    assert time.monotonic() - t0 < 15  # bounded, not a timing claim: it must not hang
    client.close()


def test_broker_command_prints_its_url_first() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "conformance.cli", "broker"],
                            stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline().strip()  # type: ignore[union-attr]
        assert line.startswith("mqtt://127.0.0.1:")
        MqttClient(BrokerURL.parse(line)).connect().close()
    finally:
        proc.terminate()
        proc.wait(10)

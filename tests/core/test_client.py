"""The MQTT client wrapper (conformance.client) against real brokers."""

from __future__ import annotations

import pytest

from conformance.client import (
    CHUNKED_READS,
    READ_CHUNK,
    BrokerError,
    BrokerURL,
    MqttClient,
    PublishRefused,
)


def test_broker_url_parsing_and_credentials_from_the_environment() -> None:
    env = {"WARAPS_USERNAME": "alice", "WARAPS_PASSWORD": "s3cret"}
    url = BrokerURL.parse("mqtts://broker.example:8883", env)
    assert (url.scheme, url.host, url.port, url.username) == ("mqtts", "broker.example", 8883, "alice")
    assert url.password == "s3cret"
    assert "s3cret" not in repr(url) and "s3cret" not in str(url)
    assert BrokerURL.parse("127.0.0.1", {}).port == 1883
    assert BrokerURL.parse("embedded").scheme == "embedded"


@pytest.mark.parametrize(("text", "message"), [
    ("http://x:1", "scheme 'http' is not one of mqtt, mqtts, embedded"),
    ("mqtt://u:pw@x:1", "put it in WARAPS_PASSWORD"),
    ("mqtt://x:99999", "port is not a number from 1 to 65535"),
])
def test_bad_broker_url_says_how_to_fix(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        BrokerURL.parse(text, {})


def test_arena_environment_variables() -> None:
    env = {"WARAPS_BROKER": "127.0.0.1", "WARAPS_PORT": "8883", "WARAPS_TLS_CONNECTION": "True"}
    url = BrokerURL.from_env(env)
    assert url is not None and (url.scheme, url.port) == ("mqtts", 8883)
    assert BrokerURL.from_env({}) is None


def test_round_trip_and_publish_policy(broker_url: str, prefix: str) -> None:
    allowed = f"{prefix}/unit/air/simulation/dji0/exec/command"
    with MqttClient(BrokerURL.parse(broker_url), may_publish=lambda t: t == allowed) as c:
        c.subscribe(f"{prefix}/#")
        c.publish(allowed, b'{"command": "ping"}')
        m = c.get(timeout=5)
        assert m is not None and (m.topic, m.payload) == (allowed, b'{"command": "ping"}')
        with pytest.raises(PublishRefused, match="docs/ARCHITECTURE.md 'Safety'"):
            c.publish(f"{prefix}/unit/air/simulation/other0/exec/command", b"{}")
        assert c.get(timeout=0.2) is None  # nothing went out


def test_the_payload_policy_refuses_before_anything_goes_out(embedded_broker, prefix: str
                                                             ) -> None:
    """``refuse_payload`` (the suite's motion gate): a topic the policy allows, a payload it
    refuses: PublishRefused with its reason, and nothing reaches the broker."""
    topic = f"{prefix}/unit/air/real/dji0/exec/command"
    url = BrokerURL.parse(embedded_broker.url)
    with MqttClient(url, may_publish=lambda t: t == topic,
                    refuse_payload=lambda t, p: "names move-to" if b"move-to" in p else None
                    ) as c:
        c.subscribe(f"{prefix}/#")
        with pytest.raises(PublishRefused, match="names move-to"):
            c.publish(topic, '{"task": "move-to"}')  # str payloads are judged as bytes too
        assert c.get(timeout=0.3) is None  # nothing went out
        c.publish(topic, b'{"command": "ping"}')
        m = c.get(timeout=5)
        assert m is not None and m.payload == b'{"command": "ping"}'


def test_a_burst_read_in_chunks_arrives_whole_and_in_order(broker_url: str, prefix: str) -> None:
    # Many small packets share a chunk; a big one spans several; packet boundaries fall
    # anywhere in a chunk. Each must arrive once, intact, in order.
    topic = f"{prefix}/unit/air/simulation/dji0/exec/command"
    sizes = [(i * 37) % 300 for i in range(1500)]
    sizes[700] = 3 * READ_CHUNK + 123
    payloads = [bytes([65 + i % 26]) * n + str(i).encode() for i, n in enumerate(sizes)]
    url = BrokerURL.parse(broker_url)
    with MqttClient(url) as sub, MqttClient(url, may_publish=lambda t: t == topic) as pub:
        assert CHUNKED_READS  # the chunked path is the one under test
        sub.subscribe(f"{prefix}/#")
        for p in payloads:
            pub.publish(topic, p, qos=0)
        got: list[bytes] = []
        while len(got) < len(payloads) and (m := sub.get(timeout=10)) is not None:
            got.append(m.payload)
        assert sub.get(timeout=0.2) is None  # and nothing twice
    assert len(got) == len(payloads) and got == payloads


def test_default_client_publishes_nowhere(embedded_broker) -> None:
    with MqttClient(BrokerURL.parse(embedded_broker.url)) as c, pytest.raises(PublishRefused):
        c.publish("anything", b"x")


def test_unreachable_broker_is_one_clear_error() -> None:
    from conformance.broker import free_port

    port = free_port()
    with pytest.raises(BrokerError, match=rf"cannot reach the broker at mqtt://127.0.0.1:{port}"):
        MqttClient(BrokerURL.parse(f"mqtt://127.0.0.1:{port}")).connect(timeout=2)


@pytest.fixture
def password_broker(tmp_path):
    """A Mosquitto of this test's own on a free loopback port that wants a password."""
    from private_mosquitto import PrivateMosquitto

    broker = PrivateMosquitto(tmp_path, users={"alice": "right"}).start()
    yield broker.url
    broker.stop()


def test_a_refused_connection_is_reported_at_once_with_the_fix(password_broker: str) -> None:
    import time

    url = BrokerURL.parse(password_broker, {"WARAPS_USERNAME": "alice", "WARAPS_PASSWORD": "wrong"})
    timeout = 30.0
    started = time.monotonic()
    with pytest.raises(BrokerError, match=r"[Nn]ot authorized.*WARAPS_USERNAME / WARAPS_PASSWORD"):
        MqttClient(url).connect(timeout=timeout)
    # The refusal ends the wait: the CONNACK came back, the deadline was not waited out.
    assert time.monotonic() - started < timeout
    ok = BrokerURL.parse(password_broker, {"WARAPS_USERNAME": "alice", "WARAPS_PASSWORD": "right"})
    MqttClient(ok).connect(timeout=timeout).close()


def test_a_lost_broker_is_one_gap_not_paho_log_lines(tmp_path, caplog) -> None:
    """While the broker is gone, paho's loop logs "Client is not connected" at ERROR between
    reconnect attempts; the gap is the client's to report, and the terminal stays quiet."""
    import time

    from private_mosquitto import PrivateMosquitto

    broker = PrivateMosquitto(tmp_path).start()
    client = broker.client()
    try:
        broker.stop()
        deadline = time.monotonic() + 10.0
        while client.is_connected and time.monotonic() < deadline:
            time.sleep(0.05)  # the loop sees the socket close: bounded by the deadline
        assert not client.is_connected
        time.sleep(2.5)  # paho's backoff (1 s, then 2 s): its loop runs without a socket
        assert client.gaps and client.gaps[-1].end is None
    finally:
        client.close()
    # Under pytest the records reach caplog; on a user's terminal, logging's last resort.
    assert not [r for r in caplog.records if "not connected" in r.getMessage()]

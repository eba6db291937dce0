"""MQTT through paho-mqtt 2.x: the only module that imports paho.

A small typed API in the manner of aiomqtt: ``BrokerURL`` (``conformance/broker_url.py``,
re-exported: parsed, password only from the environment), ``Message`` (arrival time in Unix seconds, topic, raw bytes), and ``MqttClient``
whose every wait is bounded, whose subscriptions survive a reconnect, which records the
connection gaps it lived through, and which refuses to publish where it may not (the linter's
client may publish nowhere; the suite's only to the unit under test).
"""

from __future__ import annotations

import logging
import queue
import ssl
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import cast

import paho.mqtt.client as paho
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode

from conformance.broker_url import BrokerError, BrokerURL  # re-exported, as before
from conformance.masking import mask_password  # noqa: F401 (re-exported: a URL fit to print)
from conformance.message import Gap, Message  # re-exported: ``from conformance.client import ...``


class _NotConnected(logging.Filter):
    """paho logs "Client is not connected" at ERROR when its network loop runs between a lost
    socket and the reconnect, or races a disconnect. The gap is ours to report (in words the
    user can act on, ``Gap.reason``); on the terminal the line only alarms."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith("Client is not connected")


PAHO_LOG = logging.getLogger("paho.mqtt.client")
PAHO_LOG.addFilter(_NotConnected())


class PublishRefused(PermissionError):
    """A publish the safety rules forbid (docs/ARCHITECTURE.md 'Safety'). Never caught to carry
    on."""


PublishPolicy = Callable[[str], bool]
"""Decides whether a topic may be published to (docs/ARCHITECTURE.md 'Safety')."""


def publish_nowhere(topic: str) -> bool:
    """The linter's policy: it never publishes."""
    return False


PayloadPolicy = Callable[[str, bytes], "str | None"]
"""Why a payload may not be published to a topic the ``PublishPolicy`` allows, or None
(the publish policy is the one gate, so no scenario can send what it forbids: the suite's
refuses motion on a real unit; docs/ARCHITECTURE.md 'Safety')."""


READ_CHUNK = 65536
"""Bytes read from the socket at once (see _ChunkedPaho)."""


class _ChunkedPaho(paho.Client):
    """paho's client, reading the socket in chunks.

    paho 2.x reads each packet with three or more ``recv`` calls (the command byte, each byte
    of the remaining length, then the rest) after one ``select`` per packet: four system calls
    for every message. Here ``_sock_recv`` serves those small reads from one 64 KiB ``recv``,
    and ``loop_read`` handles every packet already read before paho's loop selects again (a
    buffered packet would not wake ``select``). On loopback a counting-only subscriber went from
    about 58k to 80k messages/s, and the live linter from 0.68 to 0.88 of plain paho
    (bench/bench_lint.py). paho's packet handling, keepalive, TLS and reconnect are untouched;
    the buffer is emptied whenever paho closes its socket.
    """

    _rbuf = b""
    _rpos = 0

    def _sock_recv(self, bufsize: int) -> bytes:
        buf, pos = self._rbuf, self._rpos
        if pos >= len(buf):
            buf = super()._sock_recv(READ_CHUNK)  # BlockingIOError when nothing is there
            if not buf:
                return buf  # the broker closed the connection
            pos = 0
        self._rbuf, self._rpos = buf, pos + bufsize
        return buf[pos:pos + bufsize]

    def loop_read(self, max_packets: int = 1) -> paho.MQTTErrorCode:
        rc = super().loop_read(max_packets)
        while (rc == paho.MQTT_ERR_SUCCESS and self._rpos < len(self._rbuf)
               and self._sock is not None):
            rc = super().loop_read(max_packets)
        return rc

    def _sock_close(self) -> None:
        self._rbuf, self._rpos = b"", 0  # never parse an old connection's bytes on a new one
        super()._sock_close()


# Chunked reads rely on private methods of paho 2.x; should a release rename them, the plain
# client is used (slower, equally correct).
_Paho = _ChunkedPaho if all(callable(getattr(paho.Client, n, None)) for n in
                            ("_sock_recv", "_sock_close", "_packet_read")) else paho.Client
CHUNKED_READS = _Paho is _ChunkedPaho
"""Whether this paho release lets sockets be read in chunks (``READ_CHUNK``)."""


class MqttClient:
    """A connected MQTT 3.1.1 client (amqtt refuses MQTT 5), or MQTT 5 with ``mqtt5`` (the
    reference unit's variant mqtt5-qos1, on a broker that speaks it).

    ``on_message`` runs on paho's network thread and must be quick; without it, messages are
    queued and read with ``messages()`` / ``get()``. Every wait takes a timeout in seconds.
    """

    def __init__(self, broker: BrokerURL, *, client_id: str | None = None,
                 on_message: Callable[[Message], None] | None = None,
                 may_publish: PublishPolicy = publish_nowhere,
                 refuse_payload: PayloadPolicy | None = None,
                 on_connection_change: Callable[[bool, str], None] | None = None,
                 keepalive: int = 30, mqtt5: bool = False) -> None:
        if broker.scheme in ("embedded", "virtual"):
            raise BrokerError("start the embedded broker first (conformance.broker) and pass "
                              "its mqtt:// URL")
        self.broker = broker
        self.client_id = client_id or f"waraps-conformance-{uuid.uuid4().hex[:12]}"
        self.may_publish = may_publish
        self.refuse_payload = refuse_payload
        self._on_message = on_message
        self._on_connection_change = on_connection_change
        self._queue: queue.Queue[Message] = queue.Queue()
        self._subscriptions: dict[str, int] = {}
        self._connected = threading.Event()
        self._connect_failure: str | None = None
        self._connack = threading.Event()  # any CONNACK, accepted or refused: ends connect()'s wait
        self._lock = threading.Lock()
        self.gaps: list[Gap] = []
        self.received = 0
        # paho stamps msg.timestamp with time.monotonic(); convert once to Unix seconds.
        self._mono_to_unix = time.time() - time.monotonic()
        self._keepalive = keepalive
        self._closing = False
        self.mqtt5 = mqtt5
        """Whether it speaks MQTT 5 (else 3.1.1)."""

        self._paho = self._make_paho(broker, mqtt5)

    def _make_paho(self, broker: BrokerURL, mqtt5: bool) -> paho.Client:
        """paho's client, set up for ``broker`` (credentials, TLS) and wired to this one."""
        # MQTT 5 has no clean_session: its clean start is paho's default.
        session = {"protocol": paho.MQTTv5} if mqtt5 else {"protocol": paho.MQTTv311,
                                                             "clean_session": True}
        c = _Paho(paho.CallbackAPIVersion.VERSION2, client_id=self.client_id, **session)
        c.enable_logger(PAHO_LOG)
        if broker.username:
            c.username_pw_set(broker.username, broker.password)
        if broker.scheme == "mqtts":
            c.tls_set(ca_certs=broker.ca_file, certfile=broker.cert_file,
                      keyfile=broker.key_file, cert_reqs=ssl.CERT_NONE if broker.insecure
                      else ssl.CERT_REQUIRED)
            if broker.insecure:
                c.tls_insecure_set(True)
        c.reconnect_delay_set(min_delay=1, max_delay=30)  # backoff after a dropped connection
        # QoS 1 publishes from a suite are few; bound the unacknowledged window anyway
        # (docs/FIELD-NOTES.md 'MQTT on loopback': paho overwrites past 65,535 in flight).
        c.max_inflight_messages_set(1000)
        c.on_connect = self._handle_connect
        c.on_disconnect = self._handle_disconnect
        c.on_message = self._handle_message
        return c

    def reconnect_backoff(self, max_delay: float) -> None:
        """Retry a dropped connection at least every ``max_delay`` seconds (default 30): a
        client that waits on the broker within a budget must not sleep past it."""
        self._paho.reconnect_delay_set(min_delay=1, max_delay=max(1, int(max_delay)))

    # --- connection -------------------------------------------------------------------------
    def connect(self, timeout: float = 5.0) -> MqttClient:
        """Connect and start the network thread; raise ``BrokerError`` saying what failed."""
        b = self.broker
        try:
            self._paho.connect(b.host, b.port, keepalive=self._keepalive)
        except ssl.SSLError as e:
            raise BrokerError(f"TLS handshake with {b} failed: {e.reason or e}. Check the CA "
                              f"file (--ca-file) and that the broker speaks TLS on this port"
                              ) from None
        except (OSError, UnicodeError) as e:  # UnicodeError: a host name IDNA refuses
            why = (e.strerror if isinstance(e, OSError) else None) or e
            raise BrokerError(f"cannot reach the broker at {b}: {why}. Is it "
                              f"running and listening there? (--broker, WARAPS_BROKER/"
                              f"WARAPS_PORT)") from None
        self._paho.loop_start()
        self._connack.wait(timeout)
        if not self._connected.is_set():
            self._paho.loop_stop()
            reason = self._connect_failure or f"no CONNACK within {timeout:.1f} s"
            raise BrokerError(f"the broker at {b} did not accept the connection: {reason}")
        return self

    def _handle_connect(self, client: paho.Client, userdata: object, flags: paho.ConnectFlags,
                        reason_code: ReasonCode, properties: Properties | None) -> None:
        if reason_code.is_failure:
            self._connect_failure = str(reason_code)
            if str(reason_code).lower().startswith(("not authorized", "bad user")):
                self._connect_failure += (" (check WARAPS_USERNAME / WARAPS_PASSWORD)")
            self._connack.set()
            return
        with self._lock:
            subs = list(self._subscriptions.items())
            if self.gaps and self.gaps[-1].end is None:
                self.gaps[-1] = replace(self.gaps[-1], end=time.time())
        for topic, qos in subs:  # clean session: subscriptions do not survive a reconnect
            client.subscribe(topic, qos)
        self._connected.set()
        self._connack.set()
        if self._on_connection_change:
            self._on_connection_change(True, "connected")

    def _handle_disconnect(self, client: paho.Client, userdata: object,
                           flags: paho.DisconnectFlags, reason_code: ReasonCode,
                           properties: Properties | None) -> None:
        self._connected.clear()
        if self._closing:
            return
        with self._lock:
            self.gaps.append(Gap(time.time(), None, str(reason_code)))
        if self._on_connection_change:
            self._on_connection_change(False, str(reason_code))

    @property
    def is_connected(self) -> bool:
        return self._connected.is_set()

    def wait_connected(self, timeout: float) -> bool:
        return self._connected.wait(timeout)

    def close(self, timeout: float = 2.0) -> None:
        """Disconnect cleanly (before an embedded broker shuts down:
        docs/FIELD-NOTES.md 'The embedded amqtt broker')."""
        self._closing = True
        try:
            self._paho.disconnect()
        finally:
            self._paho.loop_stop()

    def __enter__(self) -> MqttClient:
        if not self.is_connected:
            self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- messages ---------------------------------------------------------------------------
    def subscribe(self, topic: str, qos: int = 0, timeout: float = 5.0) -> None:
        """Subscribe and wait for the SUBACK, so nothing published afterwards is missed."""
        done = threading.Event()
        result: list[list[ReasonCode]] = []

        def on_subscribe(client: paho.Client, userdata: object, mid: int,
                         reason_codes: list[ReasonCode], properties: Properties | None) -> None:
            result.append(reason_codes)
            done.set()

        with self._lock:
            self._subscriptions[topic] = qos
        self._paho.on_subscribe = on_subscribe
        rc, _ = self._paho.subscribe(topic, qos)
        if rc != paho.MQTT_ERR_SUCCESS:
            raise BrokerError(f"subscribe to {topic!r} failed: {paho.error_string(rc)}")
        if not done.wait(timeout):
            raise BrokerError(f"no SUBACK for {topic!r} within {timeout:.1f} s")
        codes: list[ReasonCode] = result[0] if result else []
        if any(getattr(c, "is_failure", False) for c in codes):
            raise BrokerError(f"the broker refused the subscription to {topic!r}: {codes} "
                              f"(an ACL may forbid it)")

    def _handle_message(self, client: paho.Client, userdata: object,
                        msg: paho.MQTTMessage) -> None:
        self.received += 1
        # A received payload is bytes (a bytearray only where paho builds one to send).
        m = Message(msg.timestamp + self._mono_to_unix, msg.topic, cast(bytes, msg.payload),
                    msg.qos, bool(msg.retain))
        if self._on_message is not None:
            self._on_message(m)
        else:
            self._queue.put(m)

    def get(self, timeout: float) -> Message | None:
        """The next queued message, or None after ``timeout`` seconds."""
        try:
            return self._queue.get(timeout=max(0.0, timeout))
        except queue.Empty:
            return None

    def messages(self, timeout: float) -> Iterator[Message]:
        """Queued messages until ``timeout`` seconds have passed (a deadline, not a sleep)."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            m = self.get(left)
            if m is not None:
                yield m

    def publish(self, topic: str, payload: bytes | str, qos: int = 1, retain: bool = False,
                timeout: float = 5.0, wait: bool = True) -> None:
        """Publish where the policy allows; with QoS > 0 (and ``wait``) wait for the broker's
        ack (paho resends an unacknowledged one either way)."""
        if not self.may_publish(topic):
            raise PublishRefused(f"refusing to publish to {topic!r}: not a command topic of "
                                 f"the unit under test (docs/ARCHITECTURE.md 'Safety')")
        if self.refuse_payload is not None:
            why = self.refuse_payload(topic, payload.encode() if isinstance(payload, str)
                                      else bytes(payload))
            if why:
                raise PublishRefused(f"refusing to publish to {topic!r}: {why}")
        info = self._paho.publish(topic, payload, qos=qos, retain=retain)
        if info.rc != paho.MQTT_ERR_SUCCESS and info.rc != paho.MQTT_ERR_NO_CONN:
            raise BrokerError(f"publish to {topic!r} failed: {paho.error_string(info.rc)}")
        if qos > 0 and wait:
            try:
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError) as e:
                raise BrokerError(f"publish to {topic!r} not acknowledged: {e}") from None

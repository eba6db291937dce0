"""The embedded amqtt broker: the zero-setup default for the demo and for tests.

Runs amqtt on its own event loop in a background thread, on 127.0.0.1 only (amqtt binds
0.0.0.0:1883 when left to itself), on a free port unless one is given. The pitfalls of
docs/FIELD-NOTES.md 'The embedded amqtt broker'
handled here: ``Broker()`` is created inside the running loop; the anonymous-auth plugin stays
(without it every connect fails "Not authorized"); shutdown is bounded by a timeout because
amqtt 0.12 can hang on clients with QoS 1 acks in flight.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
import warnings
from typing import Any

HOST = "127.0.0.1"


class EmbeddedBrokerError(RuntimeError):
    pass


def free_port(host: str = HOST) -> int:
    """A TCP port on loopback that nothing listens on right now."""
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def _config(port: int) -> dict[str, Any]:
    return {
        "listeners": {"default": {"type": "tcp", "bind": f"{HOST}:{port}", "max_connections": 0}},
        # Only what a broker needs: anonymous auth
        # (docs/FIELD-NOTES.md 'The embedded amqtt broker': the default plugin set costs
        # ~35 % throughput and the $SYS plugin warns about psutil).
        "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin": {"allow_anonymous": True}},
    }


class EmbeddedBroker:
    """An amqtt broker on loopback in a background thread.

    >>> with EmbeddedBroker() as broker:
    ...     url = broker.url          # 'mqtt://127.0.0.1:PORT'
    """

    def __init__(self, port: int | None = None) -> None:
        self.port = port or free_port()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._broker: Any = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def url(self) -> str:
        return f"mqtt://{HOST}:{self.port}"

    def start(self, timeout: float = 10.0) -> EmbeddedBroker:
        """Start and return once the broker accepts connections (typically 5-200 ms)."""
        self._thread = threading.Thread(target=self._run, name=f"amqtt-{self.port}", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise EmbeddedBrokerError(f"the embedded broker did not start within {timeout} s")
        if self._error is not None:
            raise EmbeddedBrokerError(
                f"the embedded broker could not listen on {HOST}:{self.port}: {self._error}. "
                f"Is the port taken? Leave --port out to use a free one") from self._error
        return self

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._start())
        except BaseException as e:  # reported to start()
            self._error = e
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
            for t in pending:
                t.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

    async def _start(self) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from amqtt.broker import Broker  # costs ~95 ms: import only when started
        # amqtt logs every connection at INFO and tracebacks of clients that vanish; keep quiet.
        logging.getLogger("amqtt").setLevel(logging.ERROR)
        logging.getLogger("transitions").setLevel(logging.ERROR)
        self._broker = Broker(_config(self.port))  # must be created inside the running loop
        await self._broker.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Shut down; bounded by ``timeout`` seconds even when amqtt hangs."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None or not thread.is_alive():
            return
        fut = asyncio.run_coroutine_threadsafe(self._broker.shutdown(), loop)
        try:
            fut.result(timeout)
        except Exception:  # a hung or failed shutdown must not hang the caller
            fut.cancel()
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout)

    def __enter__(self) -> EmbeddedBroker:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def serve(port: int | None = None) -> None:
    """Run a broker in the foreground until Ctrl-C (``waraps-conformance broker``)."""
    broker = EmbeddedBroker(port).start()
    print(broker.url, flush=True)  # for other processes: the first line is the URL
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        broker.stop()

"""The tests' Mosquitto fixture cleans up what it starts: the last process that used the daemon
it started stops it; a daemon that was already running is left alone."""

from __future__ import annotations

import contextlib
import subprocess

from private_mosquitto import PrivateMosquitto
from shared_mosquitto import listening, shared_mosquitto

from conformance.broker import free_port


def test_the_last_user_stops_the_daemon_it_started_whoever_started_it(tmp_path) -> None:
    port = free_port()
    first, second = contextlib.ExitStack(), contextlib.ExitStack()
    assert first.enter_context(shared_mosquitto(port=port, run=tmp_path))  # starts it
    assert second.enter_context(shared_mosquitto(port=port, run=tmp_path))  # another worker
    first.close()
    assert listening("127.0.0.1", port), "stopped under a worker still using it"
    second.close()
    assert not listening("127.0.0.1", port), "left running"
    assert not (tmp_path / "mosquitto.pid").exists()


def test_a_user_that_died_without_leaving_does_not_keep_it_running(tmp_path) -> None:
    port = free_port()
    gone = subprocess.Popen(["true"])
    gone.wait()  # its pid no longer runs: a worker killed before it could leave
    with shared_mosquitto(port=port, run=tmp_path):
        (tmp_path / "users" / f"{gone.pid}-killed").touch()
    assert not listening("127.0.0.1", port)


def test_a_daemon_that_was_already_running_is_left_alone(tmp_path) -> None:
    private = PrivateMosquitto(tmp_path / "private").start()
    try:
        with shared_mosquitto(port=private.port, run=tmp_path / "run") as up:
            assert up
        assert listening("127.0.0.1", private.port)
    finally:
        private.stop()

"""Fixtures of the simulator's tests: observers that record and command over a real broker."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from sim_observer import Observer


@pytest.fixture
def observe() -> Iterator[Callable[..., Observer]]:
    """Make observers: ``observe(broker_url, "prefix/#", command_topics=(...))``; closed at the
    end of the test."""
    made: list[Observer] = []

    def make(broker: str, topic_filter: str, command_topics: tuple[str, ...] = ()) -> Observer:
        o = Observer(broker, topic_filter, command_topics)
        made.append(o)
        return o

    yield make
    for o in made:
        o.close()

"""Fuzz target: an ``--explore-replay`` file (``conformance.scenarios.story.load``), the story an
earlier exploration stored, as JSON text.

Invariant: ``load`` returns at most ``MAX_STEPS`` actions or raises ``StoryError`` with a
one-line message; every action it returns is one the explorer can run: its fields of the right
types (a task name and a signal name in UTF-8, a slot and a step that are whole numbers from
0), and it is described
(``story.describe``) without raising. Time proportional to the input.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from dataclasses import fields
from pathlib import Path

from conformance.scenarios.explore_action import Action
from conformance.scenarios.explore_steps import MAX_STEPS
from conformance.scenarios.story import StoryError, describe, load
from fuzz.harness import Broken, one_line, within_time

PATH = Path(tempfile.mkdtemp(prefix="fuzz-story-")) / "story.json"
atexit.register(shutil.rmtree, PATH.parent, True)


def prepare() -> None:
    """Nothing to build."""


def _runnable(action: Action) -> None:
    # Every field of the typed step is what the explorer reads; the rest was ignored.
    for f in fields(action):
        value = getattr(action, f.name)
        if f.name in ("slot", "step", "periods") and value is not None \
                and (type(value) is not int or value < 0):
            raise Broken(f"a step with {f.name} {value!r} was accepted: {action}")
        if f.name in ("task", "signal") and type(value) is not str:
            raise Broken(f"a step with {f.name} {value!r} was accepted: {action}")
        if f.name in ("task", "signal"):
            try:  # a name is sent in a command: UTF-8 (a lone surrogate once a TypeError)
                value.encode("utf-8")
            except UnicodeEncodeError:
                raise Broken(f"a step with a {f.name} that is not UTF-8 was accepted") from None
        if f.name in ("task_uuid", "teardown") and type(value) is not bool:
            raise Broken(f"a step with {f.name} {value!r} was accepted: {action}")
    describe(action)


def test_one_input(data: bytes) -> None:
    PATH.write_bytes(data)
    with within_time(len(data)):
        try:
            actions, _ = load(PATH)
        except StoryError as e:
            one_line(e, "story error", shown=True)
            return
        if len(actions) > MAX_STEPS:
            raise Broken(f"a story of {len(actions)} steps was accepted (at most {MAX_STEPS})")
        for action in actions:
            _runnable(action)



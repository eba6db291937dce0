"""Fuzz target: an ``--explore-replay`` file (``conformance.scenarios.story.load``), the story an
earlier exploration stored, as JSON text.

Invariant: ``load`` returns actions or raises ``StoryError`` with a one-line message; every
action it returns is one the explorer can run: its fields of the right types (a task name, a
slot and a step that are whole numbers from 0, a signal name), and it is described
(``story.describe``) without raising. Time proportional to the input.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

from conformance.scenarios.story import FIELDS, StoryError, describe, load
from fuzz.harness import Broken, one_line, within_time

PATH = Path(tempfile.mkdtemp(prefix="fuzz-story-")) / "story.json"
atexit.register(shutil.rmtree, PATH.parent, True)
NEEDS = {"start": ("task",), "signal": ("signal",), "resend": ("step",)}


def prepare() -> None:
    """Nothing to build."""


def _runnable(action: dict) -> None:
    for key in NEEDS.get(action["do"], ()):
        if key not in action:
            raise Broken(f"a {action['do']} step without {key!r} was accepted: {action}")
    own = FIELDS[action["do"]]  # what the explorer reads of this kind of step; the rest it ignores
    for key in ("slot", "step", "periods"):
        if key not in own:
            continue
        value = action.get(key)
        if value is not None and (type(value) is not int or value < 0):
            raise Broken(f"a step with {key} {value!r} was accepted: {action}")
    for key in ("task", "signal"):
        if key in own and key in action and type(action[key]) is not str:
            raise Broken(f"a step with {key} {action[key]!r} was accepted")
    describe(action)


def test_one_input(data: bytes) -> None:
    PATH.write_bytes(data)
    with within_time(len(data)):
        try:
            actions, _ = load(PATH)
        except StoryError as e:
            one_line(e, "story error", shown=True)
            return
        for action in actions:
            _runnable(action)



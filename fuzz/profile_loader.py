"""Fuzz target: a profile file (``conformance.profile.load``): YAML text as a user or
``waraps-conformance profile`` writes it, loaded and checked key by key.

Invariant: ``load`` returns a ``Profile`` or raises ``ProfileError`` with a one-line message
(where and how to fix it); a profile loaded has finite numbers; time and memory proportional
to the input (no billion laughs, no extends cycle, no deep recursion). The loader's hardening
is tested apart (tests/core/test_profile_forged.py); this target finds what it misses.
"""

from __future__ import annotations

import atexit
import dataclasses
import math
import os
import shutil
import tempfile

from conformance.profile import ProfileError, load
from fuzz.harness import Broken, one_line, within_time

_DIR = tempfile.mkdtemp(prefix="fuzz-profile-")
atexit.register(shutil.rmtree, _DIR, True)
PATH = os.path.join(_DIR, "profile.yaml")


def prepare() -> None:
    """Load the built-in profiles once, instrumented."""
    load("default")


def test_one_input(data: bytes) -> None:
    with open(PATH, "wb") as f:
        f.write(data)
    with within_time(len(data)):
        try:
            profile = load(PATH)
        except ProfileError as e:
            one_line(e, "profile error", shown=True)
            return
    for item in dataclasses.fields(profile):
        value = getattr(profile, item.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise Broken(f"profile loaded with {item.name} = {value!r}")

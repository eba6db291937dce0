"""Profiles that cannot be forged: the loader reads a YAML subset, refusing
what a profile never needs (anchors, aliases, tags, size, depth, numbers that are not finite,
non-UTF-8, extends cycles) with one line naming the file, where and the fix: no hang, no
traceback, whatever the file holds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from conformance import profile
from conformance.profile import ProfileError

LAUGHS = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True))


@pytest.mark.parametrize(("text", "message"), [
    (LAUGHS.encode(), "line 1: an anchor (&a); remove it (a profile takes no anchors"),
    (b"name: x\ndescription: *x\n", "an alias (*x); write the value out"),
    (b"name: !!python/object:os.system x\n", "line 1: a tag (tag:yaml.org,2002:python/"),
    (b"name: !!binary aGVsbG8=\n", "a tag (tag:yaml.org,2002:binary)"),
    (b"x: " + b"[" * 10_000 + b"]" * 10_000 + b"\n", "nested deeper than 32 levels"),
    (b"a:\n" + b"".join(b" " * i + b"- \n" for i in range(1, 200)), "nested deeper than 32"),
    (b"safe-radius: .inf\n", "safe-radius: inf is not a finite number; write a number"),
    (b"rate-tolerance: .nan\n", "rate-tolerance: nan is not a finite number"),
    (b"safe-radius: 1" + b"0" * 400 + b"\n", "line 1: a number written in 401 characters"),
    (b"safe-radius: 12345678901234567\n", "is beyond 1e+15; write a smaller number"),
    # Python's own 4300-digit limit, and a base-60 integer it cannot print: refused first.
    (b"rate-tolerance: " + b"1" * 5000 + b"\n", "line 1: a number written in 5000 characters"),
    (b"safe-radius: " + b":".join([b"1"] * 3000) + b"\n", "a number written in 5999 characters"),
    (b"tasks:\n  go-home: {params: {speed: -.inf}}\n", "tasks.go-home.params.speed: -inf"),
    (b"name: caf\xe9\n", "line 1: byte 0xe9 is not UTF-8; save the file as UTF-8"),
    (b"description: '" + b"x" * (1024 * 1024) + b"'\n", "over the 1048576-byte bound"),
])
def test_a_forged_profile_is_refused_in_one_line(tmp_path: Path, text: bytes,
                                                 message: str) -> None:
    path = tmp_path / "forged.yaml"
    path.write_bytes(text)
    with pytest.raises(ProfileError) as e:
        profile.load(path)
    assert message in str(e.value)
    assert str(e.value).startswith(f"{path}: ") and "\n" not in str(e.value)


def test_an_extends_cycle_is_refused_with_its_chain(tmp_path: Path) -> None:
    own = tmp_path / "own.yaml"
    own.write_text(f"extends: {own}\n")
    with pytest.raises(ProfileError, match=r"extends itself \(.*own.yaml -> .*own.yaml\)"):
        profile.load(own)
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text(f"extends: {b}\nname: a\n")
    b.write_text(f"extends: {a}\nname: b\n")
    with pytest.raises(ProfileError) as e:
        profile.load(a)
    assert "a.yaml -> " in str(e.value) and "b.yaml -> " in str(e.value)
    assert "remove an extends" in str(e.value)


def test_a_billion_laughs_profile_ends_the_run_with_one_line_at_once(tmp_path: Path) -> None:
    """The console script, as a user runs it: exit status 2, one line, no traceback (the
    payload expands to 10^9 strings if composed: a hang, not a refusal)."""
    path = tmp_path / "laughs.yaml"
    path.write_text(LAUGHS)
    run = subprocess.run([sys.executable, "-m", "conformance.cli", "lint", "--from", "-",
                          "--profile", str(path)], input=b"", capture_output=True,
                         timeout=60)
    assert "Traceback" not in run.stderr.decode()
    assert "an anchor (&a)" in (run.stderr + run.stdout).decode()
    assert run.returncode != 0


def test_the_builtin_profiles_and_documented_examples_are_in_the_subset() -> None:
    for name in profile.builtin_names():
        profile.load(name)
    for example in sorted(Path(__file__).parents[2].joinpath("docs", "profiles").glob("*.yaml")):
        profile.load(example)


@pytest.mark.parametrize("value", [b"1" * 5000, b":".join([b"1"] * 3000)],
                         ids=["5000-digits", "base-60-3000-parts"])
@pytest.mark.parametrize("command", ["pytest", "validate", "lint"])
def test_a_profile_number_past_the_bound_is_one_line_everywhere(tmp_path: Path, value: bytes,
                                                                command: str) -> None:
    """Once an INTERNALERROR in pytest, a traceback in validate and Python's own words
    ('Exceeds the limit (4300 digits)') in lint: now the loader's one line, usage's status."""
    path = tmp_path / "big.yaml"
    path.write_bytes(b"extends: default\nsafe-radius: " + value + b"\n")
    recording = tmp_path / "r.jsonl"
    recording.write_text('{"ts": 1763700000.0, "topic": "waraps/unit/air/simulation/u0/'
                         'heartbeat", "payload": "{}"}\n')
    argv = {"pytest": ["-m", "pytest", "-p", "no:cacheprovider", "--unit",
                       "waraps/unit/air/simulation/dji0", "--broker", "virtual"],
            "validate": ["-m", "conformance.cli", "validate", "waraps/unit/air/simulation/u0/"
                         "heartbeat", str(recording)],
            "lint": ["-m", "conformance.cli", "lint", "--from", str(recording),
                     "--format", "none"]}[command]
    done = subprocess.run([sys.executable, *argv, "--profile", str(path)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    out = done.stdout + done.stderr
    assert done.returncode in (2, 4), out  # usage (pytest's is 4)
    assert "a number written in" in out, out
    assert "Traceback" not in out and "INTERNALERROR" not in out and "4300" not in out

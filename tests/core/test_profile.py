"""Profiles (conformance.profile): built-ins, user files, and precise errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from conformance import profile
from conformance.profile import ProfileError
from conformance.rules import Severity


def test_builtin_profiles_load_from_the_package() -> None:
    assert {"default", "strict"} <= set(profile.builtin_names())
    default, strict = profile.load("default"), profile.load("strict")
    assert default.severity_of("ERR-010") is Severity.WARNING
    assert strict.severity_of("ERR-010") is Severity.ERROR
    assert strict.severity_of("HB-003") is Severity.ERROR
    assert strict.is_strict and not default.is_strict


def test_user_file_extends_a_builtin(tmp_path: Path) -> None:
    path = tmp_path / "drone.yaml"
    path.write_text("extends: strict\nname: my-drone\nmotion-tasks: [move-to]\n"
                    "safe-radius: 20\nrate-tolerance: 0.1\n")
    p = profile.load(path)
    assert (p.name, p.motion_tasks, p.safe_radius, p.rate_tolerance) == (
        "my-drone", ("move-to",), 20.0, 0.1)
    assert p.severity_of("ERR-001") is Severity.ERROR  # inherited from strict
    assert p.source == str(path)


@pytest.mark.parametrize(("text", "message"), [
    ("rate-tolerence: 0.1\n", "unknown key 'rate-tolerence' (did you mean 'rate_tolerance'?)"),
    ("safe-radius: -3\n", "safe-radius must be a non-negative number"),
    ("tasks: move-to\n", "tasks must be a list of strings"),
    ("severity: {HB003: error}\n", "'HB003' matches no rule id (did you mean HB-003?)"),
    ("severity: {HB-003: fatal}\n", "'fatal' is not error or warning"),
    ("min-intervals: 1\n", "min-intervals must be a whole number >= 2"),
    ("- a\n- b\n", "a profile is a mapping"),
    ("a: [\n", "not valid YAML"),
])
def test_bad_profile_names_file_key_and_fix(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ProfileError) as err:
        profile.load(path)
    assert message in str(err.value)
    assert str(path) in str(err.value)


def test_unknown_profile_name_lists_the_builtins() -> None:
    with pytest.raises(ProfileError, match=r"neither a built-in profile \(.*strict.*\)"):
        profile.load("strickt")

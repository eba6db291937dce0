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
    ("rate-tolerence: 0.1\n", "unknown key 'rate-tolerence' (did you mean 'rate-tolerance'?)"),
    ("safe-radius: -3\n", "safe-radius must be a non-negative number"),
    ("tasks: move-to\n", "tasks must be a list of task names, or a mapping"),
    ("severity: {HB003: error}\n", "'HB003' matches no rule id (did you mean HB-003?)"),
    ("severity: {HB-003: fatal}\n", "severity.HB-003: 'fatal' is not one of 'error', 'warning'"),
    ("levels: [sensor, direct_execution]\n",
     "levels[1]: 'direct_execution' is not one of 'sensor', 'direct execution', 'tst execution', "
     "'delegation' (did you mean 'direct execution'?)"),
    ("motion_tasks: [move-to, 3]\n", "motion-tasks must be a list of strings, got ['move-to', 3]"),
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


def test_a_task_has_its_own_feedback_deadline(tmp_path: Path) -> None:
    """A unit moving at its real speed: one task's feedback deadline from the profile, the
    others keep the profile's feedback_timeout (scenarios' Timing.feedback_for)."""
    from conformance.scenarios.context import Timing

    path = tmp_path / "slow.yaml"
    path.write_text("extends: default\nfeedback_timeout: 20\ntasks:\n  move-to:\n"
                    "    feedback-timeout: 90\n  look-at-bearing:\n")
    p = profile.load(path)
    assert p.task_feedback_timeouts == {"move-to": 90.0}
    timing = Timing(p, scale=2.0)
    assert (timing.feedback_for("move-to"), timing.feedback_for("look-at-bearing")) == (180, 40)
    path.write_text("tasks:\n  move-to:\n    feedback-timeout: 0\n")
    with pytest.raises(ProfileError):
        profile.load(path)


def test_unknown_profile_name_lists_the_builtins() -> None:
    with pytest.raises(ProfileError, match=r"neither a built-in profile \(.*strict.*\)"):
        profile.load("strickt")


def test_the_schema_states_exactly_the_profile_keys() -> None:
    """profiles/profile.schema.json is the one statement of the format: a key of Profile
    without a schema entry (or the reverse) would be undocumented or unloadable."""
    # task-params, task-scenarios and task-feedback-timeouts are read from 'tasks' written
    # as a mapping
    fields = {f.replace("_", "-") for f in profile.Profile.__dataclass_fields__} - {
        "source", "task-params", "task-scenarios", "task-feedback-timeouts"}
    assert set(profile.schema()["properties"]) == fields | {"extends"}
    for key, prop in profile.schema()["properties"].items():
        assert prop.get("description"), f"{key} has no description"


def test_the_schema_defaults_are_the_profile_defaults() -> None:
    defaults = profile.Profile()
    for key, prop in profile.schema()["properties"].items():
        if "default" in prop:
            value = getattr(defaults, key.replace("-", "_"))
            assert (list(value) if isinstance(value, tuple) else value) == prop["default"], key


EXAMPLES = sorted((Path(__file__).parents[2] / "docs" / "profiles").glob("*.yaml"))


def test_there_is_a_commented_example_per_kind_of_unit() -> None:
    from conformance.topics import AGENT_TYPES

    assert {p.stem for p in EXAMPLES} == set(AGENT_TYPES)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_each_example_profile_loads_and_names_real_tasks(path: Path) -> None:
    from conformance.taskspec import task_specs

    p = profile.load(path)
    known = {s.name for s in task_specs()}
    # a task outside section 9 only with the parameters to start it
    assert set(p.tasks) - set(p.task_params) <= known
    assert set(p.motion_tasks) <= known | set(p.task_params)
    assert set(p.motion_tasks) <= set(p.tasks) or not p.tasks
    assert path.read_text().count("#") >= 5, "an example explains itself in comments"

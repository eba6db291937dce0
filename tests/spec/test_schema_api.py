"""conformance.schema: the API colleagues build on (kinds -> schemas, task specs, params
schemas, the hash), and package data that works outside the source tree."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from conformance import schema, taskspec

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(("kind", "path"), [
    ("heartbeat", "messages/heartbeat.json"),
    ("sensor/position", "messages/sensor-position.json"),
    ("sensor/course", "messages/sensor-angle.json"),
    ("sensor/camera_url", "messages/sensor-url.json"),
    ("sensor/battery_state", None),
    ("exec/command/start-task", "messages/exec-command.json"),
    ("exec/command", "messages/exec-command.json"),
    ("tst/command/signal-unit", "messages/tst-command.json"),
    ("tst/feedback", "messages/tst-feedback.json"),
    ("unknown", None),
])
def test_schema_for_each_kind(kind: str, path: str | None) -> None:
    assert schema.schema_path_for_kind(kind) == path


def test_params_schema_is_self_contained_and_equivalent() -> None:
    for spec in taskspec.task_specs():
        bundled = taskspec.params_schema(spec.name)
        assert "$ref" not in json.dumps(bundled)
        shipped = taskspec.params_schema(spec.name, bundled=False)
        uses_geopoint = any(p.type.startswith("geopoint") for p in spec.parameters)
        assert ("$ref" in json.dumps(shipped)) == uses_geopoint
        assert jsonschema.Draft202012Validator(bundled).is_valid(spec.example)
        assert not jsonschema.Draft202012Validator(bundled).is_valid({"zz-unknown": 1})


def test_unknown_task_names_close_matches() -> None:
    with pytest.raises(KeyError, match="did you mean move-to"):
        taskspec.task_spec("move_to")
    with pytest.raises(KeyError):
        taskspec.params_schema("dance")


def test_task_spec_parameters() -> None:
    spec = taskspec.task_spec("move-path")
    assert spec.parameter("speed").constraints["enum"] == ["fast", "standard", "slow"]
    assert spec.parameter("waypoints").required and spec.parameter("waypoints").type == "geopoints"
    with pytest.raises(KeyError, match="has no parameter"):
        spec.parameter("altitude")
    assert taskspec.task_spec("look-at-position").feedback_statuses == (
        "in-view-center", "in-view", "not-in-view")


def test_inline_refs_cuts_recursion() -> None:
    tst = schema.inline_refs(schema.load("generated/start-tst.json"), max_depth=1)
    text = json.dumps(tst)
    assert "$ref" not in text and '"items": false' in text


def test_rule_annotations_follow_refs() -> None:
    path = ("properties", "task", "$ref", "allOf", 0, "then", "properties", "params", "$ref",
            "properties", "waypoint", "$ref", "properties", "latitude", "maximum")
    assert schema.rule_annotations("generated/start-task.json", path).rule == "TASK-001"
    assert schema.rule_annotations("messages/sensor-position.json",
                                   ("$ref", "properties", "latitude", "maximum")).rule \
        == "SENS-001"
    # ERR-010: a task's GeoPoint (every example of one is a task's: 10, 11)
    err = schema.rule_annotations("generated/params/move-to.json",
                                  ("properties", "waypoint", "$ref", "allOf", 0, "required"))
    assert err.rule == "ERR-010" and err.expected and "rostype" in err.expected


def test_package_data_works_outside_the_source_tree(tmp_path: Path) -> None:
    """A non-editable build ships the schemas; they load and validate from another cwd."""
    build = subprocess.run(
        [sys.executable, "-c", "from setuptools import setup; "
         f"setup(script_args=['-q', 'build_py', '-d', {str(tmp_path / 'lib')!r}])"],
        cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert build.returncode == 0, build.stderr
    lib = str(tmp_path / "lib")
    command = json.dumps({"command": "start-task", "com-uuid": "b992552b-90b0-4911-8707-"
                          "d6f808362bd2", "task": {"name": "move-to", "params": {}}})
    probe = "\n".join([
        "import conformance.schema as s, conformance.validator as v",
        f"assert s.__file__.startswith({lib!r}), s.__file__",
        "print(s.schemas_hash())",
        f"m = v.validate('waraps/unit/air/simulation/dji0/exec/command', {command!r})",
        "print([x.rule for x in m.violations])",
    ])
    env = {**os.environ, "PYTHONPATH": lib}
    out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    hash_line, rules_line = out.stdout.split("\n")[:2]
    assert hash_line == schema.schemas_hash()
    assert rules_line == "['TASK-001']"

"""The task specification files and the deterministic schema generator (items 2-3)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from conformance import schema, specgen, taskspec
from conformance.cli import schemas as schemas_cli

SECTION_9 = ["image-object-detection", "look-at-bearing", "look-at-position",
             "look-at-positions", "move-path", "move-to", "observe-position", "search-area",
             "search-areas", "search-around-position", "land", "navigate", "take-off"]


def test_one_task_file_per_task_of_section_9() -> None:
    assert sorted(taskspec.task_names()) == sorted(SECTION_9)


@pytest.mark.parametrize("name", SECTION_9)
def test_task_file_states_name_description_tags_types_and_why(name: str) -> None:
    spec = taskspec.task_spec(name)
    assert spec.description and spec.section.startswith("9.")
    assert spec.required_why, "the file must record why its parameters are (not) required"
    for p in spec.parameters:
        assert p.type in taskspec.SPEC_TYPES and p.description
    if spec.tags != spec.spec_tags:
        assert spec.raw.get("tags-why"), "a tag that differs from the spec needs a reason"


def test_vehicle_tag_marks_every_task_that_moves_the_unit() -> None:
    moving = {s.name for s in taskspec.task_specs() if s.moves_unit}
    assert {"move-to", "move-path", "navigate", "land", "take-off", "search-area",
            "search-areas", "search-around-position", "observe-position"} == moving


@pytest.mark.parametrize("name", SECTION_9)
def test_each_task_example_is_valid_under_its_params_schema(name: str) -> None:
    spec = taskspec.task_spec(name)
    errors = list(schema.compiled(taskspec.params_schema_path(name)).iter_errors(spec.example))
    assert not errors, [e.message for e in errors]
    # The bundled form (no $ref) says the same, for colleagues' generators and jsonschema.
    jsonschema.Draft202012Validator(taskspec.params_schema(name)).validate(spec.example)


def test_prose_constraints_are_in_the_schemas() -> None:
    move = taskspec.params_schema("move-to")
    assert move["properties"]["speed"]["enum"] == ["fast", "standard", "slow"]
    area = taskspec.params_schema("search-area")["properties"]["area"]
    assert area["minItems"] == 3  # 9.9: a closed polygon
    areas = taskspec.params_schema("search-areas")["properties"]["areas"]
    assert areas["items"]["minItems"] == 3
    nav = taskspec.params_schema("navigate")["properties"]["speed"]
    assert nav["items"]["enum"] == ["fast", "standard", "slow"]
    duration = taskspec.params_schema("observe-position")["properties"]["duration"]
    assert duration["type"] == "integer" and duration["minimum"] == -(2**31)


def test_every_schema_file_is_a_valid_draft_2020_12_schema() -> None:
    for name in schema.files():
        if name.endswith(".json"):
            document = schema.load(name)
            assert document["$schema"] == "https://json-schema.org/draft/2020-12/schema", name
            jsonschema.Draft202012Validator.check_schema(document)
            schema.compiled(name)


def test_commands_pick_params_by_if_then_not_oneof() -> None:
    text = json.dumps(schema.load("generated/start-task.json"))
    assert '"if"' in text and "oneOf" not in text
    tst = schema.load("generated/start-tst.json")
    assert tst["$defs"]["node"]["properties"]["children"]["items"] == {"$ref": "#/$defs/node"}


def test_generation_is_deterministic() -> None:
    assert specgen.generate_files() == specgen.generate_files()
    for rel, text in specgen.generate_files().items():
        if rel.endswith(".json"):
            assert text == specgen.dumps(json.loads(text)), f"{rel} is not in canonical form"


def test_committed_generated_files_are_fresh(tmp_path: Path) -> None:
    specgen.write(tmp_path)
    committed = {k[len("generated/"):]: v.decode() for k, v in schema.files().items()
                 if k.startswith("generated/")}
    fresh = {p.relative_to(tmp_path).as_posix(): p.read_text("utf-8")
             for p in sorted(tmp_path.rglob("*")) if p.is_file()}
    stale = sorted(k for k in fresh.keys() | committed.keys() if fresh.get(k) != committed.get(k))
    assert not stale, (f"schemas/generated is stale ({', '.join(stale)}): run "
                       f"`{specgen.REGENERATE}` and commit schemas/generated/")


def test_check_mode_reports_a_stale_copy(tmp_path: Path) -> None:
    specgen.write(tmp_path)
    assert schemas_cli.main(["generate", "--out", str(tmp_path), "--check"]) == 0
    (tmp_path / "geopoint.json").write_text("{}\n")
    (tmp_path / "extra.json").write_text("{}\n")
    assert specgen.stale_files(tmp_path) == ["extra.json", "geopoint.json"]
    assert schemas_cli.main(["generate", "--out", str(tmp_path), "--check"]) == 1


def test_module_entry_point_generates(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "conformance.cli", "schemas", "--out",
                          str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "start-tst.json").is_file() and (tmp_path / "TASKS.md").is_file()


def test_task_file_typo_is_an_error_naming_file_and_key() -> None:
    data = dict(taskspec.task_spec("move-to").raw)
    data["paramters"] = {}
    with pytest.raises(schema.SchemaError, match=r"x\.yaml.*paramters"):
        taskspec.parse_task(data, "x.yaml")
    bad_type = dict(taskspec.task_spec("move-to").raw)
    bad_type["parameters"] = {"speed": {"type": "float32", "description": "d"}}
    bad_type["required"] = []
    with pytest.raises(schema.SchemaError, match="'float32' is not one of .*geopointarrays"):
        taskspec.parse_task(bad_type, "x.yaml")


def test_schemas_hash_is_stable_and_hex() -> None:
    h = schema.schemas_hash()
    assert h == schema.schemas_hash() and len(h) == 64 and int(h, 16) >= 0

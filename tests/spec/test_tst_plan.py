"""TST trees (conformance.tst) and `waraps-conformance validate --tst`: a mission planner checks
a plan before sending it, and sees every problem of the tree with its JSON path."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from conformance.tst import read_tree, unit_name

CORPUS = Path(__file__).parent / "corpus"
U1, U2 = "5184d315-15c4-42d4-a647-fa74f794c03b", "e912ac32-d1a9-4e58-946a-a9a67989e849"
GEO = {"altitude": 40.0, "latitude": 57.7611363, "longitude": 16.6805011, "rostype": "GeoPoint"}

# A plan with one problem of each kind, and where each one is.
BROKEN_PLAN = {
    "name": "seq", "common_params": {"execunit": "dji0", "node-uuid": U1}, "params": {},
    "children": [
        {"name": "move-to", "params": {"waypoint": dict(GEO, latitude=100), "speed": "quick"},
         "children": []},
        {"name": "look-at-angle", "params": {"pan": 45}, "children": [],
         "common-params": {"node-uuid": U1}},
        {"name": "conc", "params": {}, "children": []},
        {"name": "take-off", "params": {}, "children": [
            {"name": "land", "params": {"land-at-current-position-flag": True}}]},
    ]}
EXPECTED = {
    ("ERR-017", "$.common_params.execunit"),
    ("TASK-001", "$.children[0].params.waypoint.latitude"),
    ("TASK-001", "$.children[0].params.speed"),
    ("ERR-005", "$.children[1].name"),
    ("ERR-009", "$.children[1].common-params"),
    ("TST-014", "$.children[1].common-params.node-uuid"),
    ("TST-014", "$.children[2].children"),
    ("TST-014", "$.children[3].children"),
}


def validate_cli(*args: str, stdin: bytes | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "conformance.cli", "validate", *args],
                          input=None if stdin is None else stdin.decode(), capture_output=True,
                          text=True)


def test_every_problem_of_a_plan_is_listed_with_its_path(tmp_path: Path) -> None:
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(BROKEN_PLAN))
    run = validate_cli("--tst", str(plan), "--json")
    assert run.returncode == 1, run.stderr
    found = {(v["rule"], v["path"]) for v in json.loads(run.stdout)["violations"]}
    assert found == EXPECTED
    text = validate_cli("--tst", str(plan))
    assert text.returncode == 1
    assert "path      $.children[3].children" in text.stdout
    assert "none: take-off is a task, only seq and conc have children" in text.stdout


def test_a_plan_as_a_whole_start_tst_command_keeps_its_paths() -> None:
    command = {"com-uuid": U2, "command": "start-tst", "tst": BROKEN_PLAN}
    run = validate_cli("--tst", "-", "--json", stdin=json.dumps(command).encode())
    found = {(v["rule"], v["path"]) for v in json.loads(run.stdout)["violations"]}
    assert found == {(rule, "$.tst" + path[1:]) for rule, path in EXPECTED}


def test_a_good_plan_passes_and_the_spec_examples_warn_only_on_errata() -> None:
    good = {"name": "conc", "params": {}, "common_params": {"execunit": "/dji0", "node-uuid": U1},
            "children": [{"name": "move-to", "params": {"waypoint": GEO}, "children": []},
                         {"name": "look-at-position", "params": {"geopoint": GEO}}]}
    run = validate_cli("--tst", "-", stdin=json.dumps(good).encode())
    assert run.returncode == 0 and "verdict   pass" in run.stdout, run.stdout
    index = json.loads((CORPUS / "index.json").read_text())["examples"]
    for example in (e for e in index if e["section"].startswith("11.")):
        file, expected = ((example["raw"], example["expected"]) if example["valid-json"] else
                          (example["repaired"]["file"], example["repaired"]["expected"]))
        run = validate_cli("--tst", str(CORPUS / file), "--json")
        report = json.loads(run.stdout)
        assert report["verdict"] == expected["verdict"], (example["id"], report)
        assert {v["rule"] for v in report["violations"]} == set(expected["rules"])


def test_tst_takes_one_file_not_a_topic() -> None:
    run = validate_cli("--tst", "waraps/unit/ground/real/op0/tst/command", "plan.json")
    assert run.returncode == 2 and "--tst takes one FILE" in run.stderr
    assert validate_cli().returncode == 2


def test_read_tree_reads_either_spelling_and_inherits_nothing_silently() -> None:
    root, problems = read_tree({"name": "seq", "common-params": {"execunit": "/dji0",
                                                                 "node-uuid": U1},
                                "children": [{"name": "take-off", "params": {}}]})
    assert problems == [] and root is not None
    assert (root.node_uuid, root.execunit, root.composite) == (U1, "/dji0", True)
    child = root.children[0]
    assert (child.path, child.node_uuid, child.execunit) == ("$.tst.children[0]", None, None)
    _, problems = read_tree({"name": "take-off", "common_params": {"node-uuid": U1},
                             "common-params": {"node-uuid": U2}})
    assert [p.path for p in problems] == ["$.tst.common_params"]


@pytest.mark.parametrize("tree", [[], {"children": 3}, "seq"])
def test_read_tree_reports_what_the_schema_reports_too_as_such(tree: object) -> None:
    _, problems = read_tree(tree)
    assert problems and all(p.in_schema for p in problems)


def test_read_tree_refuses_a_tree_too_large_to_read() -> None:
    wide = {"name": "conc", "children": [{"name": "take-off"}] * 2000}
    _, problems = read_tree(wide)
    assert [p.observed for p in problems] == ["more"]


@pytest.mark.parametrize(("text", "name"), [("/dji21", "dji21"), ("dji21", "dji21"),
                                            ("waraps/unit/air/real/dji21", "dji21")])
def test_unit_names_are_read_in_every_form(text: str, name: str) -> None:
    assert unit_name(text) == name

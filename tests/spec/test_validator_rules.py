"""Every stateless rule the validator implements: a passing message and a failing one with the
exact rule id (and JSON path)."""

from __future__ import annotations

import copy
from datetime import UTC, datetime
from typing import Any

import orjson
import pytest

from conformance.profile import Profile
from conformance.schema_errors import json_path
from conformance.validator import Validator, validate

UNIT = "waraps/unit/air/simulation/dji0"
NOW = 1_700_000_000.0
U1 = "b992552b-90b0-4911-8707-d6f808362bd2"
U2 = "1c5284da-b803-49d1-8c39-b96ef00603e7"
U3 = "29c24bbf-88f0-4de2-97e9-4bd0d5f6bf23"
GEO = {"altitude": 40.0, "latitude": 57.7611363, "longitude": 16.6805011, "rostype": "GeoPoint"}

GOOD: dict[str, tuple[str, dict[str, Any] | Any]] = {
    "heartbeat": ("heartbeat", {
        "agent-type": "air", "agent-uuid": U1, "levels": ["sensor", "direct execution"],
        "name": "dji0", "rate": 1.0, "stamp": NOW, "type": "HeartBeat"}),
    "sensor_info": ("sensor_info", {
        "agent-uuid": U1, "name": "dji0", "rate": 1, "stamp": NOW, "type": "SensorInfo",
        "sensor-data-provided": ["position", "heading", "course", "speed"]}),
    "direct_execution_info": ("direct_execution_info", {
        "agent-uuid": U1, "name": "dji0", "rate": 1.0, "stamp": NOW,
        "type": "DirectExecutionInfo",
        "tasks-available": [{"name": "move-to", "signals": ["$abort", "$enough", "land-now"]}],
        "tasks-executing": [{"task-name": "move-to", "task-uuid": U2}]}),
    "tst_execution_info": ("tst_execution_info", {
        "agent-uuid": U1, "name": "dji0", "rate": 1.0, "stamp": NOW, "type": "TstExecutionInfo"}),
    "position": ("sensor/position", dict(GEO)),
    "heading": ("sensor/heading", 359.5),
    "course": ("sensor/course", 0),
    "speed": ("sensor/speed", 3.2),
    "camera_url": ("sensor/camera_url", "rtsp://127.0.0.1/cam"),
    "ping": ("exec/command", {"com-uuid": U1, "command": "ping", "sender": "commander"}),
    "start-task": ("exec/command", {
        "com-uuid": U1, "command": "start-task", "sender": "commander", "execution-unit": "dji0",
        "task-uuid": U2, "task": {"name": "move-to", "params": {"speed": "slow",
                                                                "waypoint": dict(GEO)}}}),
    "signal-task": ("exec/command", {"com-uuid": U1, "command": "signal-task",
                                     "signal": "$abort", "task-uuid": U2}),
    "query-status": ("exec/command", {"com-uuid": U1, "command": "query-status",
                                      "task-uuid": U2}),
    "response": ("exec/response", {"agent-uuid": U1, "com-uuid": U2, "fail-reason": "",
                                   "response": "running", "response-to": U3, "task-uuid": U1}),
    "feedback": ("exec/feedback", {"agent-uuid": U1, "com-uuid": U2, "status": "running",
                                   "task-uuid": U3}),
    "start-tst": ("tst/command", {
        "com-uuid": U1, "command": "start-tst", "receiver": "op0", "sender": "commander",
        "tst": {"name": "seq", "params": {}, "children": [
            {"name": "look-at-position", "params": {"geopoint": dict(GEO)}, "children": []},
            {"name": "move-to", "params": {"waypoint": dict(GEO)}, "children": [],
             "common_params": {"node-uuid": U3}}],
            "common_params": {"execunit": "/op0", "node-uuid": U2}}}),
    "signal-tst-node": ("tst/command", {"com-uuid": U1, "command": "signal-tst-node",
                                        "node-uuid": U2, "sender": "commander",
                                        "signal": "$abort"}),
    "signal-tst-tree": ("tst/command", {"com-uuid": U1, "command": "signal-tst-tree",
                                        "node-uuid": U2, "signal": "$pause"}),
    "signal-unit": ("tst/command", {"com-uuid": U1, "command": "signal-unit", "unit": "/dji21",
                                    "signal": "$abort"}),
    "tst-response": ("tst/response", {"com-uuid": U1, "fail-reason": "", "response": "started",
                                      "response-to": U2, "root-uuid": U3}),
    "tst-feedback": ("tst/feedback", {"com-uuid": U1, "fail-reason": "", "node-uuid": U2,
                                      "root-flag": True, "status": "succeeded"}),
}


def run(sub: str, message: Any, *, time: float | None = NOW, profile: Profile | None = None,
        unit: str = UNIT) -> list[tuple[str, str]]:
    payload = message if isinstance(message, bytes) else orjson.dumps(message)
    v = Validator(profile).validate(f"{unit}/{sub}", payload, time)
    return [(x.rule, x.path) for x in v.violations]


def mutated(name: str, change: Any) -> tuple[str, Any]:
    sub, message = GOOD[name]
    message = copy.deepcopy(message)
    change(message)
    return sub, message


@pytest.mark.parametrize("name", sorted(GOOD))
def test_conformant_message_has_no_violation(name: str) -> None:
    sub, message = GOOD[name]
    assert run(sub, message) == []


def test_kinds() -> None:
    kinds = {name: validate(f"{UNIT}/{sub}", orjson.dumps(m)).kind
             for name, (sub, m) in GOOD.items()}
    assert kinds["start-task"] == "exec/command/start-task"
    assert kinds["signal-unit"] == "tst/command/signal-unit"
    assert kinds["position"] == "sensor/position"
    assert kinds["feedback"] == "exec/feedback"


def _set(path: str, value: Any) -> Any:
    def change(m: Any) -> None:
        *head, last = path.split("/")
        for key in head:
            m = m[int(key)] if isinstance(m, list) else m[key]
        if value is _DROP:
            del m[last]
        elif isinstance(m, list):
            m[int(last)] = value
        else:
            m[last] = value
    return change


_DROP = object()

# (good message, change, expected rule, expected JSON path)
FAULTS = [
    ("heartbeat", _set("agent-uuid", _DROP), "HB-001", "$.agent-uuid"),
    ("heartbeat", _set("rate", "1"), "HB-009", "$.rate"),
    ("heartbeat", _set("rate", 0), "HB-009", "$.rate"),
    ("heartbeat", _set("type", "Heartbeat"), "HB-002", "$.type"),
    ("heartbeat", _set("agent-type", "drone"), "HB-004", "$.agent-type"),
    ("heartbeat", _set("agent-type", "surface"), "HB-004", "$.agent-type"),  # topic says air
    ("heartbeat", _set("agent-uuid", "b992552b90b04911"), "HB-005", "$.agent-uuid"),
    ("heartbeat", _set("levels/1", "flying"), "HB-007", "$.levels[1]"),
    ("heartbeat", _set("levels/1", "direct_execution"), "ERR-008", "$.levels[1]"),
    ("heartbeat", _set("name", "dji1"), "MSG-006", "$.name"),
    ("heartbeat", _set("stamp", NOW * 1000), "MSG-008", "$.stamp"),
    ("heartbeat", _set("stamp", NOW - 3600), "MSG-005", "$.stamp"),
    ("sensor_info", _set("type", "SensorInformation"), "SI-001", "$.type"),
    ("sensor_info", _set("sensor-data-provided/0", "Position"), "SI-001",
     "$.sensor-data-provided[0]"),
    ("sensor_info", _set("agent-uuid", _DROP), "ERR-012", "$.agent-uuid"),
    ("sensor_info", _set("name", "piraya0"), "MSG-006", "$.name"),
    ("direct_execution_info", _set("tasks-executing", _DROP), "DEI-001", "$.tasks-executing"),
    ("direct_execution_info", _set("tasks-available/0/signals/0", "$stop"), "DEI-003",
     "$.tasks-available[0].signals[0]"),
    ("direct_execution_info", _set("agent-uuid", _DROP), "ERR-012", "$.agent-uuid"),
    ("direct_execution_info", _set("tasks-executing/0/task-uuid", "t1"), "ERR-014",
     "$.tasks-executing[0].task-uuid"),
    ("tst_execution_info", _set("rate", _DROP), "TEI-001", "$.rate"),
    ("tst_execution_info", _set("agent-uuid", _DROP), "ERR-012", "$.agent-uuid"),
    ("tst_execution_info", _set("stamp", NOW / 1e9 * 1e18), "MSG-008", "$.stamp"),
    ("position", _set("latitude", 91.0), "SENS-001", "$.latitude"),
    ("position", _set("longitude", "16.68"), "SENS-001", "$.longitude"),
    ("position", _set("altitude", _DROP), "SENS-001", "$.altitude"),
    ("position", _set("rostype", "Point"), "SENS-001", "$.rostype"),
    ("ping", _set("com-uuid", _DROP), "EXEC-001", "$.com-uuid"),
    ("ping", _set("command", "pong"), "EXEC-001", "$.command"),
    ("ping", _set("command", "signal-executor"), "ERR-007", "$.command"),
    ("ping", _set("com-uuid", "79d118b0-501a-4156-83c2-95fd9aaafb2"), "ERR-014", "$.com-uuid"),
    ("signal-task", _set("signal", "$stop"), "EXEC-001", "$.signal"),
    ("signal-task", _set("task-uuid", _DROP), "EXEC-001", "$.task-uuid"),
    ("query-status", _set("task-uuid", 7), "EXEC-001", "$.task-uuid"),
    ("start-task", _set("task/params/speed", "quick"), "TASK-001", "$.task.params.speed"),
    ("start-task", _set("task/params/waypoint", _DROP), "TASK-001", "$.task.params.waypoint"),
    ("start-task", _set("task/params/waypoint/latitude", -91), "TASK-001",
     "$.task.params.waypoint.latitude"),
    ("start-task", _set("task/params/waypoint/rostype", _DROP), "ERR-010",
     "$.task.params.waypoint.rostype"),
    ("start-task", _set("task/params/altitude", 40.0), "TASK-003", "$.task.params.altitude"),
    ("start-task", _set("task/name", "fly-to"), "TASK-002", "$.task.name"),
    ("start-task", _set("task", _DROP), "EXEC-001", "$.task"),
    ("start-task", _set("task/params", []), "TASK-001", "$.task.params"),
    ("response", _set("response", "done"), "EXEC-003", "$.response"),
    ("response", _set("response", "success"), "ERR-006", "$.response"),
    ("response", _set("response-to", _DROP), "EXEC-002", "$.response-to"),
    ("response", _set("com-uuid", U3), "EXEC-005", "$.com-uuid"),
    ("response", _set("response", "failed"), "EXEC-007", "$.fail-reason"),
    ("response", _set("agent-uuid", "agent-1"), "HB-005", "$.agent-uuid"),
    ("feedback", _set("task-uuid", _DROP), "EXEC-FB-001", "$.task-uuid"),
    ("feedback", _set("status", "Finished"), "EXEC-FB-002", "$.status"),
    ("feedback", _set("status", "runing"), "EXEC-FB-002", "$.status"),
    ("feedback", _set("status", "docking"), "EXEC-FB-002", "$.status"),
    ("start-tst", _set("tst/common_params/node-uuid", 5), "TST-001",
     "$.tst.common_params.node-uuid"),
    ("start-tst", _set("tst/children/0/params/geopoint/latitude", 100), "TASK-001",
     "$.tst.children[0].params.geopoint.latitude"),
    ("start-tst", _set("tst/name", "look-at-angle"), "ERR-005", "$.tst.name"),
    ("start-tst", _set("tst/children/0/name", "seq-x"), "TASK-002", "$.tst.children[0].name"),
    ("start-tst", _set("tst", _DROP), "TST-001", "$.tst"),
    ("signal-tst-node", _set("signal", 3), "TST-001", "$.signal"),
    ("signal-unit", _set("unit", _DROP), "TST-001", "$.unit"),
    ("signal-tst-tree", _set("command", "signal-tree"), "TST-001", "$.command"),
    ("tst-response", _set("response", "accepted"), "TST-002", "$.response"),
    ("tst-response", _set("response-to", U1), "TST-002", "$.com-uuid"),
    ("tst-feedback", _set("status", "finished"), "TST-003", "$.status"),
    ("tst-feedback", _set("root-flag", "true"), "TST-003", "$.root-flag"),
    # section 14's errata and tree structure
    ("tst-response", _set("response", "running"), "ERR-015", "$.response"),
    ("ping", _set("command", "start-tst"), "ERR-016", "$.command"),
    ("ping", _set("command", "signal-unit"), "ERR-016", "$.command"),
    ("signal-unit", _set("unit", "dji21"), "ERR-017", "$.unit"),
    ("start-tst", _set("tst/common_params/execunit", "op0"), "ERR-017",
     "$.tst.common_params.execunit"),
    ("tst_execution_info", _set("type", "TSTExecutionInfo"), "ERR-018", "$.type"),
    ("tst_execution_info", _set("type", "TstExecInfo"), "TEI-001", "$.type"),
    ("start-tst", _set("tst/children/1/common_params/node-uuid", U2), "TST-014",
     "$.tst.children[1].common_params.node-uuid"),
    ("start-tst", _set("tst/children/0/children", [{"name": "seq", "children": []}]), "TST-014",
     "$.tst.children[0].children"),
    ("start-tst", _set("tst/children", []), "TST-014", "$.tst.children"),
    ("start-tst", _set("tst/common-params", {"execunit": "/dji0"}), "TST-014",
     "$.tst.common_params"),
    ("start-tst", _set("tst/children/0/common-params", {"node-uuid": U2}), "TST-014",
     "$.tst.children[0].common-params.node-uuid"),
    ("start-tst", _set("tst/children/1/common-params", {"node-uuid": U2}), "TST-014",
     "$.tst.children[1].common_params"),
]


@pytest.mark.parametrize(("name", "change", "rule", "path"), FAULTS,
                         ids=[f"{f[2]}-{f[0]}-{i}" for i, f in enumerate(FAULTS)])
def test_fault_is_reported_with_its_rule_and_path(name: str, change: Any, rule: str,
                                                  path: str) -> None:
    sub, message = mutated(name, change)
    found = run(sub, message)
    assert (rule, path) in found, found


def test_err_009_common_params_spelled_with_hyphen_is_only_err_009() -> None:
    sub, message = GOOD["start-tst"]
    message = copy.deepcopy(message)
    message["tst"]["common-params"] = message["tst"].pop("common_params")
    assert run(sub, message) == [("ERR-009", "$.tst.common-params")]


def test_err_010_a_tasks_geopoint_tagged_type_or_untagged_is_only_err_010() -> None:
    """ERR-010 rests on the examples, and every example of a GeoPoint is a task's (10, 11):
    there 'type' or no tag warns. 6.1 has no example of sensor/position: no tag is asked of
    it (it warned on every agent); a tag with another value is still SENS-001."""
    tagged_type = {k: v for k, v in GEO.items() if k != "rostype"} | {"type": "GeoPoint"}
    untagged = {k: v for k, v in GEO.items() if k != "rostype"}
    assert run("sensor/position", tagged_type) == []
    assert run("sensor/position", untagged) == []
    assert run("sensor/position", {**untagged, "type": "Point"}) == [("SENS-001", "$.type")]
    sub, message = GOOD["start-task"]
    for waypoint in (tagged_type, untagged):
        message = copy.deepcopy(message)
        message["task"]["params"]["waypoint"] = waypoint
        assert run(sub, message) == [("ERR-010", "$.task.params.waypoint.rostype")]


def test_err_003_misspelled_look_at_bearing_flag_is_only_err_003() -> None:
    message = {"com-uuid": U1, "command": "start-task", "task": {
        "name": "look-at-bearing",
        "params": {"bearing": 45, "tilt": -45, "use_absoiute_bearing": False}}}
    assert run("exec/command", message) == [
        ("ERR-003", "$.task.params.use_absoiute_bearing")]


def test_err_004_observe_position_example_forms_are_only_err_004() -> None:
    message = {"com-uuid": U1, "command": "start-task", "task": {
        "name": "observe-position",
        "params": {"geopoint": [dict(GEO)], "speed": [7.0], "duration": 20}}}
    assert run("exec/command", message) == [("ERR-004", "$.task.params.geopoint"),
                                            ("ERR-004", "$.task.params.speed")]
    # A list that is not the erratum form is still checked inside.
    message["task"]["params"]["geopoint"] = [{"latitude": 1}]
    found = run("exec/command", message)
    assert ("TASK-001", "$.task.params.geopoint[0].longitude") in found


def test_task_conditional_requirements() -> None:
    land = {"com-uuid": U1, "command": "start-task", "task": {"name": "land", "params": {}}}
    assert run("exec/command", land) == [("TASK-001", "$.task.params.p")]
    land["task"]["params"] = {"land-at-current-position-flag": True}
    assert run("exec/command", land) == []
    look = {"com-uuid": U1, "command": "start-task",
            "task": {"name": "look-at-position", "params": {}}}
    assert run("exec/command", look) == [("TASK-001", "$.task.params")]
    look["task"]["params"] = {"named-position": "/dji1"}
    assert run("exec/command", look) == []


def test_area_needs_three_points() -> None:
    message = {"com-uuid": U1, "command": "start-task", "task": {
        "name": "search-area", "params": {"area": [dict(GEO), dict(GEO)]}}}
    assert run("exec/command", message) == [("TASK-001", "$.task.params.area")]


def test_unknown_task_params_are_not_checked() -> None:
    message = {"com-uuid": U1, "command": "start-task",
               "task": {"name": "dance", "params": {"style": 1}}}
    assert run("exec/command", message) == [("TASK-002", "$.task.name")]


def test_feedback_status_near_miss_and_task_specific() -> None:
    def detail(status: str, profile: Profile | None = None) -> list[str]:
        sub, message = GOOD["feedback"]
        v = Validator(profile).validate(f"{UNIT}/{sub}",
                                        orjson.dumps({**message, "status": status}), NOW)
        return [x.detail for x in v.violations]

    assert detail("RUNNING")[0].startswith("a near miss of the standard status 'running'")
    assert detail("finnished")[0].startswith("a near miss of the standard status 'finished'")
    assert "task-specific?" in detail("docking")[0]
    assert detail("in-view") == []  # look-at-position's statuses (9.4)
    assert detail("docking", Profile(task_specific_statuses=("docking",))) == []


def test_stamp_without_arrival_time_is_not_judged() -> None:
    sub, message = mutated("heartbeat", _set("stamp", NOW * 1000))
    assert run(sub, message, time=None) == []


def test_stamp_details_say_milliseconds() -> None:
    sub, message = mutated("heartbeat", _set("stamp", NOW * 1000))
    v = validate(f"{UNIT}/{sub}", orjson.dumps(message), NOW)
    assert "looks like milliseconds" in v.violations[0].detail
    # the arrival time as a person reads it (and the number, to compare with the stamp)
    clock = datetime.fromtimestamp(NOW, UTC).strftime("%H:%M:%S")
    assert f"of its arrival at {clock}." in v.violations[0].expected
    sub, message = mutated("heartbeat", _set("stamp", NOW + 5))
    assert run(sub, message, profile=Profile(clock_tolerance=10)) == []
    assert run(sub, message, profile=Profile(clock_tolerance=1)) == [("MSG-005", "$.stamp")]


@pytest.mark.parametrize("name", ["heartbeat", "ping", "response", "position"])
@pytest.mark.parametrize("payload", [b"[]", b"42", b'"text"', b"null", b"[{}]"])
def test_non_object_where_an_object_is_expected_is_msg_003(name: str, payload: bytes) -> None:
    sub, _ = GOOD[name]
    assert run(sub, payload) == [("MSG-003", "$")]


def test_scalar_sensors_are_not_objects() -> None:
    assert run("sensor/heading", {"data": 12.0}) == [("SENS-002", "$")]
    assert run("sensor/heading", 360) == [("SENS-002", "$")]
    assert run("sensor/heading", -1) == [("SENS-002", "$")]
    assert run("sensor/speed", -0.5) == [("SENS-003", "$")]
    assert run("sensor/camera_url", 5) == [("SENS-004", "$")]
    assert run("sensor/videoserver_url", "http://x") == []
    assert run("sensor/battery_state", {"anything": [1, 2]}) == []  # optional: not defined


def test_every_violation_carries_evidence() -> None:
    sub, message = mutated("start-task", _set("task/params/speed", "quick"))
    v = validate(f"{UNIT}/{sub}", orjson.dumps(message), NOW)
    (x,) = v.violations
    assert x.expected == "one of fast | standard | slow" and x.observed == '"quick"'
    assert x.topic == f"{UNIT}/exec/command" and x.unit == UNIT and x.time == NOW
    assert x.excerpt.startswith("{")


def test_one_violation_per_rule_and_spot() -> None:
    sub, message = mutated("heartbeat", _set("levels/0", 7))  # type and enum both fail
    assert run(sub, message) == [("HB-007", "$.levels[0]")]


def test_json_path_quotes_keys_that_are_not_names() -> None:
    assert json_path(["task", "params", "waypoints", 2, "latitude"]) == \
        "$.task.params.waypoints[2].latitude"
    assert json_path(["a b", "x.y"]) == '$["a b"]["x.y"]'


def test_tst_node_of_a_known_task_needs_params() -> None:
    sub, message = mutated("start-tst", _set("tst/children/0/params", _DROP))
    assert run(sub, message) == [("TST-001", "$.tst.children[0].params")]

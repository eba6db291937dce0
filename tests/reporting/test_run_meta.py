"""The run's metadata and a unit's facts, typed (``RunMeta``, ``UnitFacts`` in results.py): the
JSON report keeps the keys it always had, and a report read back is parsed into the typed
form or refused with an error that names what is wrong."""

from __future__ import annotations

import dataclasses

import orjson
import pytest

from conformance.report_meta import MalformedReport, RunMeta, UnitFacts
from conformance.reporting import read_json, write_all
from conformance.reporting.htmlreport import META_SHOWN_ELSEWHERE, META_WORDS
from conformance.results import RunReport, UnitReport

CERTIFICATION_KEYS = [
    "agent_uuid", "allow_hostile", "allow_motion", "commands_sent", "dry_run", "exit_status",
    "explore", "explore_story", "profile_source", "reboot", "rerun", "safety", "seed",
    "timing_scale", "tst_command_topic", "unit"]
"""The keys of a certification's JSON ``meta`` (and ``rerun <RULE>`` for each failed or
warned rule), as the reports have carried them: the golden list."""
LINT_KEYS = [
    "bag_messages_read", "duration_s", "not_judged", "provisional", "recording_formats",
    "recording_lines", "recording_problem_lines", "recording_problems", "source", "tls_options",
    "unexamined_reason", "units"]
"""The keys of a lint's JSON ``meta``: the golden list."""
ANY_RUN_KEYS = ["report_truncated"]

FACTS_KEYS = ["conversations_dropped", "declared_rates", "message_counts", "position",
              "sensors_listed", "sensors_seen", "tasks_available", "tasks_executing"]
"""The keys of a unit's JSON ``facts``: the golden list."""


def every_field() -> RunMeta:
    """A RunMeta with every field said (each its own name), and one rule's rerun line."""
    said = {f.name: f.name for f in dataclasses.fields(RunMeta) if f.name != "rerun_of"}
    return RunMeta(**said, rerun_of={"HB-003": "pytest --unit u -k HB-003"})


def test_the_json_meta_keys_are_the_golden_list():
    """A field renamed or left out of the typed form would change a key of every report (the
    HTML report's head and tests/plugin read them): refused here."""
    keys = every_field().to_dict()
    assert sorted(keys) == sorted(CERTIFICATION_KEYS + LINT_KEYS + ANY_RUN_KEYS + ["rerun HB-003"])
    assert keys["rerun HB-003"] == "pytest --unit u -k HB-003" and keys["seed"] == "seed"
    # a field not said is no key at all (a lint's report has none of the suite's keys)
    assert RunMeta(source="rec.jsonl").to_dict() == {"source": "rec.jsonl"}
    assert RunMeta(agent_uuid="").to_dict() == {"agent_uuid": ""}  # said, if empty


def test_the_json_facts_keys_are_the_golden_list():
    assert sorted(UnitFacts().to_dict()) == FACTS_KEYS


def test_the_html_head_names_meta_by_its_json_keys():
    """The HTML head's words and its left-out keys are keys the typed meta writes (a renamed
    field would silently fall back to its bare name, or show twice)."""
    keys = set(every_field().to_dict())
    assert {k for k, _ in META_WORDS} <= keys and META_SHOWN_ELSEWHERE <= keys


def test_meta_and_facts_read_back_as_written():
    meta = every_field()
    assert RunMeta.from_dict(orjson.loads(orjson.dumps(meta.to_dict()))) == meta
    facts = UnitFacts(declared_rates={"heartbeat": 1.0}, sensors_listed=("position",),
                      sensors_seen={"position": 3}, tasks_available={"move-to": ("$abort",)},
                      tasks_executing={"u-1": "move-to"}, position=(58.4, 15.6, None),
                      message_counts={"exec/command": 2}, conversations_dropped=1)
    assert UnitFacts.from_dict(orjson.loads(orjson.dumps(facts.to_dict()))) == facts
    # a report of an older writer (no facts) and a newer one (a key not known here)
    assert UnitFacts.from_dict({}) == UnitFacts()
    assert RunMeta.from_dict({"source": "x", "a_newer_key": "y"}) == RunMeta(source="x")


@pytest.mark.parametrize(("meta", "said"), [
    ([], "the report's meta is a list, not an object"),
    ({"seed": 7}, "the report's meta 'seed' is a number, not text"),
    ({"rerun HB-003": None}, "the report's meta 'rerun HB-003' is null, not text"),
])
def test_a_malformed_meta_is_refused_saying_what(meta, said):
    with pytest.raises(MalformedReport, match=f"^{said}$"):
        RunMeta.from_dict(meta)


@pytest.mark.parametrize(("facts", "said"), [
    ("none", "a unit's facts are text, not an object"),
    ({"sensors_listed": "position"}, "a unit's facts 'sensors_listed': text, not a list"),
    ({"message_counts": {"heartbeat": 1.5}},
     "a unit's facts 'message_counts': a number, not a whole number"),
    ({"position": [58.4]}, "a unit's facts 'position': "),
    ({"tasks_available": {"move-to": [1]}}, "a unit's facts 'tasks_available': a number, not text"),
])
def test_malformed_facts_are_refused_saying_which(facts, said):
    with pytest.raises(MalformedReport, match=f"^{said}"):
        UnitFacts.from_dict(facts)


def test_reading_a_malformed_report_names_the_fault(run_report: RunReport, tmp_path):
    path = write_all(run_report, tmp_path, "run")["json"]
    data = orjson.loads(path.read_bytes())
    assert isinstance(read_json(path).meta, RunMeta)
    data["meta"]["duration_s"] = 19.03
    path.write_bytes(orjson.dumps(data))
    with pytest.raises(MalformedReport, match="'duration_s' is a number"):
        read_json(path)
    data["meta"] = {}
    next(iter(data["units"].values()))["facts"]["sensors_seen"] = ["position"]
    path.write_bytes(orjson.dumps(data))
    with pytest.raises(MalformedReport, match="'sensors_seen': a list, not an object"):
        read_json(path)


def test_a_report_made_in_code_has_empty_meta_and_facts():
    report = RunReport(kind="lint", started=0.0, finished=1.0,
                       units={"u": UnitReport("u", "air", "simulation", "u")})
    data = report.to_dict()
    assert data["meta"] == {}
    assert data["units"]["u"]["facts"] == UnitFacts().to_dict()

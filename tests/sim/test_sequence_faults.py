"""Each sequence fault changes exactly what it names, and only in the order of commands that
shows it (a pause before an abort, a second task while one is paused, a resend after the end):
the same hand-written sequence against the conformant reference unit and the faulty one, on
Mosquitto, compared; then both recordings linted (``lint --from``): the faulty one fails
exactly the fault's rules, the conformant one nothing. That no scripted scenario reaches them
is what ``Fault.sequence`` says (the fault matrices leave them out)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import orjson
import pytest
from sim_sequences import SEQUENCES, Driver, drive

from conformance.cli.lint import main as lint_main
from conformance.recording import Event, RecordingWriter
from conformance.sim import FAULTS
from conformance.sim.faults import SEQUENCE_FAULTS

pytestmark = pytest.mark.mosquitto


def _answers(d: Driver, command: str) -> list[str]:
    coms = {c["com-uuid"] for c in d.on("exec/command") if c.get("command") == command}
    return [r["response"] for r in d.on("exec/response") if r.get("response-to") in coms]


def _tasks(d: Driver) -> list[str]:
    out: list[str] = []
    for c in d.on("exec/command"):
        if c.get("command") == "start-task" and c["task-uuid"] not in out:
            out.append(c["task-uuid"])
    return out


def _listed(d: Driver, task: str) -> bool:
    return any(task in {e.get("task-uuid") for e in i["tasks-executing"]}
               for i in d.on("direct_execution_info")[-2:])


def _paused_listings(d: Driver, task: str) -> list[bool]:
    """Whether each direct_execution_info while ``task`` was paused listed it."""
    paused = [m.time for m in d.messages if m.topic.endswith("exec/feedback")
              and orjson.loads(m.payload).get("task-uuid") == task]
    began, ended = paused[1], (paused[2:] or [float("inf")])[0]  # 'paused', then the next
    return [task in {e.get("task-uuid") for e in orjson.loads(m.payload)["tasks-executing"]}
            for m in d.messages if m.topic.endswith("direct_execution_info")
            and began < m.time < ended]


def _lint(d: Driver, tmp_path: Path, name: str) -> set[str]:
    """The rules ``lint --from`` of ``d``'s recording fails for the unit."""
    recording = tmp_path / f"{name}.jsonl"
    with recording.open("wb") as f:
        writer = RecordingWriter(f)
        # A time the host held the unit (it shares this process) is recorded as the
        # observer's gap, as a capture records a lost connection: a loaded machine's silence.
        held = [e for s, t in d.holds for e in (Event(s, "disconnected", "host held the unit"),
                                                  Event(t, "connected", "host held the unit"))]
        for item in sorted([*d.messages, *held], key=lambda m: m.time):
            writer.write(item)
    profile = tmp_path / "sequence.yaml"  # the answers came within ms: short deadlines
    # strict: as the fault matrix, the decided rules (EXEC-FB-004: nothing after a final
    # status) fail when a fault breaks them; by default they would only warn.
    profile.write_text("extends: default\nname: sequence\nresponse_timeout: 1.0\n"
                       "feedback_timeout: 3.0\nstrict: true\n")
    out = io.StringIO()
    reports = tmp_path / f"reports-{name}"
    lint_main(["--from", str(recording), "--profile", str(profile), "--plain", "--format",
               "json", "--reports-dir", str(reports)], stdout=out)
    report = json.loads(next(reports.glob("*.json")).read_text())
    rules = report["units"][d.unit]["rules"]
    return {r for r, res in rules.items() if res["verdict"] == "fail"}


def test_the_sequence_faults_are_registered_as_such() -> None:
    assert SEQUENCE_FAULTS == set(SEQUENCES)
    assert all(FAULTS[f].sequence and FAULTS[f].active for f in SEQUENCE_FAULTS)
    assert not any(f.sequence for n, f in FAULTS.items() if n not in SEQUENCE_FAULTS)


@pytest.mark.slow
@pytest.mark.parametrize("fault", sorted(SEQUENCES))
def test_a_sequence_fault_changes_exactly_what_it_names_and_lint_fails_its_rule(
        fault: str, mosquitto: str, prefix: str, tmp_path: Path) -> None:
    sequence = SEQUENCES[fault]
    good = drive(mosquitto, f"{prefix}/unit/air/simulation/good0", (), sequence)
    bad = drive(mosquitto, f"{prefix}/unit/air/simulation/bad0", (fault,), sequence)
    a, *others = _tasks(good)
    fa, *fothers = _tasks(bad)
    if fault in ("abort-paused-resumes", "feedback-after-abort-paused"):
        assert good.statuses(a) == ["running", "paused", "aborted"]
        assert bad.statuses(fa) == {
            "abort-paused-resumes": ["running", "paused", "running", "aborted"],
            "feedback-after-abort-paused": ["running", "paused", "aborted", "paused"]}[fault]
    elif fault == "pause-pauses-all":
        assert good.statuses(a) == ["running", "aborted"]
        assert bad.statuses(fa) == ["running", "paused", "aborted"]  # paused by the other's
        assert good.statuses(others[0]) == bad.statuses(fothers[0]) == [
            "running", "paused", "aborted"]
    elif fault == "resend-after-end-runs-again":
        assert good.statuses(a) == ["running", "finished"]
        assert bad.statuses(fa) == ["running", "finished", "running", "aborted"]  # ran again
        assert _answers(good, "signal-task") == ["ok", "failed"]  # nothing left to abort
        assert _answers(bad, "signal-task") == ["ok", "ok"]
    elif fault == "preempt-paused-silently":
        assert good.statuses(a) == ["running", "paused", "aborted"]  # pre-empted
        assert bad.statuses(fa) == ["running", "paused"]  # gone without a word
        assert not _listed(bad, fa) and not _listed(good, a)
        assert good.statuses(others[0]) == bad.statuses(fothers[0])
    elif fault in ("query-paused-unknown", "query-paused-finished"):
        assert _answers(good, "query-status") == ["paused"]
        assert _answers(bad, "query-status") == [fault.rsplit("-", 1)[1]]
        assert good.statuses(a) == bad.statuses(fa) == ["running", "paused", "aborted"]
    elif fault == "paused-dropped-from-list":
        assert good.statuses(a) == bad.statuses(fa) == ["running", "paused"]
        assert _paused_listings(good, a) == [True] * len(_paused_listings(good, a))
        listings = _paused_listings(bad, fa)
        assert listings[0] and not any(listings[1:]) and len(listings) > 2, listings
    elif fault == "resend-signal-reapplied":
        assert good.statuses(a) == ["running", "paused", "running", "aborted"]
        assert bad.statuses(fa) == ["running", "paused", "running", "paused", "aborted"]
    elif fault == "abort-aborts-all":
        assert good.statuses(a) == ["running", "aborted"]
        assert bad.statuses(fa) == ["running", "aborted"]  # aborted with the other
        assert _answers(good, "signal-task") == ["ok", "ok"]
        assert _answers(bad, "signal-task") == ["ok", "failed"]  # nothing left to abort
    else:
        pytest.fail(f"no expectation for {fault}")
    # Everything else the unit answered is the same.
    for command in ("start-task", "ping"):
        assert _answers(good, command) == _answers(bad, command), command
    if fault not in ("resend-after-end-runs-again", "abort-aborts-all"):
        assert _answers(good, "signal-task") == _answers(bad, "signal-task")
    # lint of the recordings: exactly the fault's rules, and nothing on the conformant unit.
    assert _lint(bad, tmp_path, "bad") == set(FAULTS[fault].rules)
    assert _lint(good, tmp_path, "good") == set()

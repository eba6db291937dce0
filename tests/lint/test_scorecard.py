"""The live scorecard: redrawn in place on a terminal, plain lines in a pipe; findings
in the final view. Fed through the real Monitor with synthetic traffic (no broker needed)."""

from __future__ import annotations

import io
import re
from pathlib import Path

import orjson
import pytest
from lint_helpers import T0, run_lint, unit_traffic, write_recording

from conformance.checks import Monitor
from conformance.client import Message
from conformance.lint.linter import Linter
from conformance.lint.scorecard import Scorecard
from conformance.profile import Profile


def heartbeat_type_fault(msgs: list[Message]) -> list[Message]:
    """Every heartbeat says type 'Heartbeat' (HB-002)."""
    out = []
    for m in msgs:
        if m.topic.endswith("/heartbeat"):
            hb = orjson.loads(m.payload)
            hb["type"] = "Heartbeat"
            m = Message(m.time, m.topic, orjson.dumps(hb))
        out.append(m)
    return out


ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
DJI0 = "4774daa2-246c-4124-8d92-5e7806c5b385"


def linter_with(prefix: str) -> Linter:
    linter = Linter(Monitor(Profile(), kind="lint"), Profile())
    msgs = unit_traffic(prefix, "dji0", seconds=12, agent_uuid=DJI0) + heartbeat_type_fault(
        unit_traffic(prefix, "bad0", seconds=12))
    linter.feed(sorted(msgs, key=lambda m: m.time))
    return linter


def test_terminal_view_is_redrawn_in_place(prefix: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "160")  # the drawing fits the terminal: make it a known one
    monkeypatch.setenv("LINES", "40")
    out = io.StringIO()
    card = Scorecard(out, tty=True, title="test")  # drawn by rich as on a terminal
    linter = linter_with(prefix)
    card.update(linter, elapsed=12.0, connected=True, force=True)
    first = out.getvalue()
    lines = ANSI.sub("", first).splitlines()
    assert lines[0].startswith("waraps-conformance lint test | 00:00:12 |") and "connected" in lines[0]
    assert lines[1].split() == ["UNIT", "TYPE", "ROLE", "LEVELS", "MSG/S", "LAST", "SEEN",
                                "STATUS", "VIOLATIONS", "BY", "RULE"]
    bad = next(ln for ln in lines if f"{prefix}/unit/air/simulation/bad0" in ln)
    good = next(ln for ln in lines if f"{prefix}/unit/air/simulation/dji0" in ln)
    assert "FAIL" in bad and "HB-002x12" in bad and "sensor,exec" in bad
    assert " ok " in good and "HB-002" not in good
    assert lines.index(bad) < lines.index(good)  # worst first
    assert "\x1b[1;31mFAIL\x1b[0m" in first and "\x1b[32mok\x1b[0m" in first  # in colour
    card.update(linter, elapsed=13.0, connected=False, force=True)
    second = out.getvalue()[len(first):]
    # Back up over the last drawing, erasing each of its lines, and draw again.
    assert second.startswith("\r\x1b[2K" + "\x1b[1A\x1b[2K" * (len(lines) - 1))
    assert "DISCONNECTED, reconnecting" in second
    card.update(linter, elapsed=13.5, connected=False)
    assert out.getvalue() == first + second  # at most one drawing a second
    card.close()
    assert "\x1b[?25h" in out.getvalue()[len(first + second):]  # the cursor is back


def test_terminal_view_draws_control_characters_harmlessly() -> None:
    """A unit name from a topic may hold escape sequences: the terminal is not told to obey
    them, and the columns stay where they are."""
    from rich.console import Console

    from conformance.lint.scorecard import styled

    term = io.StringIO()
    table = ["UNIT        STATUS", "evil\x1b[2J\x07 FAIL"]
    Console(file=term, force_terminal=True, width=80).print(styled("h", table, [(1, 16, "FAIL")], []))
    assert "\x1b[2J" not in term.getvalue() and "\x07" not in term.getvalue()
    assert "evil\\x1b[2J\\x07 \x1b[1;31mFAIL" in term.getvalue()  # escaped


def test_plain_view_prints_each_first_violation_once_and_summaries(prefix: str) -> None:
    out = io.StringIO()
    card = Scorecard(out, tty=False)
    linter = linter_with(prefix)
    card.update(linter, force=True)
    text = out.getvalue()
    hb002 = [ln for ln in text.splitlines() if " HB-002 " in ln]
    assert len(hb002) == 1 and f"FAIL {prefix}/unit/air/simulation/bad0 HB-002" in hb002[0]
    assert "expected" in hb002[0] and "observed" in hb002[0]
    assert "\x1b[" not in text
    assert f"2 units, {linter.messages} messages, failing: {prefix}/unit/air/simulation/bad0" in text
    more = unit_traffic(prefix, "dji0", seconds=2, t0=T0 + 12, agent_uuid=DJI0)
    linter.feed(more)
    card.update(linter)
    assert out.getvalue() == text  # nothing new to say, and no summary before 10 s


def test_findings_are_listed_once_each_with_count_and_times(tmp_path: Path, reports_dir: Path,
                                                             prefix: str) -> None:
    """Two processes under one unit name, alternating agent-uuids (HB-011): one line for the
    rule, however many heartbeats show it."""
    a = unit_traffic(prefix, "dji0", seconds=20, agent_uuid="11111111-1111-4111-8111-111111111111")
    b = unit_traffic(prefix, "dji0", seconds=20, agent_uuid="22222222-2222-4222-8222-222222222222",
                     t0=T0 + 0.5)
    twin = [m for m in b if m.topic.endswith("/heartbeat")]
    run = run_lint(["--from", str(write_recording(tmp_path / "twin.jsonl", a + twin))],
                   reports_dir)
    assert run.code == 1
    final = run.out[run.out.index("findings (each unit or commander and rule once"):]
    final = final[:final.index("\n\n")]
    hb011 = [ln for ln in final.splitlines() if " HB-011 " in ln]
    assert len(hb011) == 1 and f"{prefix}/unit/air/simulation/dji0" in hb011[0]
    count = run.report["units"][f"{prefix}/unit/air/simulation/dji0"]["violation_counts"][
        "HB-011"]
    assert count > 10 and f": {count}x first " in hb011[0] and ", last " in hb011[0]


def test_recorded_duration_limits_what_is_judged(tmp_path: Path, reports_dir: Path,
                                                  prefix: str) -> None:
    rec = write_recording(tmp_path / "r.jsonl", unit_traffic(prefix, "dji0", seconds=30))
    run = run_lint(["--from", str(rec), "--duration", "10s"], reports_dir)
    unit = run.report["units"][f"{prefix}/unit/air/simulation/dji0"]
    assert unit["last_seen"] - unit["first_seen"] <= 10.0
    assert unit["message_count"] < 30 * 7


def test_plain_view_says_when_a_rate_goes_off_and_when_it_is_back(prefix: str) -> None:
    """A unit at 0.45 Hz declaring 1 Hz (off by 2x: the rule's words) is shown failing while
    lint runs (within 10 intervals), not only on the final screen; the row shows it too."""
    out = io.StringIO()
    card = Scorecard(out, tty=False)
    linter = Linter(Monitor(Profile(), kind="lint"), Profile())
    slow = unit_traffic(prefix, "slow0", seconds=30, rate=1 / 2.2, agent_uuid=DJI0)
    for m in slow:  # declares 0.45 Hz: re-declare 1 Hz while sending at 0.45
        if m.topic.endswith("/heartbeat"):
            hb = orjson.loads(m.payload)
            hb["rate"] = 1.0
            m = Message(m.time, m.topic, orjson.dumps(hb))
        linter.feed([m])
        card.update(linter, force=True)
    unit = f"{prefix}/unit/air/simulation/slow0"
    lines = [ln for ln in out.getvalue().splitlines() if ln.endswith("(live)")]
    assert len(lines) == 1 and f"FAIL {unit} HB-003" in lines[0], out.getvalue()
    assert "0.45 Hz over the latest 10 intervals" in lines[0]
    (row,) = [r for r in card.rows(linter) if r.unit == unit]
    assert row.status == "FAIL" and row.live == ("HB-003",)
    assert "HB-003(live)" in card.table([row], None)[1]
# --- the verdict model in lint's outputs (conformance.conclusion) -----------
def html_counts(page: str) -> dict[str, int]:
    """The verdict counts of the HTML report's header ('84 pass' badges, '3 not run')."""
    head = page[page.index('<table class="head">'):]  # the run's facts (each unit has its own)
    row = head[head.index("<th>verdicts</th>"):]
    row = row[:row.index("</tr>")]
    return {v: int(n) for n, v in re.findall(r">(\d+) ([a-z -]+)</span>", row)}


def text_counts(out: str) -> dict[str, int]:
    """The counts on the line lint's text output opens with (``verdict: fail (84 pass, ...)``)."""
    line = next(ln for ln in out.splitlines() if ln.startswith("verdict: "))
    inside = line[line.index("(") + 1:line.index(")")]
    return {v: int(n) for n, v in (part.split(" ", 1) for part in inside.split(", "))}


def test_a_short_passive_lint_certifies_nothing(mosquitto: str, prefix: str,
                                                reports_dir: Path) -> None:
    """Lint of live traffic for a few seconds: each unit as observed ('never commanded'),
    never 'certified' and never 'pass', in the text, the JSON, the HTML and the JUnit file."""
    from conformance.sim import SimUnit

    unit = f"{prefix}/unit/air/simulation/dji0"
    with SimUnit(unit, mosquitto, rate=5.0, seed=1):
        run = run_lint(["--broker", mosquitto, "--topic", f"{prefix}/#", "--duration", "3s"],
                       reports_dir)
    assert run.report is not None and unit in run.report["units"], run.out
    without = run.out.replace("not certified", "").replace("pytest --unit run certifies", "")
    assert "certified" not in without and "PASS" not in run.out, run.out
    assert run.report["verdict"] != "pass" and run.report["verdict"] in ("clean", "warn", "fail")
    status = run.report["conclusion"]["units"][unit]
    assert "never commanded" in status["summary"] and status["summary"] in run.out
    assert status["levels"] and not any(lv["certified"] for lv in status["levels"])
    (html,) = reports_dir.glob("*.html")
    page = html.read_text()
    head = page.split('<details class="fold">')[0]  # what opens the report
    assert "— certified" not in head and ">pass<" not in head and "never commanded" in head
    headings = re.findall(r"<h2 .*</h2>", page)  # each unit's own badge: observed, not passed
    assert headings and not any(">pass<" in h for h in headings), headings
    (xml,) = reports_dir.glob("*.xml")
    junit = xml.read_text()
    assert f'name="verdict" value="{run.report["verdict"]}"' in junit
    assert 'value="pass"' not in junit.split("<testcase")[0]
    assert "— certified" not in junit and "never commanded" in junit


def test_recorded_lint_opens_with_verdicts_most_severe_first_and_counts_agree(
        tmp_path: Path, reports_dir: Path, prefix: str) -> None:
    """A recording: each unit's verdict and its most severe findings come first (a death before
    a rate), not the replayed stream; the counts are the same in the text, JSON and HTML."""
    from conformance.recording import Event

    traffic = (unit_traffic(prefix, "aaa0", seconds=30, heartbeat_every=2)  # HB-003 only
               + unit_traffic(prefix, "zzz0", seconds=12))  # dies at 12 s: HB-012
    rec = write_recording(tmp_path / "r.jsonl", [Event(T0 - 0.5, "start", "subscribed"),
                                                 *traffic, Event(T0 + 30, "end", "stopped")])
    # Strict: a unit that received no command and stops may have been switched off (HB-012's
    # decided 'no-command'); adopted, it is the death this ordering is about.
    run = run_lint(["--from", str(rec), "--strict"], reports_dir)
    assert run.code == 1 and run.report is not None
    lines = run.out.splitlines()
    first_finding = next(i for i, ln in enumerate(lines) if " HB-0" in ln)
    # The verdicts come before the table and the evidence; the dead unit (a later name) first.
    assert lines[first_finding].split()[:2] == ["death", "HB-012"], run.out
    assert first_finding < next(i for i, ln in enumerate(lines) if ln.startswith("UNIT "))
    dead = next(i for i, ln in enumerate(lines) if ln.startswith("  FAIL") and "zzz0" in ln)
    slow = next(i for i, ln in enumerate(lines) if ln.startswith("  FAIL") and "aaa0" in ln)
    assert dead < slow and "it died at" in lines[dead]
    assert not any(ln.startswith(("00:", "01:", "02:")) and " HB-0" in ln for ln in lines), \
        "the replayed stream is not printed line by line"
    # One set of counts in every output.
    (html,) = reports_dir.glob("*.html")
    counts = {v: n for v, n in run.report["conclusion"]["counts"].items() if n}
    assert text_counts(run.out) == counts
    assert {v: n for v, n in html_counts(html.read_text()).items() if n} == counts
    assert sum(counts.values()) == sum(run.report["verdict_counts"].values())


def test_the_evidence_cap_never_cuts_a_death_for_a_rate(prefix: str) -> None:
    """Units named before the dead one fail a rate: capped at 2, the death is still shown
    (strict: with no command before it, a stop is HB-012's decided 'no-command')."""
    from conformance.lint.runner import failures
    from conformance.reporting.text import render_verdicts

    m = Monitor(Profile(strict=True), kind="lint")
    msgs = [*unit_traffic(prefix, "zzz0", seconds=10)]
    for name in ("aaa0", "aaa1", "aaa2"):
        msgs += unit_traffic(prefix, name, seconds=30, heartbeat_every=2)
    for msg in sorted(msgs, key=lambda x: x.time):
        m.feed(msg)
    m.finish(T0 + 30)
    report = m.report()
    capped = failures(report, limit=2)
    assert capped.index("HB-012") < capped.index("HB-003")
    assert capped.count("HB-003 heartbeat rate") == 1
    assert capped.endswith("... and 2 more failed rules: every violation is in the reports")
    opening = render_verdicts(report, per_unit=1)
    assert opening.splitlines()[1].startswith("  FAIL ") and "zzz0" in opening.splitlines()[1]
    assert opening.splitlines()[2].split()[:2] == ["death", "HB-012"]


def test_the_suites_probes_seen_live_are_shown_as_in_the_final_outputs(prefix: str) -> None:
    """Lint beside a certification sees the suite's commands and its deliberately malformed
    probes: they are no commander's fault (docs/ARCHITECTURE.md 'Whose fault it is') and the
    final report has no row for them, so no live line shows them failing either."""
    from conformance.checks.suite_commands import LABEL, SENDER, UNREADABLE

    out = io.StringIO()
    card = Scorecard(out, tty=False)
    linter = Linter(Monitor(Profile(), kind="lint"), Profile())
    msgs = unit_traffic(prefix, "dji0", seconds=6, agent_uuid=DJI0)
    command = f"{prefix}/unit/air/simulation/dji0/exec/command"
    msgs.append(Message(T0 + 2.1, command, orjson.dumps(
        {"com-uuid": "not-a-uuid", "command": "no-such-command", "sender": SENDER})))
    msgs += [Message(T0 + 2.2 + i * 0.01, command, payload)
             for i, (_, payload) in enumerate(UNREADABLE)]
    linter.feed(sorted(msgs, key=lambda m: m.time))
    card.update(linter, force=True)
    assert LABEL not in out.getvalue() and LABEL not in linter.by_unit
    assert linter.failing_units() == []
    linter.finish(T0 + 6.5)
    assert LABEL not in linter.monitor.report().units


def test_a_finding_judged_after_its_evidence_is_printed_in_time_order(prefix: str) -> None:
    """A ping left unanswered is judged when the unit next answers, its finding stamped
    when the ping was sent: the live line is printed at the time it was found, in order
    with the others, and says when its evidence was sent."""
    import time as time_module
    import uuid

    out = io.StringIO()
    card = Scorecard(out, tty=False)
    linter = Linter(Monitor(Profile(), kind="lint"), Profile())
    base = f"{prefix}/unit/air/simulation/dji0"
    first, second = str(uuid.uuid4()), str(uuid.uuid4())
    msgs = unit_traffic(prefix, "dji0", seconds=12, agent_uuid=DJI0)
    msgs += [Message(T0 + 2.0, f"{base}/exec/command", orjson.dumps(
                 {"com-uuid": first, "command": "ping", "sender": "op0"})),
             Message(T0 + 8.0, f"{base}/exec/command", orjson.dumps(
                 {"com-uuid": second, "command": "ping", "sender": "op0"})),
             Message(T0 + 8.1, f"{base}/exec/response", orjson.dumps(
                 {"agent-uuid": DJI0, "com-uuid": str(uuid.uuid4()), "response": "pong",
                  "response-to": second}))]
    for m in sorted(msgs, key=lambda m: m.time):
        linter.feed([m])
        card.update(linter)
    (line,) = [ln for ln in out.getvalue().splitlines() if " EXEC-PING-001 " in ln]

    def clock(t: float) -> str:
        return time_module.strftime("%H:%M:%S", time_module.localtime(t))

    assert line.startswith(f"{clock(T0 + 8.1)} FAIL {base} EXEC-PING-001 "), line
    assert f"(its evidence sent at {clock(T0 + 2.0)})" in line

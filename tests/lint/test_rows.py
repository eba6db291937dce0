"""The terminal scorecard and the fleet page show one unit alike: both render ``lint.rows``
(3). One run (a clean unit, one that breaks a rule, one slower than it declares, a
commander with a clean command and one with a faulty one), read off both as they render it:
while it runs and at its end."""

from __future__ import annotations

import html
import re
import uuid

import orjson
from lint_helpers import T0, unit_traffic

from conformance.checks import Monitor
from conformance.client import Message
from conformance.facts import RunFacts
from conformance.judge import judge
from conformance.lint.fleetview import FleetView
from conformance.lint.linter import Linter
from conformance.lint.scorecard import Scorecard, rows_from_report
from conformance.lint.serve import App
from conformance.profile import Profile

DJI0 = "4774daa2-246c-4124-8d92-5e7806c5b385"


def traffic(prefix: str) -> list[Message]:
    """dji0 clean, bad0 with heartbeats of the wrong type (HB-002), slow0 at 0.45 Hz while it
    declares 1 Hz (HB-003, live: off by 2x or more, the rule's words, so it fails live as at
    the end; a drift within 2x is a decided condition and warns); op0 pings dji0, op1 sends a
    command without com-uuid."""
    msgs = unit_traffic(prefix, "dji0", seconds=20, agent_uuid=DJI0)
    for m in unit_traffic(prefix, "bad0", seconds=20):
        if m.topic.endswith("/heartbeat"):
            hb = orjson.loads(m.payload)
            hb["type"] = "Heartbeat"
            m = Message(m.time, m.topic, orjson.dumps(hb))
        msgs.append(m)
    for m in unit_traffic(prefix, "slow0", seconds=30, rate=1 / 2.2):
        if m.topic.endswith("/heartbeat"):
            hb = orjson.loads(m.payload)
            hb["rate"] = 1.0
            m = Message(m.time, m.topic, orjson.dumps(hb))
        msgs.append(m)
    command = f"{prefix}/unit/air/simulation/dji0/exec/command"
    msgs.append(Message(T0 + 5.0, command, orjson.dumps(
        {"com-uuid": str(uuid.uuid4()), "command": "ping", "sender": "op0"})))
    msgs.append(Message(T0 + 6.0, command, orjson.dumps({"command": "ping", "sender": "op1"})))
    return sorted(msgs, key=lambda m: m.time)


def terminal(card: Scorecard, rows: list) -> dict[str, tuple[str, set[str]]]:
    """Unit -> (status, {'RULExN', 'RULE(live)'}) as the scorecard's table shows them."""
    head, *lines = card.table(rows, None, width=400)
    at, width = head.index("STATUS"), head.index("TYPE") - 1
    out = {}
    for line in lines:
        status, _, viol = line[at:].partition(" ")
        out[line[:width].rstrip()] = (status, set(viol.split()) - {"-"})
    return out


def page(view: FleetView) -> dict[str, tuple[str, set[str]]]:
    """Unit -> (status, {'RULExN', 'RULE(live)'}) as the fleet page's table shows them."""
    body = App(view).route("/fragment/fleet")[1].decode()
    out = {}
    for row in re.findall(r'<tr class="row .*?</tr>', body, re.S):
        unit = html.unescape(re.search(r'data-unit="([^"]*)"', row)[1])
        status = html.unescape(re.search(r'data-status="([^"]*)"', row)[1])
        assert "more</div>" not in row, "every finding of the run fits in a row"
        found = {f"{r}x{n or 0}" for r, n in re.findall(
            r'#[^"]*">([A-Z0-9-]+)</a>[^<]*(?:<span class="muted">×(\d+)</span>)?', row)}
        found |= {f"{r}(live)" for r in re.findall(r'<span class="mono">([A-Z0-9-]+)</span> off',
                                                    row)}
        out[unit] = (status, found)
    return out


def test_the_terminal_and_the_page_show_each_unit_alike(prefix: str) -> None:
    profile = Profile()
    linter = Linter(Monitor(profile, kind="lint"), profile)
    card = Scorecard(tty=False, live=False)
    view = FleetView("test", live=False)
    for m in traffic(prefix):
        linter.feed([m])
        view.observe(linter)
    view.observe(linter, force=True)
    shown = terminal(card, card.rows(linter))
    assert shown == page(view)
    slow = shown[f"{prefix}/unit/air/simulation/slow0"]
    assert slow[0] == "FAIL" and "HB-003(live)" in slow[1], shown
    assert shown[f"{prefix}/unit/air/simulation/bad0"][0] == "FAIL"
    assert shown[f"{prefix}/unit/air/simulation/dji0"][0] in ("ok", "warn")
    assert shown["commander op0"] == ("ok", set()), shown  # a row each, clean or not
    assert shown["commander op1"][0] == "FAIL"

    linter.finish(linter.last_time)
    report = judge(linter.monitor.report(), RunFacts(kind="lint"))
    view.finish(linter, report, verdict=report.conclusion.verdict)
    final = terminal(card, rows_from_report(report))
    assert final == page(view)
    assert final[f"{prefix}/unit/air/simulation/bad0"][0] == "FAIL"
    assert any("HB-002" in f for f in final[f"{prefix}/unit/air/simulation/bad0"][1])


def test_a_silent_unit_is_silent_alike_on_the_terminal_the_page_and_the_metrics(
        prefix: str) -> None:
    """gone0 stops after 5 s while dji0 goes on: once lint looks (``watch_silences``), both
    views and /metrics say it is silent, from the one row; it fails no rule for that yet."""
    from prometheus_client.parser import text_string_to_metric_families

    from conformance.lint.metrics import exposition

    profile = Profile()
    linter = Linter(Monitor(profile, kind="lint"), profile)
    card = Scorecard(tty=False, live=False)
    view = FleetView("test", live=False)
    msgs = unit_traffic(prefix, "dji0", seconds=20) + unit_traffic(prefix, "gone0", seconds=5)
    linter.feed(sorted(msgs, key=lambda m: m.time))
    linter.watch_silences()
    view.observe(linter, force=True)
    gone = f"{prefix}/unit/air/simulation/gone0"
    shown = terminal(card, card.rows(linter))
    assert shown == page(view)
    assert shown[gone][0] == "silent" and shown[f"{prefix}/unit/air/simulation/dji0"][0] == "ok"
    assert any(v.unit == gone and "silent since" in v.observed for v in linter.fleet)
    families = {f.name: f for f in text_string_to_metric_families(
        exposition(lambda: view.snapshot).decode())}
    up = {s.labels["unit"]: s.value for s in families["waraps_lint_unit_up"].samples}
    failing = {s.labels["unit"]: s.value for s in families["waraps_lint_unit_failing"].samples}
    assert up[gone] == 0.0 and failing[gone] == 0.0

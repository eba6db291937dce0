"""Liveness, live: a unit of a live fleet that dies while ``lint --serve`` watches is shown
silent at once (page, terminal, /metrics: ``waraps_lint_unit_up``, its last-seen timestamp),
listed in the fleet observations, and shown back when it returns; the shipped alert rules
(docs/alerts/waraps-lint.rules.yml), evaluated over real scrapes of lint, fire on it."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest
import yaml
from lint_helpers import Process
from promql import Sample, evaluate, scrape
from test_lint_serve import get, rows, serving, wait_until

from conformance.lint.metrics import CONTENT_TYPE
from conformance.sim.fleet import Fleet

RULES = Path(__file__).parents[2] / "docs" / "alerts" / "waraps-lint.rules.yml"
JOB = "waraps-lint"
RATE = 2.0
"""Hz: silent after 3 periods (1.5 s); seen within a snapshot (1 s) and a poll."""
SEEN_WITHIN = 10 * (1.0 / RATE) + 3.0
"""Seconds from the kill to the page and /metrics saying so: 3 periods of silence, then
lint's next snapshot, with room for a loaded machine (2 shared cores)."""


def alert_rules() -> dict[str, str]:
    groups = yaml.safe_load(RULES.read_text())["groups"]
    return {r["alert"]: r["expr"] for g in groups for r in g["rules"]}


def metrics(url: str) -> list[Sample]:
    from prometheus_client.parser import text_string_to_metric_families

    status, headers, body = get(f"{url}metrics")
    assert status == 200 and headers["Content-Type"] == CONTENT_TYPE, headers
    return scrape(text_string_to_metric_families(body.decode()), job=JOB, up=True)


def values(samples: list[Sample], name: str) -> dict[str, float]:
    return {s.label("unit"): s.value for s in samples if s.name == name}


def firing(rule: str, samples: list[Sample]) -> set[str]:
    return {s.label("unit") or rule for s in evaluate(alert_rules()[rule], samples, time.time())}


def test_every_shipped_alert_rule_is_within_what_the_evaluator_reads() -> None:
    rules = alert_rules()
    assert set(rules) == {"WarapsUnitSilent", "WarapsUnitFailing", "WarapsLintStopped"}
    for expr in rules.values():
        evaluate(expr, [], 0.0)  # raises on anything it does not evaluate exactly


@pytest.mark.slow
@pytest.mark.mosquitto
def test_a_unit_killed_in_a_live_fleet_is_silent_at_once_and_back_when_it_returns(
        mosquitto: str, prefix: str, tmp_path: Path) -> None:
    names = [f"{prefix}/unit/air/simulation/dji{i}" for i in range(3)]
    with Fleet(names[0], mosquitto, 3, rate=RATE) as fleet:
        lint = Process(["lint", "--broker", mosquitto, "--topic", f"{prefix}/#", "--serve", "0",
                        "--serve-linger", "30", "--plain",
                        "--reports-dir", str(tmp_path / "reports")])
        try:
            url = serving(lint)
            wait_until("every unit clean", lambda: all(
                rows(get(url)[2].decode()).get(n) == "ok" for n in names), timeout=20)
            before = metrics(url)
            assert values(before, "waraps_lint_unit_up") == dict.fromkeys(names, 1.0)
            assert firing("WarapsUnitSilent", before) == set()
            assert firing("WarapsUnitFailing", before) == set()
            assert firing("WarapsLintStopped", before) == set()

            fleet.kill(1)
            killed = time.time()
            page = wait_until("dji1 silent on the page", lambda: (lambda r: r if r.get(
                names[1]) == "silent" else None)(rows(get(url)[2].decode())),
                timeout=SEEN_WITHIN)
            assert page[names[0]] == page[names[2]] == "ok", page
            html = get(url)[2].decode()
            assert "silent: no heartbeat since" in html  # its row says since when
            assert "HB-010" in html.split("Fleet observations", 1)[1]  # listed as it happens
            after = wait_until("dji1 down in /metrics", lambda: (lambda m: m if values(
                m, "waraps_lint_unit_up").get(names[1]) == 0.0 else None)(metrics(url)),
                timeout=SEEN_WITHIN)
            assert values(after, "waraps_lint_unit_up")[names[0]] == 1.0
            silent = {s.label("status"): s.value for s in after
                      if s.name == "waraps_lint_units" and s.label("party") == "unit"}
            assert silent["silent"] == 1.0, silent
            last_seen = values(after, "waraps_lint_unit_last_seen_timestamp_seconds")
            assert last_seen[names[1]] <= killed + 1.0 / RATE < last_seen[names[0]]
            assert firing("WarapsUnitSilent", after) == {names[1]}
            # A silence alone is no verdict yet: it fails HB-010 or HB-012 as the judge says
            assert firing("WarapsUnitFailing", after) == set()
            assert firing("WarapsLintStopped", after) == set()
            lint.wait_for(f"{names[1]} silent: no heartbeat since")  # the terminal too

            fleet.reboot(1)  # back, with a new agent-uuid
            back = wait_until("dji1 back on the page", lambda: (lambda r: r if r.get(
                names[1]) not in (None, "silent") else None)(rows(get(url)[2].decode())),
                timeout=SEEN_WITHIN)
            assert back[names[1]] in ("FAIL", "ok"), back  # HB-010 judges the silence
            wait_until("dji1 up in /metrics", lambda: values(
                metrics(url), "waraps_lint_unit_up").get(names[1]) == 1.0, timeout=SEEN_WITHIN)
            lint.wait_for(f"{names[1]} heard again")
            assert "until heard again" in get(url)[2].decode().split("Fleet observations")[1]
            assert firing("WarapsUnitSilent", metrics(url)) == set()
            lint.proc.send_signal(signal.SIGINT)  # the run ends; the page lingers
            lint.wait_for("serving the final fleet page", timeout=30)
            assert firing("WarapsLintStopped", metrics(url)) == {"WarapsLintStopped"}
        finally:
            lint.interrupt()
    unreachable = scrape([], job=JOB, up=False)  # the scrape of a lint that is gone
    assert firing("WarapsLintStopped", unreachable) == {"WarapsLintStopped"}


@pytest.mark.parametrize("rows", [0, 2])
def test_metrics_follow_the_exposition_conventions(rows: int) -> None:
    """Text format 0.0.4 as Prometheus expects it, base units (seconds, no ``_hz``), and no
    family that announces itself (HELP, TYPE) without a sample (a recording's end, no unit)."""
    from conformance.lint import metrics
    from conformance.lint.fleetview import RateView, Row, Snapshot

    assert metrics.CONTENT_TYPE == "text/plain; version=0.0.4; charset=utf-8"
    units = tuple(Row(f"p/unit/air/simulation/u{i}", "unit", messages=5, last_seen=10.0,
                      rates=(RateView("heartbeat", 2.0, 1.0),), by_kind=(("heartbeat", 5),))
                  for i in range(rows))
    text = metrics.exposition(lambda: Snapshot(1, 0.0, None, "", True, True, 5, 0, 0, None,
                                               units)).decode()
    assert "_hz" not in text
    announced = [line.split()[2] for line in text.splitlines() if line.startswith("# TYPE")]
    samples = {line.split("{")[0].split()[0] for line in text.splitlines()
               if line and not line.startswith("#")}
    for name in announced:
        assert {name, f"{name}_total"} & samples, f"{name}: HELP and TYPE, no sample"
    if rows:
        assert 'waraps_lint_period_seconds{kind="heartbeat",unit="p/unit/air/simulation/u0",' \
               'which="declared"} 0.5' in text

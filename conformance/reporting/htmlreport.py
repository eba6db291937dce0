"""The HTML report: one self-contained file (inline CSS and SVG, no script, no network).

It opens with what a person came for: the run's verdict (``not certified`` or
``interrupted`` when the run did not complete, never a pass), the levels certified and the
failing rules. Then the header facts, each once and in words (kind, units, broker, profile,
agent-uuids, times, suite version, schemas hash, verdict counts), then per unit a scorecard (verdict per rule with title, spec section and reason), a
plot of every measured rate over time against the declared rate, and the evidence of every
failure and warning. Everything that came from the wire is escaped: payload excerpts are
hostile input.
"""

from __future__ import annotations

import html
import os
from pathlib import Path

from conformance.reporting.files import atomic_write
from conformance.reporting.text import iso_time, printable
from conformance.results import RateStat, RunReport, UnitReport
from conformance.rules import CATALOGUE
from conformance.violation import RuleResult, Verdict, Violation

COLOURS = {
    Verdict.PASS: "#1a7f37", Verdict.FAIL: "#cf222e", Verdict.WARN: "#9a6700",
    Verdict.SKIP: "#6e7781", Verdict.COULD_NOT_TEST: "#8250df",
}
ORDER = [Verdict.FAIL, Verdict.WARN, Verdict.COULD_NOT_TEST, Verdict.PASS, Verdict.SKIP]
RUN_VERDICT_COLOURS = {"not certified": "#cf222e", "interrupted": "#bc4c00"}
# Run facts (RunReport.meta) in words, in this order; keys shown elsewhere are left out.
META_WORDS = (("error", "why not certified"), ("not_run", "rules not run"),
              ("profile_source", "profile file"), ("timing_scale", "timing scale"),
              ("seed", "seed"), ("dry_run", "dry run"), ("allow_motion", "motion allowed"),
              ("reboot", "reboot"), ("commands_sent", "commands sent"),
              ("rerun", "repeat this run"))
META_SHOWN_ELSEWHERE = {"unit", "broker", "started", "finished", "suite_version", "agent_uuid",
                        "verdict", "interrupted", "exit_status"}
SERIES_COLOURS = ["#0969da", "#bf3989", "#1a7f37", "#bc4c00", "#8250df", "#6e7781"]

CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"Liberation Sans",sans-serif;
 margin:0;padding:24px 32px;color:#1f2328;background:#fff}
h1{font-size:22px;margin:0 0 12px}h2{font-size:18px;margin:32px 0 8px;padding-top:12px;
 border-top:2px solid #d0d7de}h3{font-size:15px;margin:20px 0 6px}
table{border-collapse:collapse;margin:4px 0 12px}td,th{padding:3px 10px 3px 0;text-align:left;
 vertical-align:top}th{color:#57606a;font-weight:600}
table.card td,table.card th{border-bottom:1px solid #eaeef2;padding:4px 10px 4px 4px}
th,td.mono,td:has(.badge){white-space:nowrap}
.badge{display:inline-block;padding:1px 8px;border-radius:10px;color:#fff;font-weight:600;
 font-size:12px;white-space:nowrap}
.mono,code,pre{font-family:ui-monospace,"DejaVu Sans Mono","Liberation Mono",monospace;
 font-size:12.5px}
pre{background:#f6f8fa;border:1px solid #d0d7de;padding:6px 8px;white-space:pre-wrap;
 word-break:break-all;margin:2px 0;max-width:100ch}
.ev{border-left:4px solid #cf222e;padding:4px 0 4px 12px;margin:8px 0 14px}
.ev.warn{border-left-color:#9a6700}.plots{display:flex;flex-wrap:wrap;gap:16px}
.plot{border:1px solid #d0d7de;border-radius:6px;padding:6px 8px;max-width:384px}.muted{color:#57606a}
details summary{cursor:pointer;color:#57606a;margin:6px 0}nav a{margin-right:12px}
"""


def esc(text: object) -> str:
    """Escaped for HTML text and attributes, control characters made visible."""
    return html.escape(printable("" if text is None else text), quote=True)


def badge(verdict: Verdict, text: str | None = None) -> str:
    return (f'<span class="badge v-{verdict.value}" style="background:{COLOURS[verdict]}">'
            f"{esc(text or verdict.value)}</span>")


def anchor(unit: str) -> str:
    return "u-" + "".join(c if c.isalnum() else "-" for c in unit)


def run_verdict(report: RunReport) -> str:
    """The run's verdict: the certification's own (``meta['verdict']``), else the worst."""
    return report.meta.get("verdict") or report.worst().value


def _verdict_badge(text: str) -> str:
    try:
        return badge(Verdict(text))
    except ValueError:
        colour = RUN_VERDICT_COLOURS.get(text, "#6e7781")
        return (f'<span class="badge v-run" style="background:{colour}">{esc(text)}</span>')


def render_html(report: RunReport, files: list[str] | None = None) -> str:
    """The whole report as one HTML document; ``files`` are the names of the files written
    with it (the footer says which)."""
    out: list[str] = []
    title = f"WARA-PS conformance {report.kind} report"
    out.append(f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
               f'<meta name="viewport" content="width=device-width,initial-scale=1">'
               f"<title>{esc(title)}</title><style>{CSS}</style></head><body>")
    out.append(f"<h1>{esc(title)} {_verdict_badge(run_verdict(report))}</h1>")
    out.append(_summary(report))
    out.append(_header(report))
    for name, unit in report.units.items():
        out.append(_unit(report, name, unit))
    written = ", ".join(files or [])
    out.append(f'<p class="muted">waraps-conformance {esc(report.suite_version)} — '
               + (f"written together with {esc(written)}, from the same results."
                  if written else "written on its own.") + "</p>")
    out.append("</body></html>\n")
    return "".join(out)


def _summary(report: RunReport) -> str:
    """Verdict, levels certified and failing rules: the first thing a person reads."""
    from conformance.results import LEVEL_NAMES

    verdict = run_verdict(report)
    rows = [("verdict", _verdict_badge(verdict))]
    complete = verdict not in RUN_VERDICT_COLOURS
    for name, unit in report.units.items():
        levels = []
        for level in unit.levels:
            failing = [r for r in unit.rules.values() if r.verdict is Verdict.FAIL
                       and CATALOGUE.get(r.rule) is not None
                       and LEVEL_NAMES.get(CATALOGUE[r.rule].level) == level]
            state = ("not certified: the run did not complete" if not complete else
                     f"not certified: {len(failing)} failing rule(s)" if failing else
                     "certified")
            levels.append(f"{esc(level)} — {esc(state)}")
        rows.append((f"levels of {esc(name)}" if len(report.units) > 1 else "levels",
                     "<br>".join(levels) or "none declared"))
    failing = [(u, r) for u, r in report.failures() if r.verdict is Verdict.FAIL]
    if failing:
        rows.append(("failing rules", "<br>".join(
            f'<a href="#{anchor(u)}-{esc(r.rule)}" class="mono">{esc(r.rule)}</a> '
            f"{esc(CATALOGUE[r.rule].title if r.rule in CATALOGUE else '')}"
            + (f' <span class="muted">({esc(u)})</span>' if len(report.units) > 1 else "")
            for u, r in failing)))
    return '<table class="summary">' + "".join(
        f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows) + "</table>"


def _header(report: RunReport) -> str:
    counts = report.verdict_counts()
    # Rules that never ran are recorded could-not-test ('not run: ...'); counted apart.
    not_run = len(report.meta.get("not_run", "").split())
    counts[Verdict.COULD_NOT_TEST.value] -= not_run
    rows = [
        ("kind", esc(report.kind)),
        ("units", f"{len(report.units)}: " + " ".join(
            f'<a href="#{anchor(n)}" class="mono">{esc(n)}</a>' for n in report.units)),
        ("broker", f'<span class="mono">{esc(report.broker or "-")}</span>'),
        ("profile", esc(report.profile)),
        ("agent-uuid", "<br>".join(
            f'<span class="mono">{esc(n)}: {esc(", ".join(u.agent_uuids) or "-")}</span>'
            for n, u in report.units.items() if n != "(unattributed)")),
        ("started", esc(iso_time(report.started))),
        ("finished", esc(iso_time(report.finished)) or "(running)"),
        ("suite version", esc(report.suite_version)),
        ("schemas hash", f'<span class="mono">{esc(report.schemas_hash or "-")}</span>'),
        ("verdicts", " ".join(badge(v, f"{counts[v.value]} {v.value}") for v in ORDER)
         + (f" {_verdict_badge(f'{not_run} not run')}" if not_run else "")),
        ("exit status", esc(report.meta.get("exit_status", report.exit_code()))),
    ]
    if report.gaps:
        rows.append(("observer gaps", "<br>".join(
            f"{esc(iso_time(a))} – {esc(iso_time(b))} ({b - a:.1f} s)" for a, b in report.gaps)))
    if report.unexamined:
        rows.append(("unexamined", f"{report.unexamined} messages could not be examined"))
    words = dict(META_WORDS)
    for key in dict.fromkeys([k for k, _ in META_WORDS] + sorted(report.meta)):
        value = report.meta.get(key)
        if value and key not in META_SHOWN_ELSEWHERE:
            rows.append((esc(words.get(key, key.replace("_", " "))), esc(value)))
    return '<table class="head">' + "".join(
        f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows) + "</table>"


def _unit(report: RunReport, name: str, unit: UnitReport) -> str:
    out = [f'<h2 id="{anchor(name)}"><span class="mono">{esc(name)}</span> '
           f"{badge(unit.worst())}</h2>"]
    counts = unit.verdict_counts()
    if unit.party == "commander":  # what it sent, judged by the commander's rules
        facts = [("party", "commander: the rules of what it sent (its commands)"),
                 ("commands", esc(unit.message_count)),
                 ("seen", f"{esc(iso_time(unit.first_seen))} – {esc(iso_time(unit.last_seen))}"),
                 ("verdicts", " ".join(badge(v, f"{counts[v.value]} {v.value}")
                                       for v in ORDER))]
        out.append("<table>" + "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in facts)
                   + "</table>")
        out.append("<h3>Scorecard</h3>")
        out.append(_scorecard(sorted((r for r in unit.rules.values()
                                      if r.verdict is not Verdict.SKIP),
                                     key=lambda r: ORDER.index(r.verdict))))
        return "".join(out)
    facts = [
        ("agent-type / role / name", esc(f"{unit.agent_type} / {unit.role} / {unit.name}")),
        ("agent-uuid", f'<span class="mono">{esc(", ".join(unit.agent_uuids) or "-")}</span>'),
        ("levels", esc(", ".join(unit.levels) or "-")),
        ("messages", esc(unit.message_count)),
        ("seen", f"{esc(iso_time(unit.first_seen))} – {esc(iso_time(unit.last_seen))}"),
        ("verdicts", " ".join(badge(v, f"{counts[v.value]} {v.value}") for v in ORDER)),
    ]
    listed = unit.facts.get("sensors_listed")
    if listed:
        facts.append(("sensors listed", esc(", ".join(map(str, listed)))))
    out.append("<table>" + "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in facts)
               + "</table>")
    out.append("<h3>Scorecard</h3>")
    ranked = sorted(unit.rules.values(), key=lambda r: ORDER.index(r.verdict))
    shown = [r for r in ranked if r.verdict is not Verdict.SKIP]
    skipped = [r for r in ranked if r.verdict is Verdict.SKIP]
    out.append(_scorecard(shown))
    if skipped:
        out.append(f"<details><summary>{len(skipped)} rules skipped (not claimed, not "
                   f"observed, or needing a stimulus)</summary>{_scorecard(skipped)}</details>")
    if unit.rates:
        out.append("<h3>Rates</h3><div class=\"plots\">")
        out.extend(_rate_plot(r, i) for i, r in enumerate(unit.rates))
        out.append("</div>")
    bad = [r for r in ranked if r.verdict in (Verdict.FAIL, Verdict.WARN)]
    if bad:
        out.append("<h3>Evidence</h3>")
        for r in bad:
            out.append(_evidence(unit, r, f"{anchor(name)}-{r.rule}"))
    return "".join(out)


def _scorecard(results: list[RuleResult]) -> str:
    rows = []
    for r in results:
        rule = CATALOGUE.get(r.rule)
        rows.append(f'<tr class="rule v-{r.verdict.value}"><td class="mono">{esc(r.rule)}</td>'
                    f"<td>{badge(r.verdict)}</td><td>{esc(rule.title if rule else '')}</td>"
                    f'<td class="muted">{esc(rule.section if rule else "")}</td>'
                    f"<td>{esc(r.reason)}</td></tr>")
    return ('<table class="card"><tr><th>rule</th><th>verdict</th><th>title</th><th>spec</th>'
            "<th>reason</th></tr>" + "".join(rows) + "</table>")


def _evidence(unit: UnitReport, r: RuleResult, ident: str = "") -> str:
    rule = CATALOGUE.get(r.rule)
    total = unit.violation_counts.get(r.rule, len(r.violations))
    more = (f' <span class="muted">(showing {len(r.violations)} of {total})</span>'
            if total > len(r.violations) else "")
    out = [f'<div class="ev {r.verdict.value}" id="{esc(ident)}"><b class="mono">{esc(r.rule)}</b> '
           f"{esc(rule.title if rule else '')} {badge(r.verdict)}{more}"
           f'<div class="muted">spec {esc(rule.section if rule else "")}</div>']
    if not r.violations:
        out.append(f"<p>{esc(r.reason)}</p>")
    for v in r.violations:
        out.append(_violation(v))
    out.append("</div>")
    return "".join(out)


def _violation(v: Violation) -> str:
    rows = [("expected", esc(v.expected)), ("observed", esc(v.observed)),
            ("topic", f'<span class="mono">{esc(v.topic)}</span>' if v.topic else ""),
            ("time", esc(iso_time(v.time))),
            ("JSON path", f'<span class="mono">{esc(v.path)}</span>' if v.path else ""),
            ("hint", esc(v.detail))]
    body = "".join(f"<tr><th>{k}</th><td>{val}</td></tr>" for k, val in rows if val)
    if v.excerpt:
        body += f'<tr><th>payload</th><td><pre class="payload">{esc(v.excerpt)}</pre></td></tr>'
    return f'<table class="violation">{body}</table>'


def _rate_plot(stat: RateStat, index: int) -> str:
    """A small SVG plot: measured rate (Hz) over time, the declared rate dashed, and the
    tolerance band when known."""
    w, h, left, right, top, bottom = 380, 170, 44, 10, 10, 26
    colour = SERIES_COLOURS[index % len(SERIES_COLOURS)]
    pts = [(t, r) for t, r in stat.series if r == r and r != float("inf")]
    t0 = stat.start if stat.start is not None else (pts[0][0] if pts else 0.0)
    t1 = max([stat.end or t0] + [t for t, _ in pts] + [t0 + 1e-9])
    ymax = max([r for _, r in pts] + [(stat.declared_hz or 0) * 1.5, 1e-9]) * 1.1
    clipped = False
    if stat.declared_hz and ymax > stat.declared_hz * 4:
        # A burst at 1000x the declared rate would flatten everything else: clip at 4x.
        ymax, clipped = stat.declared_hz * 4, True
        pts = [(t, min(r, ymax)) for t, r in pts]

    def x(t: float) -> float:
        return left + (t - t0) / (t1 - t0) * (w - left - right)

    def y(r: float) -> float:
        return top + (1 - r / ymax) * (h - top - bottom)

    measured = (f"{stat.measured_hz:.2f} Hz over {stat.intervals} intervals"
                if stat.measured_hz else "not measured")
    declared = f"{stat.declared_hz:.2f} Hz" if stat.declared_hz else "none"
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
           f'viewBox="0 0 {w} {h}" role="img" aria-label="{esc(stat.kind)} rate">']
    svg.append(f'<rect x="{left}" y="{top}" width="{w - left - right}" '
               f'height="{h - top - bottom}" fill="#f6f8fa" stroke="#d0d7de"/>')
    if stat.declared_hz:
        tol = stat.tolerance
        if tol is not None and 0 <= tol < 1:
            hi, lo = stat.declared_hz / (1 - tol), stat.declared_hz / (1 + tol)
            svg.append(f'<rect x="{left}" y="{y(min(hi, ymax)):.1f}" width="{w - left - right}" '
                       f'height="{max(0.0, y(lo) - y(min(hi, ymax))):.1f}" fill="{colour}" '
                       f'fill-opacity="0.10"/>')
        yd = y(stat.declared_hz)
        svg.append(f'<line x1="{left}" y1="{yd:.1f}" x2="{w - right}" y2="{yd:.1f}" '
                   f'stroke="#57606a" stroke-dasharray="5 4"/>'
                   f'<text x="{w - right - 4}" y="{yd - 4:.1f}" font-size="10" '
                   f'text-anchor="end" fill="#57606a">declared {esc(declared)}</text>')
    if len(pts) == 1:
        svg.append(f'<circle cx="{x(pts[0][0]):.1f}" cy="{y(pts[0][1]):.1f}" r="2.5" '
                   f'fill="{colour}"/>')
    elif pts:
        path = " ".join(f"{x(t):.1f},{y(r):.1f}" for t, r in pts)
        svg.append(f'<polyline points="{path}" fill="none" stroke="{colour}" '
                   f'stroke-width="1.5"/>')
    else:
        svg.append(f'<text x="{(w + left) / 2}" y="{h / 2}" font-size="12" text-anchor="middle" '
                   f'fill="#57606a">no intervals measured</text>')
    if clipped:
        svg.append(f'<text x="{left + 4}" y="{top + 11}" font-size="10" fill="#cf222e">'
                   f"clipped at {ymax:.3g} Hz</text>")
    for r in (0.0, ymax if clipped else ymax / 1.1):
        svg.append(f'<text x="{left - 4}" y="{y(r) + 4:.1f}" font-size="10" text-anchor="end" '
                   f'fill="#57606a">{r:.2g}</text>')
    svg.append(f'<text x="{left}" y="{h - 8}" font-size="10" fill="#57606a">0 s</text>'
               f'<text x="{w - right}" y="{h - 8}" font-size="10" text-anchor="end" '
               f'fill="#57606a">{t1 - t0:.1f} s</text>'
               f'<text x="{(w + left) / 2}" y="{h - 8}" font-size="10" text-anchor="middle" '
               f'fill="#57606a">Hz over time</text>')
    svg.append("</svg>")
    caption = (f'<div><b class="mono">{esc(stat.kind)}</b> {badge(stat.verdict)} '
               f'<span class="mono">{esc(stat.rule)}</span><br>'
               f'<span class="muted">declared {esc(declared)}, measured {esc(measured)}'
               f"{', ' + esc(stat.reason) if stat.reason else ''}</span></div>")
    return f'<figure class="plot" style="margin:0">{caption}{"".join(svg)}</figure>'


def write_html(report: RunReport, path: str | os.PathLike[str],
               files: list[str] | None = None) -> Path:
    """Write the report as one self-contained HTML file (atomically); the path written.
    ``files``: the names of the other files written with it."""
    return atomic_write(path, render_html(report, files))

"""How a certification presents itself: the header of its pytest run (what is certified,
where, how safely) and the line that repeats it (STYLE 'pytest-randomly': every run
repeatable), shown in the header, the summary, every failure and the reports."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from conformance import __version__
from conformance.client import BrokerURL
from conformance.suite.settings import Settings


def repeat_command(settings: Settings, rule: str | None = None, *, observe: int = 0) -> str:
    """The rerun line: the pytest command that repeats this run (of ``rule`` alone, when
    given); ``observe``: seconds of observation it needs at least (``--observe``)."""
    s = settings
    parts = ["pytest", "--unit", str(s.unit)]
    parts += ["--broker", str(s.broker)]
    parts += [f"--sim-fault={f}" for f in s.sim_faults]
    if s.embedded and s.sim_rate != 1.0:
        parts += ["--sim-rate", f"{s.sim_rate:g}"]
    if s.sim_tst:
        parts.append("--sim-tst")
    if s.tst_command_topic:
        parts += ["--tst-command-topic", s.tst_command_topic]
    if s.profile.source.startswith("<built-in"):
        if s.profile.name != "default":
            parts += ["--profile", s.profile.name]
    else:  # '=': a path in its own argument could be taken for a test path by pytest
        parts += [f"--profile={s.profile.source}"]
    if s.timing_scale != 1.0:
        parts += ["--timing-scale", f"{s.timing_scale:g}"]
    parts += ["--seed", str(s.seed)]
    if observe or s.observe:
        parts += ["--observe", f"{max(observe, int(s.observe))}"]
    if rule:
        parts += ["-k", rule]
    return " ".join(parts)


def header_lines(settings: Settings, *, broker: BrokerURL, heartbeat: dict[str, Any],
                 levels: list[str], reboot: str | None, reports: Path, rerun: str
                 ) -> list[str]:
    """The lines pytest shows before the tests: ``broker`` connected to, the unit's
    ``heartbeat`` and ``levels``, how it is rebooted (None: it is not), where ``reports``
    go (without suffix), and the ``rerun`` line."""
    s, unit, profile = settings, settings.unit, settings.profile
    declared = ", ".join(levels) or "none declared"
    where = str(s.broker) if not s.embedded else \
        f"embedded {broker} with the bundled reference unit" + (
            f" (faults: {', '.join(s.sim_faults)})" if s.sim_faults else "")
    safety = [f"role {unit.role}"]
    if unit.is_real:
        safety.append("motion tasks: " + (", ".join(profile.motion_tasks) or "none")
                      if s.allow_motion else "no task that moves the unit (no --allow-motion)")
    if s.dry_run:
        safety.append("DRY RUN: nothing is published")
    if "tst execution" in levels:
        safety.append(f"TST commands to {s.tst_topic}")
    return [
        f"waraps-conformance {__version__}: certifying {unit}",
        f"  broker:   {where}",
        f"  profile:  {profile.name} ({profile.source}), timing scale {s.timing_scale:g}",
        f"  unit:     agent-uuid {heartbeat.get('agent-uuid', '?')}, agent-type "
        f"{heartbeat.get('agent-type', '?')}, levels: {declared}",
        f"  reboot:   {reboot or 'none (REBOOT-* could not test)'}",
        f"  safety:   {'; '.join(safety)}",
        f"  reports:  {reports}.json / .html",
        f"  Using --seed={s.seed} (repeat this run: {rerun})",
    ]

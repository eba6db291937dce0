"""How a certification presents itself: the header of its pytest run (what is certified,
where, how safely, and the line that repeats it, seed included, as pytest-randomly
does: every run repeatable; the line itself is ``Settings.rerun_command``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from conformance import __version__
from conformance.client import BrokerURL
from conformance.profile import downgrades
from conformance.rules import reading
from conformance.scenarios.safety import SafetyDecision
from conformance.suite.settings import Settings
from conformance.topics import TST_EXECUTION


def header_lines(settings: Settings, *, broker: BrokerURL, heartbeat: dict[str, Any],
                 levels: list[str], reboot: str | None, reports: Path, rerun: str,
                 decision: SafetyDecision) -> list[str]:
    """The lines pytest shows before the tests: ``broker`` connected to, the unit's
    ``heartbeat`` and ``levels``, how it is rebooted (None: it is not), where ``reports``
    go (without suffix), and the ``rerun`` line."""
    s, unit, profile = settings, settings.unit, settings.profile
    declared = ", ".join(levels) or "none declared"
    where = str(s.broker) if not s.embedded else \
        ("virtual time: the in-memory broker double" if s.virtual else f"embedded {broker}") + \
        " with the bundled reference unit" + (
            f" (faults: {', '.join(s.sim_faults)})" if s.sim_faults else "") + (
            f" (variants: {', '.join(s.sim_variants)})" if s.sim_variants else "")
    safety = [decision.sentence()]
    downgraded = downgrades(profile)
    if downgraded:
        safety.append(f"the profile downgrades {downgraded} to warnings")
    if s.dry_run:
        safety.append("DRY RUN: nothing is published")
    if TST_EXECUTION in levels:
        safety.append(f"TST commands to {s.tst_topic}")
    return [
        f"waraps-conformance {__version__}: certifying {unit}",
        f"  broker:   {where}",
        f"  profile:  {profile.name} ({profile.source}), timing scale {s.timing_scale:g}",
        f"  rules:    {reading(profile.is_strict)}",
        f"  unit:     agent-uuid {heartbeat.get('agent-uuid', '?')}, agent-type "
        f"{heartbeat.get('agent-type', '?')}, levels: {declared}",
        f"  reboot:   {reboot or 'none (REBOOT-* could not test)'}",
        f"  safety:   {'; '.join(safety)}",
        f"  reports:  {reports}.json / .html",
        f"  Using --seed={s.seed} (repeat this run: {rerun})",
    ]


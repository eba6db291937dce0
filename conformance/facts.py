"""The run's facts: a typed record of what kind of run it was and how it went, the one input
besides the evidence that the judge (``conformance.judge``) reads.

Written by the run that knows them (the certification's ``suite/session.py``, lint's
``lint/runner.py``), carried in the report (``RunReport.facts``, the JSON's ``facts``), and
read only by the judge and the conclusion: never as strings in ``meta``.
"""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass, fields
from datetime import UTC, datetime
from typing import Any

CTRL_C = "Ctrl-C"
"""``RunFacts.cut_short`` of a run interrupted by the user (else what cut it: --max-duration)."""


class RunKind(enum.StrEnum):
    """What a run is. A ``StrEnum``: its members print and serialise as the words reports
    have always carried, and equal them."""

    CERTIFICATION = "certification"
    """One unit, observed and commanded by ``pytest --unit``."""
    LINT = "lint"
    """Traffic observed (live or recorded), never caused: ``waraps-conformance lint``."""


class Gate(enum.StrEnum):
    """Which rows decide lint's exit status (``lint --gate``)."""

    ALL = "all"
    """Every row: units and commanders."""
    UNITS = "units"
    """Only the units' rows (a fleet gate that commanders' faults do not fail)."""


GATES = tuple(gate.value for gate in Gate)


@dataclass(frozen=True)
class RunFacts:
    """What the judge must know of a run. Times are Unix seconds."""

    kind: RunKind = RunKind.CERTIFICATION
    unit: str = ""
    """A certification's unit under test (its address)."""
    strict: bool = False
    """Decided rules fail instead of warning (``--strict-rules``, ``strict: true``)."""
    gate: Gate = Gate.ALL
    """Lint: the rows that decide the exit status."""
    error: str = ""
    """The broker or the unit could not be reached: no rule ran."""
    broker_lost: float | None = None
    """When the broker was lost for good (it did not come back within the budget)."""
    interrupted: bool = False
    """Ctrl-C, or ``--max-duration`` reached (``cut_short`` says which)."""
    cut_short: str = ""
    selection: str = ""
    """The rules were selected (``-k 'HB-003'``, ``--rule=HB-003``), as typed, shell-quoted."""
    selected: tuple[str, ...] = ()
    """The rules the selection chose (empty: every rule)."""
    ran: tuple[str, ...] = ()
    """The rules whose tests ran (a certification that did not complete)."""
    enacted_pass: tuple[str, ...] = ()
    """Rules whose test was shown passing when it ran: one failing on the whole run failed on
    traffic that came after its test (``Conclusion.judged_after_test``)."""
    untimed: bool = False
    """Lint of a capture without arrival times (``mosquitto_sub -v``)."""
    unexplored: str = ""
    """Why a certification's exploration of command orders did not run (no time left): said
    beside the verdict, never a silent skip."""
    not_judged: str = ""
    """Lint: traffic of units past the bound on units was not judged (why, in words)."""
    not_examined: str = ""
    """Lint: lines of the recording that could not be read (why, in words): what they held
    was never examined, so the run is never clean."""

    def __post_init__(self) -> None:
        # A caller's plain words ("lint", "units") made the members (frozen: set once here).
        object.__setattr__(self, "kind", RunKind(self.kind))
        object.__setattr__(self, "gate", Gate(self.gate))

    @property
    def complete(self) -> bool:
        """A certification that ran every rule to the end: nothing selected, nothing cut."""
        return not (self.error or self.broker_lost is not None or self.interrupted
                    or self.selection)

    def reasons(self) -> list[str]:
        """Why the run is partial or not certified, in words (empty for a complete run)."""
        why = []
        if self.error:
            why.append(self.error.splitlines()[0])
        if self.broker_lost is not None:
            why.append(f"the broker was lost at {iso(self.broker_lost)} and did not come back")
        if self.interrupted:
            why.append(self.cut_short or CTRL_C)
        if self.selection:
            why.append(f"only the selected rules ran: {self.selection}")
        return why

    def not_run_reason(self) -> str:
        """Why a rule whose test never ran was not run."""
        if self.error:
            return f"not run: {self.error.splitlines()[0]}"
        if self.broker_lost is not None:
            return f"not run: the broker was lost at {iso(self.broker_lost)}"
        if self.cut_short in ("", CTRL_C):
            return f"not run: interrupted ({CTRL_C})"
        return f"not run: {self.cut_short}"

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for key in ("selected", "ran", "enacted_pass"):
            d[key] = list(d[key])
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RunFacts:
        """The facts a JSON report carries; unknown keys are ignored (a newer writer)."""
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        for key in ("selected", "ran", "enacted_pass"):
            kw[key] = tuple(str(x) for x in kw.get(key, ()))
        if kw.get("broker_lost") is not None:
            kw["broker_lost"] = float(kw["broker_lost"])
        return cls(**kw)


def iso(t: float) -> str:
    """ISO 8601 UTC to the millisecond, as every report writes times."""
    try:
        return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds")
    except (OverflowError, OSError, ValueError):
        return repr(t)

"""A failure found by exploration, told as a story: numbered steps, each command sent (its
JSON), what came back, and the step where the model and the unit disagree, with the rule,
its spec section and hint as every finding shows them (``render_violation``); stored as JSON so that
``--explore-replay FILE`` runs exactly those steps again.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from conformance.reporting.text import printable, render_violation
from conformance.rules import CATALOGUE
from conformance.scenarios.deviation import Kind
from conformance.scenarios.explore_action import (
    Action,
    Query,
    Resend,
    Signal,
    Start,
    Wait,
    from_json,
    is_teardown,
)
from conformance.scenarios.explore_steps import MAX_STEPS, Step, first_disagreement

FORMAT = "waraps-conformance explore story 1"
MAX_FILE = 2_000_000
"""Bytes of a stored story read at most (a story is a few kB)."""


class StoryError(ValueError):
    """A stored story that cannot be replayed (not one, unreadable, or from another unit)."""


def describe(action: Action) -> str:
    """A step in words: ``start-task look-at-bearing as T1``, ``signal-task $pause to T1``."""
    def task(slot: int | None) -> str:
        return f"T{slot + 1}" if slot is not None else "a task-uuid never used"
    if isinstance(action, Start):
        how = "" if action.task_uuid else ", no task-uuid (the unit makes one)"
        return f"start-task {action.task} as {task(action.slot)}{how}"
    if isinstance(action, Signal):
        why = " (teardown: every task started is aborted)" if action.teardown else ""
        return f"signal-task {action.signal} to {task(action.slot)}{why}"
    if isinstance(action, Query):
        return f"query-status of {task(action.slot)}"
    if isinstance(action, Resend):
        return f"resend the command of step {action.step + 1} (same com-uuid)"
    if isinstance(action, Wait):
        return f"wait {action.periods} heartbeat(s)"
    return action.do


@dataclass
class Story:
    """The steps of one failing example; ``failing`` indexes the step where they disagree."""

    steps: list[Step]
    failing: int
    seed: int
    shrunk: bool = False
    """Whether hypothesis finished shrinking it (else: the budget ran out first)."""
    found_after: float = 0.0
    """Seconds of exploration until the first failing example was found."""
    found_steps: int = 0
    """Steps run until then (all examples)."""
    first_length: int = 0
    """Steps of the first failing example (before shrinking)."""
    path: Path | None = field(default=None)

    @property
    def length(self) -> int:
        """Steps the story has, the teardown's aborts not counted."""
        return sum(1 for s in self.steps if not is_teardown(s.action))

    @property
    def rules(self) -> list[str]:
        """The rules broken, at any step (the teardown's too: a task that vanished shows
        when the example ends)."""
        return sorted({v.rule for step in self.steps for v in step.found})

    @classmethod
    def of(cls, steps: list[Step], seed: int) -> Story:
        """The story of an example's steps, failing where they first disagree."""
        return cls(list(steps), first_disagreement(steps), seed)

    def actions(self) -> list[Action]:
        """The steps to replay (the teardown is the explorer's own, run again anyway)."""
        return [s.action for s in self.steps if not is_teardown(s.action)]

    def render(self, unit: str, rerun: str, heading: str = "", brief: bool = False) -> str:
        """The story as a person reads it; ``brief``: its steps and the rules broken only
        (told while shrinking goes on: the whole story follows when it ends)."""
        lines = [heading or f"exploration: the unit and the model disagree at step "
                 f"{self.failing + 1} of {len(self.steps)} (seed {self.seed})"]
        for i, step in enumerate(self.steps):
            mark = "   <-- the model and the unit disagree here" if step.found else ""
            if brief and step.found:
                mark += f": {', '.join(sorted({v.rule for v in step.found}))}"
            lines.append(f"  {i + 1:>2}. {printable(describe(step.action))}{mark}")
            if brief:
                continue
            for text in step.sent:
                lines.append(f"      sent  {printable(text)}")
            for j, text in enumerate(step.came or ["(nothing)"]):
                lines.append(f"      {'came' if j == 0 else '':<4}  {printable(text)}")
        if brief:
            return "\n".join(lines)
        lines.append("")
        shown = set()
        for v in (v for step in self.steps for v in step.found):
            if v.rule in shown or v.rule not in CATALOGUE:
                continue
            shown.add(v.rule)
            lines.append(render_violation(v.rule, v, unit, rerun_hint=rerun))
        return "\n".join(lines)

    def to_json(self, unit: str, adapted: Sequence[str] = ()) -> dict[str, Any]:
        """``adapted``: the rules of the deviations the run had adapted to (``Kind``): its
        commands of a kind never answered waited a short deadline, and a replay does too."""
        return {"format": FORMAT, "unit": unit, "seed": self.seed, "shrunk": self.shrunk,
                "adapted": list(adapted),
                "failing_step": self.failing + 1, "rules": self.rules, "length": self.length,
                "found_after_s": round(self.found_after, 1), "found_steps": self.found_steps,
                "first_length": self.first_length,
                "steps": [s.to_json() for s in self.steps]}

    def save(self, path: Path, unit: str, adapted: Sequence[str] = ()) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.to_json(unit, adapted), indent=1), encoding="utf-8")
        tmp.replace(path)
        self.path = path
        return path


def load(path: Path) -> tuple[list[Action], dict[str, Any]]:
    """The actions of a stored story and the story itself; ``StoryError`` when it is none."""
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_FILE + 1)
        if len(raw) > MAX_FILE:
            raise ValueError(f"over {MAX_FILE} bytes")
        # orjson: no recursion over input, and no lone surrogate (a step's name is sent
        # in a command, which must be UTF-8: one once ended the replay in a TypeError).
        data = orjson.loads(raw)
    except (OSError, ValueError) as e:
        raise StoryError(f"{path}: not a readable story ({printable(str(e))[:200]})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT \
            or not isinstance(data.get("steps"), list):
        raise StoryError(f"{path}: not a story written by --explore (format {FORMAT!r})")
    if len(data["steps"]) > MAX_STEPS:  # bounded by its count, not only by --max-duration
        raise StoryError(f"{path}: {len(data['steps'])} steps; a story holds at most "
                         f"{MAX_STEPS}, the steps an example keeps")
    adapted = data.setdefault("adapted", [])  # absent in a story stored before it was kept
    if not isinstance(adapted, list) or len(adapted) > len(ADAPTABLE) \
            or any(type(rule) is not str or rule not in ADAPTABLE for rule in adapted):
        raise StoryError(f"{path}: 'adapted' lists the rules of the deviations the run adapted "
                         f"to, some of {', '.join(sorted(ADAPTABLE))}; it holds "
                         f"{printable(str(adapted))[:200]}")
    actions: list[Action] = []
    for number, step in enumerate(data["steps"], 1):
        action = step.get("action") if isinstance(step, dict) else None
        if not isinstance(action, dict) or type(action.get("do")) is not str \
                or action["do"] not in FIELDS:
            raise StoryError(f"{path}: a step that is not an exploration step: "
                             f"{printable(str(action))[:200]}")
        wrong = _wrong_field(action)
        if wrong:
            raise StoryError(f"{path}: step {number} ({action['do']}): {wrong}")
        if not action.get("teardown"):
            actions.append(from_json(action))
    return actions, data


ADAPTABLE = frozenset(kind.rule for kind in Kind)
"""What a stored story's ``adapted`` may hold."""

_KINDS = {
    "name": (lambda v: type(v) is str and bool(v), "a name"),
    "count": (lambda v: type(v) is int and v >= 0, "a whole number from 0"),
    "slot": (lambda v: v is None or type(v) is int and v >= 0,
             "a slot: a whole number from 0 (the n-th start-task), or null"),
    "flag": (lambda v: type(v) is bool, "true or false"),
}
FIELDS: dict[str, dict[str, tuple[bool, str]]] = {
    "start": {"task": (True, "name"), "slot": (False, "slot"), "task_uuid": (False, "flag")},
    "signal": {"signal": (True, "name"), "slot": (False, "slot")},
    "query": {"slot": (False, "slot")},
    "resend": {"step": (True, "count")},
    "ping": {},
    "wait": {"periods": (False, "count")},
}
"""Each kind of step: its fields, whether each is needed, and the kind of value it holds (what
the explorer reads, ``explore_steps.Explorer``; every step may say 'teardown'). A stored story
is checked when it is loaded, so a wrong one is one line, never a traceback."""


def _wrong_field(action: dict[str, Any]) -> str:
    """What is wrong with a step's fields, or ''."""
    for key, (needed, kind) in [*FIELDS[action["do"]].items(), ("teardown", (False, "flag"))]:
        holds, what = _KINDS[kind]
        if key not in action:
            if needed:
                return f"'{key}' is missing ({what})"
        elif not holds(action[key]):
            return f"'{key}' is {printable(repr(action[key]))[:80]}, not {what}"
    return ""

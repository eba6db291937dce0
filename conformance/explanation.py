"""One message (or a TST plan) validated and explained to a person: its kind, every
violation as every output shows it (``render_violation``), and the verdict under a profile. What
``waraps-conformance validate`` prints (its command line: ``conformance.cli.validate``)."""

from __future__ import annotations

import dataclasses
from typing import Any

import orjson

from conformance import profile as profile_module
from conformance.display import printable, shorten
from conformance.judge import violation_verdict
from conformance.rules import CATALOGUE, get
from conformance.validator import Validation, Validator
from conformance.violation import Verdict

# 3: PREFIX/unit/AGENT-TYPE/ROLE/NAME/<subtopic> (a leading '/' is placed, and judged TOPIC-001).
FORMS = ("<prefix>/unit/<agent-type>/<role>/<name>/heartbeat",
         "<prefix>/unit/<agent-type>/<role>/<name>/sensor_info",
         "<prefix>/unit/<agent-type>/<role>/<name>/direct_execution_info",
         "<prefix>/unit/<agent-type>/<role>/<name>/tst_execution_info",
         "<prefix>/unit/<agent-type>/<role>/<name>/sensor/<sensor>",
         "<prefix>/unit/<agent-type>/<role>/<name>/exec/command|response|feedback",
         "<prefix>/unit/<agent-type>/<role>/<name>/tst/command|response|feedback")


def unplaceable(topic: str) -> str:
    """Why ``topic`` is refused: it names no unit, so no message kind can be judged."""
    forms = "\n".join(f"  {f}" for f in FORMS)
    return (f"waraps-conformance validate: cannot place topic {printable(repr(topic))}: it is "
            f"not under "
            f"a unit's address (spec 3). Accepted forms, e.g. "
            f"waraps/unit/air/simulation/dji0/heartbeat:\n{forms}")


def render(validation: Validation, profile: profile_module.Profile) -> str:
    """The kind, then each violation as every output shows it, then a one-line verdict."""
    # What the message holds is shown escaped: topic, paths, values.
    lines = [f"topic     {printable(validation.topic.topic)}", f"kind      {validation.kind}"]
    for v in validation.violations:
        rule = CATALOGUE.get(v.rule)
        judged = verdict_of(v.rule, profile, v.condition)
        title = rule.title if rule else ""
        lines.append("")
        lines.append(f"{v.rule} {title}".ljust(72) + f" [{judged.value}]")
        if v.path:
            lines.append(f"  path      {printable(shorten(v.path))}")
        lines.append(f"  expected  {printable(shorten(v.expected))}")
        lines.append(f"  observed  {printable(shorten(v.observed))}")
        if v.detail:
            lines.append(f"  detail    {printable(shorten(v.detail))}")
        if rule:
            lines.append(f"  spec      {rule.section}")
    lines.append("")
    lines.append(f"verdict   {overall_verdict(validation, profile).value} "
                 f"({len(validation.violations)} violation"
                 f"{'' if len(validation.violations) == 1 else 's'}, profile {profile.name})")
    return "\n".join(lines)


TST_TOPIC = "waraps/unit/ground/real/op0/tst/command"
"""Where a plan checked with --tst is judged as if sent (14.1: 'usually sent to op0')."""
_PLACEHOLDER_COM_UUID = "00000000-0000-4000-8000-000000000000"


def validate_tst(validator: Validator, payload: bytes) -> Validation:
    """A TST plan: a start-tst command, or a bare tree wrapped into one; the violations of a
    bare tree carry paths into the tree as written (``$.children[0].params``)."""
    try:
        message = orjson.loads(payload)
    except orjson.JSONDecodeError:
        message = None
    if not (isinstance(message, dict) and "command" not in message and "name" in message):
        return validator.validate(TST_TOPIC, payload)
    wrapped = {"com-uuid": _PLACEHOLDER_COM_UUID, "command": "start-tst", "tst": message}
    validation = validator.validate(TST_TOPIC, orjson.dumps(wrapped))
    moved = tuple(dataclasses.replace(v, path="$" + v.path[len("$.tst"):],
                                      expected=v.expected.replace("$.tst", "$"))
                  if v.path.startswith("$.tst") else v for v in validation.violations)
    return validation._replace(kind="tst (a tree)", message=message, violations=moved)


def verdict_of(rule_id: str, profile: profile_module.Profile, condition: str = "") -> Verdict:
    """The verdict a violation of ``rule_id`` (finding ``condition``) earns under ``profile``
    (the judge's)."""
    return violation_verdict(get(rule_id), profile.severity_of(rule_id),
                             strict=profile.adopts(rule_id), condition=condition)


def overall_verdict(validation: Validation, profile: profile_module.Profile) -> Verdict:
    """The message's verdict: its worst violation's; a message past MSG-004's bounds was not
    examined whole, so at best could-not-test, never a pass or a warn."""
    worst = Verdict.worst([verdict_of(v.rule, profile, v.condition)
                           for v in validation.violations])
    if worst is not Verdict.FAIL and any(v.rule == "MSG-004" for v in validation.violations):
        return Verdict.COULD_NOT_TEST
    return worst


def to_dict(validation: Validation, profile: profile_module.Profile) -> dict[str, Any]:
    """The validation as ``validate --json`` prints it."""
    return {
        "topic": validation.topic.topic, "kind": validation.kind,
        "verdict": overall_verdict(validation, profile).value,
        "violations": [dict(v.to_dict(), verdict=verdict_of(v.rule, profile, v.condition).value)
                       for v in validation.violations],
    }

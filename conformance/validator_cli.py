"""``waraps-conformance validate TOPIC [FILE|-]``: validate one message and say why, for a person.

    waraps-conformance validate waraps/unit/air/simulation/dji0/heartbeat hb.json
    mosquitto_sub -t '.../heartbeat' -C 1 | waraps-conformance validate .../heartbeat -
    waraps-conformance validate --tst plan.json

``--tst`` checks a TST plan before it is sent: the file holds a start-tst command or just its
tree (the ``tst`` node object); every problem of the tree is listed with its JSON path in the
file (schemas, task parameters, structure: TST-001, TASK-*, TST-014, ERR-*).

Exit code: 0 when nothing fails under the profile (warnings allowed), 1 when a rule fails,
2 for a usage error (also a topic it cannot place: it says which forms it accepts).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time as time_module
from pathlib import Path

import orjson

from conformance import profile as profile_module
from conformance.rules import CATALOGUE, Severity
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
    return (f"waraps-conformance validate: cannot place topic {topic!r}: it is not under "
            f"a unit's address (spec 3). Accepted forms, e.g. "
            f"waraps/unit/air/simulation/dji0/heartbeat:\n{forms}")


def render(validation: Validation, profile: profile_module.Profile) -> str:
    """The kind, then each violation as the STYLE guide shows it, then a one-line verdict."""
    lines = [f"topic     {validation.topic.topic}", f"kind      {validation.kind}"]
    for v in validation.violations:
        rule = CATALOGUE.get(v.rule)
        verdict = _verdict(v.rule, profile)
        title = rule.title if rule else ""
        lines.append("")
        lines.append(f"{v.rule} {title}".ljust(72) + f" [{verdict.value}]")
        if v.path:
            lines.append(f"  path      {v.path}")
        lines.append(f"  expected  {v.expected}")
        lines.append(f"  observed  {v.observed}")
        if v.detail:
            lines.append(f"  detail    {v.detail}")
        if rule:
            lines.append(f"  spec      {rule.section}")
    lines.append("")
    lines.append(f"verdict   {_overall(validation, profile).value} "
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


def _verdict(rule_id: str, profile: profile_module.Profile) -> Verdict:
    return Verdict.FAIL if profile.severity_of(rule_id) is Severity.ERROR else Verdict.WARN


def _overall(validation: Validation, profile: profile_module.Profile) -> Verdict:
    return Verdict.worst([_verdict(v.rule, profile) for v in validation.violations])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="waraps-conformance validate",
        description="Validate one WARA-PS message: print its kind and every violation.")
    parser.add_argument("topic", nargs="?", default=None,
                        help="the MQTT topic, e.g. waraps/unit/air/simulation/dji0/heartbeat "
                             "(not with --tst)")
    parser.add_argument("file", nargs="?", default="-",
                        help="file with the raw payload, or - for standard input (default)")
    parser.add_argument("--tst", action="store_true",
                        help="the file is a TST plan: a start-tst command or its tree; list "
                             "every problem of the tree with its JSON path")
    parser.add_argument("--profile", default="default",
                        help="built-in profile name or YAML file (default: default)")
    when = parser.add_mutually_exclusive_group()
    when.add_argument("--time", type=float, default=None,
                      help="arrival time (Unix seconds) to judge the stamp against (MSG-005)")
    when.add_argument("--now", action="store_true",
                      help="judge the stamp against the current time (a message just captured)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    args = parser.parse_args(argv)
    if args.tst:
        if args.topic is not None and args.file != "-":
            parser.error("--tst takes one FILE (or -), no topic")
        args.file = args.topic if args.topic is not None else args.file
    elif args.topic is None:
        parser.error("a TOPIC is needed (or --tst FILE for a TST plan)")
    try:
        profile = profile_module.load(args.profile)
    except profile_module.ProfileError as e:
        print(f"waraps-conformance validate: {e}", file=sys.stderr)
        return 2
    try:
        payload = sys.stdin.buffer.read() if args.file == "-" else Path(args.file).read_bytes()
    except OSError as e:
        print(f"waraps-conformance validate: cannot read {args.file}: {e.strerror}",
              file=sys.stderr)
        return 2
    arrival = time_module.time() if args.now else args.time
    if args.tst:
        validation = validate_tst(Validator(profile), payload)
    else:
        validation = Validator(profile).validate(args.topic, payload, arrival)
        if validation.topic.unit is None:
            print(unplaceable(args.topic), file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps({
            "topic": validation.topic.topic, "kind": validation.kind,
            "verdict": _overall(validation, profile).value,
            "violations": [dict(v.to_dict(), verdict=_verdict(v.rule, profile).value)
                           for v in validation.violations],
        }, indent=2))
    else:
        print(render(validation, profile))
    return 1 if _overall(validation, profile) is Verdict.FAIL else 0


if __name__ == "__main__":
    sys.exit(main())

"""``waraps-conformance rules``: print the rule catalogue (id, severity, mode, side, section,
title)."""

from __future__ import annotations

import json

from conformance import profile as profiles
from conformance.cli import options as opts
from conformance.rules import CATALOGUE


def main(argv: list[str]) -> int:
    parser = opts.parser("rules", "Print the rule catalogue.")
    parser.add_argument("--format", choices=("text", "json"), default="text")
    opts.add_profile_option(parser)  # the severities as this profile sets them (e.g. strict)
    parser.add_argument("--errata", action="store_true", help="only the spec's errata, with "
                        "the decision taken on each")
    args = parser.parse_args(argv)
    try:
        profile = profiles.load(args.profile)
    except profiles.ProfileError as e:
        parser.error(str(e))
    rules = [r for r in CATALOGUE.values() if r.is_erratum or not args.errata]
    if args.format == "json":
        print(json.dumps([{"id": r.id, "title": r.title, "section": r.section,
                           "severity": profile.severity_of(r.id).value, "level": r.level.value,
                           "mode": r.mode.value, "side": r.side.value,
                           "decision": r.decision} for r in rules],
                         indent=2))
        return 0
    w = max(len(r.id) for r in rules)
    for r in rules:
        print(f"{r.id:<{w}}  {profile.severity_of(r.id).value:<7}  {r.mode.value:<12}  "
              f"{r.side.value:<9}  {r.section:<32.32}  {r.title}")
        if args.errata and r.decision:
            print(f"{'':<{w}}  decision: {r.decision}\n")
    return 0

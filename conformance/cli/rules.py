"""``waraps-conformance rules``: print the rule catalogue (id, severity, mode, side, basis,
section, title; with ``--basis`` what each stands on, condition by condition: its quote or its
decision)."""

from __future__ import annotations

import json

from conformance import profile as profiles
from conformance.cli import options as opts
from conformance.display import printable
from conformance.rules import CATALOGUE, basis_counts, condition_counts


def main(argv: list[str]) -> int:
    parser = opts.parser("rules", "Print the rule catalogue.")
    parser.add_argument("--format", choices=("text", "json"), default="text")
    opts.add_profile_option(parser)  # the severities as this profile sets them (e.g. strict)
    parser.add_argument("--errata", action="store_true", help="only the spec's errata, with "
                        "the decision taken on each")
    parser.add_argument("--basis", action="store_true", help="what each rule stands on: the "
                        "spec's words (stated, implied: and why) or this suite's decision")
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
                           "basis": r.basis.value, "quote": r.quote, "because": r.because,
                           "decision": r.decision, "note": r.note,
                           "conditions": [{"id": c.id, "title": c.title, "basis": c.basis.value,
                                           "quote": c.quote, "because": c.because,
                                           "decision": c.decision} for c in r.conditions]}
                          for r in rules],
                         indent=2))
        return 0
    w = max(len(r.id) for r in rules)
    for r in rules:
        print(f"{r.id:<{w}}  {profile.severity_of(r.id).value:<7}  {r.mode.value:<12}  "
              f"{r.side.value:<9}  {r.basis.value:<7}  {r.section:<32.32}  {r.title}")
        if args.basis:
            # Each condition with its own basis: the rule's words, then what the suite added.
            print(printable(f"{'':<{w}}  {r.basis_text()}"))
            for c in r.conditions:
                print(printable(f"{'':<{w}}  condition '{c.id}' ({c.title}): {c.basis_text()}"))
            print()
        elif args.errata and r.decision:
            print(f"{'':<{w}}  decision: {r.decision}\n")
    counts, conditions = basis_counts(), condition_counts()
    print(f"\n{len(CATALOGUE)} rules: {counts['stated']} stated, {counts['implied']} implied, "
          f"{counts['decided']} decided (decided rules warn as interop risks unless the run is "
          f"strict: pytest --strict-rules, lint --strict, or strict: true in the profile)")
    print(f"{sum(conditions.values())} conditions (each rule's own words and the conditions "
          f"the suite added to them): {conditions['stated']} stated, {conditions['implied']} "
          f"implied, {conditions['decided']} decided; a finding is judged on its condition's "
          f"basis (--basis lists them)")
    return 0

"""The exit statuses of a certification (README 'Exit status'); pytest's own keep their
meaning. Their one home: the verdict model (``conclusion.py``) and the plugin read them here,
and the plugin stays cheap to import."""

EXIT_CERTIFIED, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_NOT_CERTIFIED = 0, 1, 2, 6

EXIT_LINT_PARTIAL = 4
"""Lint: no row fails, but part of the evidence could not be examined (lines malformed,
payloads past MSG-004's bounds): never clean (README 'Bounds')."""
EXIT_UNTESTED = 7
"""A complete run in which no rule failed, yet a level the unit claims is not certified: a
rule it needs could not be tested (no --reboot-cmd, a real unit without --allow-motion or
--allow-hostile, a task without parameters). A gate that reads 0 as "certified" must not
admit it."""

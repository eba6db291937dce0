"""The packaged conformance suite that ``pytest --unit ADDRESS`` collects.

``test_execution.py`` holds the active scenarios (one test per rule id, e.g.
``test_ping[EXEC-PING-001]``), ``test_passive.py`` one test per passive rule
(``test_rule[HB-003]``), judged at the end over the whole observation. ``session.py`` is the
run's state, ``settings.py`` its options, ``verdict.py`` maps verdicts onto pytest outcomes.
"""

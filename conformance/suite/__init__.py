"""The packaged conformance suite that ``pytest --unit ADDRESS`` collects.

``test_execution.py`` holds the active scenarios (one test per rule id, e.g.
``test_ping[EXEC-PING-001]``), ``test_passive.py`` one test per passive rule
(``test_rule[HB-003]``), judged at the end over the whole observation. ``session.py`` is the
run's state (``Certification``), with its parts: ``connection.py`` (broker, publish policy,
first heartbeat; ``probe.py`` says why a unit is not alive), ``observation.py`` (waits in the
unit's periods: death, the passive window), ``reboot.py``, ``outcome.py`` (the verdict and
the rules not run), ``header.py`` (the header), ``events.py`` (the
summary's events). ``settings.py`` is its options, ``verdict.py`` maps verdicts onto pytest
outcomes, ``progress.py`` shows the waits.
"""

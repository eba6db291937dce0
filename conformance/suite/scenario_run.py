"""Running the active scenarios of one certification (``Certification.run_scenario``): each
once, after the scenarios it works on, ping first as the gate of direct execution (12.1); not
at all against a dead unit (HB-012 is the finding) or for a level the unit does not claim
(5.1). What stops a scenario that is not the unit's doing (--dry-run, the publish policy, a
lost broker, --max-duration) makes its rules could-not-test, never failed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from conformance.client import BrokerError
from conformance.scenarios import SCENARIOS, NotSent, Scenario
from conformance.scenarios.traffic import OutOfTime
from conformance.suite.evidence import outage
from conformance.topics import DIRECT_EXECUTION
from conformance.violation import Observed, Verdict

if TYPE_CHECKING:
    from conformance.suite.session import Certification


def run_scenario(c: Certification, name: str) -> None:
    """Run scenario ``name`` once (later calls return at once), after what it needs; its
    tasks are aborted when it ends, and the reports written."""
    if name in c.evidence.scenarios_done:
        return
    scenario = SCENARIOS[name]
    c.check_broker(scenario.rules)
    for needed in scenario.needs:
        run_scenario(c, needed)
    if name != "reboot":  # the reboot scenario brings a dead unit back itself
        revive(c, name)
    why_not = _why_not_run(c, name, scenario)
    if why_not is not None:
        for rule in scenario.rules if why_not else ():  # "": not claimed, the Monitor's reason
            c.record(rule, seen=Observed.UNTESTABLE, reason=why_not)
        c.evidence.scenarios_done[name] = False
        return
    try:
        scenario.run(c.context)
    except NotSent as e:
        # --dry-run, or the publish policy refused it (docs/ARCHITECTURE.md 'Safety')
        for rule in scenario.rules:
            c.record(rule, seen=Observed.UNTESTABLE, reason=str(e))
    except OutOfTime as e:
        c.out_of_time_reached(e)
    except BrokerError as e:
        # The link went down under a publish: the broker's fault, never the unit's.
        lost = c.connection.lost_since() or c.traffic.clock.now()
        for rule in scenario.rules:
            c.record(rule, seen=Observed.UNTESTABLE, reason=f"{outage(lost)} ({e})")
    finally:
        c.evidence.scenarios_done[name] = True
        # Into a lost link an $abort would be lost too: the teardown sends it (finish).
        # What ignored an $abort before is left to the last teardown (i20 6).
        if not c.settings.dry_run and c.connection.is_connected:
            aborted = c.commander.abort_all(c.timing.response, stuck=False)
            aborted += c.tst.abort_all(c.timing.response, stuck=False)
            if aborted and c.out_of_time:
                c.say_aborted(aborted)
        c.reports.write()
    c.fail_if_out_of_time()


MAX_REVIVES = 3
"""Restarts of a dead unit per run at most: one that dies on every scenario is not restarted
for each (every restart waits up to the profile's reboot_timeout)."""


def revive(c: Certification, name: str) -> None:
    """A unit that died (HB-012: its death is the finding, and stays one) is restarted by the
    run's reboot (``--reboot-cmd``) before scenario ``name``, so that the scenarios left are
    still judged rather than could-not-test; said on the terminal and in the summary."""
    if c.context.reboot is None or c.settings.dry_run or c.revived >= MAX_REVIVES:
        return
    if c.connection.lost_since() is not None or c.connection.away_since() is not None:
        return  # not heard since the broker's outage: its silence is the broker's, not death
    died = c.unit_died()
    if not died:
        return
    c.revived += 1
    how, clock = c.reboot.how(), c.traffic.clock
    c.announce(f"the unit died before the {name} scenario ({died}); restarting it with {how} "
               f"and carrying on")
    mark, began = c.traffic.mark(), clock.now()
    names = c.reboot.watch_names()  # an agent may come back under another name (REBOOT-001)
    try:
        failure = c.context.reboot()
        back = None if failure is not None else c.traffic.wait_for(
            lambda e: True, c.timing.reboot, after=mark, subtopic="heartbeat",
            what="the unit's heartbeat after its restart")
        renamed = names.new_name(set(), began, 0.0) if back is None else None
    finally:
        names.close()
    if back is not None:
        # 12.1: a restart loses the history of commands; the tasks that ended before it are
        # not asked about (query-status, REBOOT-002): the scenarios after it end their own.
        c.context.notes.pop("ended", None)
        c.announce(f"the unit is back {back.time - began:.1f} s after its restart; its "
                   f"death stays HB-012's finding")
    else:
        c.announce(f"restarted with {how}, " + (f"which failed: {failure}" if failure else
                   f"but no heartbeat within {c.timing.reboot:.0f} s") + (
                   f"; a unit of its type and role first heard since: '{renamed}' (the unit "
                   f"back under another name? the suite follows only {c.unit.name!r})"
                   if renamed else ""))


def _why_not_run(c: Certification, name: str, scenario: Scenario) -> str | None:
    """Why the scenario does not run (its rules' could-not-test reason; "" for a level the
    unit does not claim: every rule of it is skipped, the Monitor's reason), or None when it
    runs (then its level's info message has been awaited)."""
    if scenario.level is not None and not c.claims(scenario.level):
        return ""  # not claimed (5.1), whether the unit lives or died
    silent = c.unit_died() if name != "reboot" else ""
    if silent:
        # A dead unit answers nothing: each wait would only run out (HB-012 is the
        # finding). The reboot scenario may bring it back, so it still runs.
        return silent
    if scenario.level is None:
        return None
    # Ping gates the other direct-execution scenarios, except robustness, whose rule asks
    # exactly whether the unit still pings.
    if name not in ("ping", "robust") and scenario.level == DIRECT_EXECUTION:
        run_scenario(c, "ping")
        deaf = _answers_none(c)
        if deaf:
            return deaf
    c.observation.wait_execution_info()
    return None


def _answers_none(c: Certification) -> str:
    """Why the unit answers no command at all, or "": ping unanswered, then each other kind
    probed on its own (``Commander.answers_none``)."""
    if c.settings.dry_run:
        return ""  # nothing was sent: let every scenario say what it would send
    if c.result("EXEC-PING-001").verdict is not Verdict.FAIL or \
            c.traffic.since(0, "exec/response"):
        return ""
    return c.commander.answers_none(c.timing.response)

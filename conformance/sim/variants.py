"""Variant switches of the reference unit: conformant-but-different behaviours, the mirror of
its faults (``conformance.sim.faults``).

A fault breaks the rules it names; a variant breaks none. Each one is a reading of the spec
that a real unit may take (section cited), and the suite must certify it: with a variant on,
a certification fails no rule, and warns only on ``warns``, the errata the catalogue accepts
with a warning (``rules --errata``) and the suite's decided rules (``rules --basis``). Where a variant is failed anyway, the check or the
scenario that fails it makes a false accusation. Variants combine freely, but for those in
``CONFLICTS`` (one sends what the other leaves out).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from conformance.rules import CATALOGUE, Severity
from conformance.sim.faults import switches


@dataclass(frozen=True)
class Variant:
    """A variant switch: its name, the spec sections that allow it, what it does, and the
    rules it makes warn (errata readings the catalogue accepts with a warning, decided rules
    it reads otherwise)."""

    name: str
    section: str
    description: str
    warns: tuple[str, ...] = ()


# Readings of a unit written from the spec alone: it accepts a signal in 12.1's words, keeps a
# ground unit's pace, and lists per task only the signals it understands (5.3).
_READINGS = (
    Variant("signal-running", "12.1 (response values 'running, failed, finished'); 12.3.2 "
            "(the signal-task response) is empty",
            "Answers a signal it accepts 'running', in 12.1's words, not 'ok'; a refusal is "
            "'failed' as before."),
    Variant("slow-answers", "12.1; the profile's response_timeout (5 s by default)",
            "Answers each command 1-3 s after it came (SLOW_ANSWERS, drawn per answer, never "
            "overtaking one held before), as a ground unit at 0.5 Hz did; its feedback is not "
            "held, so what a command causes may be told before its answer (12: no order "
            "between topics)."),
    Variant("two-signals", "5.3 ('for each task a list of signals it understands')",
            "Lists only $abort and $enough for its look-at tasks (9.2-9.4 end on $enough), and "
            "refuses any other signal to them, in direct execution and as TST leaves."),
    Variant("real-speed", "12.4 (feedback until the end; how long a task takes is not said)",
            "Runs its tasks at their real speeds, without the time compression of the plain "
            "unit: a move of a hundred metres takes over ten seconds at its qualitative speed "
            "(8 m/s standard in the air), where the plain unit takes 3 s (REAL_SPEED_SECONDS), "
            "as a unit written elsewhere did; a move of a few metres still ends in seconds."),
)

_ALL = _READINGS + (
    Variant("strict", "10, 11, 12.2, 14.3",
            "Refuses ('failed', with a fail-reason) any command the spec's examples do not "
            "show: a field none of 12.2/10/11/14.3's examples has; a start-task without "
            "execution-unit, sender or task {name, params} (10's examples; task-uuid may be "
            "left out, 12.1); a TST node without name, params, children and common_params "
            "{execunit, node-uuid} (every node of 11's examples); a unit named otherwise than "
            "'/NAME' (11's execunit, 14.3.3's unit)."),
    Variant("terse", "5, 12.3, 12.4, 14.4, 14.5; schemas/messages",
            "Sends no optional field: fail-reason only when a response is 'failed', task-uuid "
            "only in start-task responses (12.3.3); TST feedback without fail-reason and "
            "root-flag, tst_execution_info without nodes-executing; lists and publishes only "
            "the four mandatory sensors (6.1), no camera_url."),
    Variant("verbose", "2, 12.3, 12.4",
            "Adds fields of its own to every message (a vendor 'x-software' object) and puts "
            "fail-reason and task-uuid on every exec response (the task-uuid of the task the "
            "command concerns; '' in a pong or an answer to a command that names no task)."),
    Variant("slow", "12.1; the profile's response_timeout and feedback_timeout",
            "Holds every response and feedback back for SLOW_PERIODS heartbeat periods (0.4 s "
            "at 2 Hz, inside the 1 s of the shortest self-test response_timeout; 5 s at 1 Hz "
            "is the default profile's), in the order they were made."),
    Variant("key-order", "RFC 8259 4 (an object is unordered); 2",
            "Writes every JSON object's keys in reverse alphabetical order (the spec's "
            "examples sort them)."),
    Variant("success-vocabulary", "12.1",
            "Answers query-status in 12.1's own words only (running, failed, success, "
            "unknown): a finished task 'success', a paused one 'running', an aborted one "
            "'failed'.",
            warns=("ERR-006",)),
    Variant("sensor-rate-edge", "5.2, 6; the profile's rate_tolerance",
            "Sends sensor_info and its sensors EDGE slower than the declared rate (12 %: "
            "inside the default 20 % rate tolerance, not past it); camera_url every second "
            "such period (still inside SI-003's window of three)."),
    Variant("starting-feedback", "12.4",
            "Reports a started task 'starting' (12.4's list) before 'running'."),
    Variant("announce-nodes", "14.5 (not-active, the first status it lists)",
            "Reports every node of a tree it starts 'not-active' before it activates the "
            "root (a unit written elsewhere): a seq's later children say so "
            "while the first runs, and are not listed in nodes-executing until they start."),
    Variant("periodic-feedback", "12.4 ('Update of the status of the task': how often is not "
            "said)",
            "With every heartbeat, sends each running or paused task's status again, as a "
            "periodic report (a unit written elsewhere)."),
    Variant("silent-start", "12.3.3, 12.4 (feedback is an 'Update of the status')",
            "Sends no feedback for a task it starts: its start-task answer says 'running', and "
            "feedback follows only changes ($pause, the end; a unit written elsewhere, issue "
            "24)."),
    Variant("feedback-first", "12.3, 12.4 (no order between topics)",
            "Publishes the feedback a command causes before the command's response: a "
            "started task's 'running' before the start-task's answer, a signal's effect "
            "('paused', 'aborted', ...) before the signal's 'ok'."),
    Variant("info-rates", "5, 5.2, 5.3",
            "Sends sensor_info, direct_execution_info and tst_execution_info at half the "
            "heartbeat's rate, each declaring its own rate (5: 'info messages may come at a "
            "lower rate than the heartbeat')."),
    Variant("retained-info", "5, 5.2, 5.3 (MQTT retain is not ruled out)",
            "Publishes sensor_info, direct_execution_info and tst_execution_info retained, so "
            "a subscriber that joins late has them at once (the heartbeat is not retained)."),
    Variant("pretty-json", "RFC 8259 2 (insignificant whitespace)",
            "Writes every message indented over several lines, as json.dumps(indent=2) does."),
    Variant("integer-numbers", "RFC 8259 6; 5.1, 6.1",
            "Writes whole numbers without a fraction (rate 2, heading 270, speed 0), as "
            "JavaScript and many C++ JSON writers do."),
    Variant("rate-edge", "5.1, 5.3; the profile's rate_tolerance",
            "Sends its heartbeat, direct_execution_info and tst_execution_info EDGE faster "
            "than their declared rate (12 %: inside the default 20 % tolerance)."),
    Variant("level-spelling", "5.1",
            "Declares its level 'direct_execution' (5.1's prose spelling; ERR-008).",
            warns=("ERR-008",)),
    Variant("own-task", "5.3 (tasks-available may hold tasks beyond section 9)",
            "Also offers 'go-home', a task of its own that section 9 does not define: it "
            "needs a numeric 'speed' (as the public agents' go-home does), refuses a start "
            "without one ('failed', with a fail-reason) and, started, runs for a second."),
    Variant("geopoint-type", "6.1",
            "Tags its position \"type\": \"GeoPoint\" instead of rostype: 6.1 says only "
            "'GeoPoint' and has no example of sensor/position (ERR-010 is for task "
            "parameters, whose examples tag rostype)."),
    # Behaviours of public agents certified live (docs/FIELD-NOTES.md 'Real agents certified live').
    Variant("silent-unknown-command", "12.1 (four commands; nothing said of any other)",
            "Answers no command whose 'command' is a string other than 12.1's four (the "
            "official agents dispatch on the four names and drop the rest); malformed "
            "commands and the four are answered as before.",
            warns=("EXEC-ROBUST-002",)),
    Variant("respawn", "5, 5.1 (a reboot loses state; nothing ties a position across it)",
            "Comes back from a reboot at a new spawn point, RESPAWN_METRES from where it was "
            "(a restarted simulated agent draws a new random start), with its new agent-uuid."),
    Variant("late-subscriber", "2, 12.1 ('If a response is not arriving re-send the command "
            "with the same com-uuid')",
            "Loses the first command sent to it: it heartbeats before its subscription to "
            "exec/command is in place (as an independently written unit did); the commander's "
            "resend is answered."),
    Variant("resend-refused", "12.1 (resend 'until we give up or a response has arrived'; "
            "nothing says what the second answer says)",
            "Takes a resent start-task for a new one and refuses it: 'failed', 'A task is "
            "already running' (the official Python agents), with no feedback; the task it "
            "started runs on, never executed twice. The 'failed' contradicts the first "
            "answer while the task runs: EXEC-RESEND-003, a decided rule, warns.",
            warns=("EXEC-RESEND-003",)),
    Variant("signed-heading", "6.1 ('heading : float', no range)",
            "Publishes heading in (-180, 180] (atan2's range); it faces west at start, so "
            "its heading is negative.",
            warns=("SENS-002",)),
    # Readings of units written elsewhere from the spec alone (a separate block: one entry
    # each, so that other additions above merge cleanly).
    Variant("mqtt5-qos1", "2 (MQTT; neither the protocol version nor a QoS is said)",
            "Connects with MQTT 5 and publishes every message at QoS 1 (on a real broker; the "
            "embedded amqtt broker refuses MQTT 5, the virtual double carries the QoS only)."),
    Variant("both-sensor-info", "3.1 (sensor_info), 5.2 ('TOPIC: UNIT/sensor.info')",
            "Publishes its SensorInfo on both of the spec's spellings, each at the declared "
            "rate: two streams, not one at twice the rate.",
            warns=("ERR-001",)),
    Variant("preparing-status", "12.4 ('task specific strings')",
            "Reports a started task 'preparing', a status of its own, for PREPARING_SECONDS "
            "(its answer already said 'running'), then 'running'.",
            warns=("EXEC-FB-002",)),
    Variant("paused-not-executing", "5.3 ('List of tasks currently executing')",
            "Leaves a paused task out of tasks-executing while it is paused (it is not "
            "executing), and lists it again once continued."),
    Variant("reboot-away", "5, 5.1 (how long a reboot takes is not said)",
            "Is away REBOOT_AWAY seconds on a reboot (4 s, where the plain unit is away 2.5 "
            "heartbeat periods), then comes back with its new agent-uuid."),
)

VARIANTS: dict[str, Variant] = {v.name: v for v in _ALL}
CONFLICTS = (frozenset({"terse", "verbose"}), frozenset({"silent-start", "starting-feedback"}),
             frozenset({"silent-start", "preparing-status"}))
"""Variants that cannot be on together (one sends what the other leaves out)."""
INFO_SLOWER = 2.0
"""Variant info-rates: the info messages run at the heartbeat's rate divided by this."""
SLOW_PERIODS = 0.8
"""Variant slow: answers and feedback are held back this many periods. The shortest
response_timeout a profile of this project gives is 2 periods (tests' matrix.yaml: 1 s at 2 Hz;
the default profile's is 5 s at 1 Hz): 0.8 periods stays under half of every one
(tests/sim/test_variants.py checks each profile), leaving the rest to a loaded machine."""
PREPARING_SECONDS = 1.0
"""Variant preparing-status: how long a started task says 'preparing' before 'running'."""
REBOOT_AWAY = 4.0
"""Variant reboot-away: seconds a rebooted unit is away (8 heartbeat periods at the matrix's
2 Hz, where the plain unit is away 2.5 periods: REBOOT_SILENCE)."""
SLOW_ANSWERS = (1.0, 3.0)
"""Variant slow-answers: the shortest and longest hold of a response, seconds
(inside the 5 s response_timeout every profile but the tests' short ones has)."""
REAL_SPEED_SECONDS = 120.0
"""Variant real-speed: the ``task_seconds`` it runs with (the plain unit's is 3 s): only a
plan longer than its qualitative speed covers in this many seconds goes faster."""
TWO_SIGNALS = ("$abort", "$enough")
"""Variant two-signals: what its look-at tasks list (5.3)."""
RESPAWN_METRES = 400.0
"""Variant respawn: how far from its last position a rebooted unit comes back (the public
agents were seen 57-520 m away, 2 s after the restart)."""
EDGE = 0.12
"""Variant sensor-rate-edge: sensor_info and sensors run this fraction slower than declared
(the profiles' rate_tolerance is 0.2)."""

for _variant in _ALL:
    for _rule in _variant.warns:
        assert _rule in CATALOGUE, f"variant {_variant.name}: unknown rule {_rule}"
        # A warning, or a decided rule (it warns unless the run is strict).
        assert CATALOGUE[_rule].severity is Severity.WARNING or CATALOGUE[_rule].is_decided, \
            f"variant {_variant.name}: {_rule} is not accepted with a warning"


class VariantError(ValueError):
    """An unknown variant name, or variants that cannot be combined."""


def check_variants(names: str | Iterable[str]) -> frozenset[str]:
    """The variant names as a set; raise ``VariantError`` for an unknown one or a conflict."""
    out = switches(names, VARIANTS, "variant", VariantError)
    for pair in CONFLICTS:
        if pair <= out:
            raise VariantError(f"variants {' and '.join(sorted(pair))} cannot be combined")
    return out


def list_variants(as_json: bool) -> str:
    """What ``sim --list-variants`` prints."""
    if as_json:
        import json

        return json.dumps({"variants": [
            {"name": v.name, "section": v.section, "warns": list(v.warns),
             "description": v.description} for v in _ALL]}, indent=2)
    width = max(map(len, VARIANTS))
    lines = [f"{'variant':<{width}}  spec sections / what it does (conformant: fails no rule)",
             ""]
    for v in _ALL:
        warns = f"  [warns: {' '.join(v.warns)}]" if v.warns else ""
        lines.append(f"{v.name:<{width}}  {v.section}{warns}")
        lines.append(f"{'':<{width}}    {v.description}")
    return "\n".join(lines)

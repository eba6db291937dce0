"""Fault switches of the reference unit: each breaks named rules the way a real unit would.

``FAULTS[name].rules`` are exactly the catalogue rules the fault makes fail (the
certification suite asserts that, fault by fault); faults combine freely. Every rule a unit
can break has at least one fault; ``NOT_UNIT_BREAKABLE`` says, for each rule that has none,
why no unit can break it.

``scope`` says who can see a fault: ``unit`` faults show in the unit's own topics
(``<unit>/#``); ``broker`` faults move the whole unit to a topic outside its address (a
leading '/', another agent type or role), so only an observer of the broker (``#``, the
linter) sees them.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from conformance.rules import CATALOGUE, Mode


@dataclass(frozen=True)
class Fault:
    """A fault switch: its name, the rule ids it breaks, and what it does (in the words of the
    bug it imitates)."""

    name: str
    rules: tuple[str, ...]
    description: str
    scope: str = "unit"
    """``unit``: visible under the unit's own topics; ``broker``: the unit publishes at another
    address, visible only to an observer of the whole broker."""
    stimulus: bool = False
    """It shows only in answers to commands (responses, feedback), although its rules are
    judged passively once that traffic exists."""
    sequence: bool = False
    """It shows only in an order of commands the scripted scenarios do not send (a pause before
    an abort, a second task while one is paused, a resend after the end): exploration finds it
    (``conformance.protocol``), the scripted certification and workouts do not."""
    decided: tuple[str, ...] = ()
    """Of ``rules``, those it breaks only through a decided condition (``[[rule.condition]]``
    in rules.toml): they warn unless the profile adopts the decision."""

    @property
    def active(self) -> bool:
        """Whether showing it needs commands sent: an active rule, or a ``stimulus`` fault."""
        return self.stimulus or any(CATALOGUE[r].mode is not Mode.PASSIVE for r in self.rules)


def _f(name: str, rules: str, description: str, scope: str = "unit",
       stimulus: bool = False) -> Fault:
    stimulus = stimulus or any(r.startswith(("EXEC-", "ERR-006", "ERR-013", "ERR-014"))
                               for r in rules.split())
    return Fault(name, tuple(rules.split()), description, scope, stimulus)


_ALL: tuple[Fault, ...] = (
    # --- 3 topics -------------------------------------------------------------------------------
    _f("topic-leading-slash", "TOPIC-001",
       "Publishes and listens under '/<unit>/...' (a ROS namespace '/dji0' pasted into the "
       "MQTT topic).", "broker"),
    _f("topic-uppercase-sensor", "TOPIC-002 SI-001",
       "Names its camera sensor 'Camera_URL' (listed and published so)."),
    _f("topic-hyphen-sensor", "TOPIC-003 SI-001",
       "Names its camera sensor 'camera-url' (listed and published so)."),
    _f("topic-empty-level", "TOPIC-004",
       "Publishes its camera sensor at 'sensor//camera_url' (a prefix ending in '/' joined "
       "with '/'), and does not list it."),
    _f("topic-type-uav", "TOPIC-005 HB-004",
       "Calls its agent type 'uav' in its topics and heartbeat.", "broker"),
    _f("topic-role-sim", "TOPIC-006",
       "Uses the role 'sim' instead of its configured role in its topics.", "broker"),
    _f("topic-unknown-subtopic", "TOPIC-007",
       "Also publishes a legacy '<unit>/status' message that the spec does not define."),
    _f("topic-space-sensor", "TOPIC-008 TOPIC-003 SI-001",
       "Names its camera sensor 'camera url' (with a space; listed and published so)."),
    # --- any message ------------------------------------------------------------------------
    _f("payload-latin1", "MSG-001",
       "Encodes its camera_url sensor in Latin-1 ('rtsp://.../caméra' is not UTF-8)."),
    _f("course-nan", "MSG-002",
       "Publishes course as NaN while standing still (json.dumps' allow_nan default)."),
    _f("position-as-list", "MSG-003",
       "Publishes position as a one-element list of GeoPoints (10.1.6's example form)."),
    _f("camera-data-url", "MSG-004",
       "Publishes camera_url as an inline 'data:image/jpeg;base64,...' frame of 1.5 MB."),
    _f("stamp-milliseconds", "MSG-008",
       "Stamps heartbeat and info messages in milliseconds (Date.now() style)."),
    _f("stamp-clock-skew", "MSG-005",
       "Stamps with a clock that runs 120 s behind (no NTP)."),
    _f("name-mismatch", "MSG-006",
       "Puts its display name in 'name' (upper case) instead of the topic's unit name."),
    _f("retained-stale-heartbeat", "MSG-007",
       "Publishes, once, a retained 'birth' heartbeat stamped when it booted, 5 periods before "
       "it connected; every later subscriber receives that stale heartbeat."),
    # --- 5.1 heartbeat ----------------------------------------------------------------------
    _f("heartbeat-missing-field", "HB-001",
       "Leaves 'levels' out of its heartbeat (it sends its info messages anyway)."),
    _f("heartbeat-type-case", "HB-002",
       "Sends type 'Heartbeat' instead of 'HeartBeat'."),
    _f("heartbeat-rate-drift", "HB-003",
       "Declares its heartbeat rate but sends at 1/1.35 of it (sleep(period) plus work)."),
    _f("heartbeat-rate-gross", "HB-003",
       "Declares its heartbeat rate but sends every 5 declared periods (a period written "
       "where its rate belongs: a public agent declares 5 Hz and sends every 5 s)."),
    _f("agent-type-mismatch", "HB-004",
       "Says another agent-type in its heartbeat than its topic does (configured from a "
       "ground unit's template: 'ground', or 'air' on a ground unit)."),
    _f("agent-uuid-not-uuid", "HB-005",
       "Uses '<name>-<boot count>' as its agent-uuid everywhere."),
    _f("agent-uuid-changes", "HB-006",
       "Makes a new agent-uuid every 5 heartbeat periods without rebooting or going silent "
       "(the uuid is generated in the heartbeat thread, which restarts)."),
    _f("level-unknown", "HB-007",
       "Declares an extra level 'telemetry'."),
    _f("undeclared-direct-execution", "HB-013",
       "Declares only the 'sensor' level, yet sends direct_execution_info and answers "
       "commands (seen in the field)."),
    _f("level-unbacked", "HB-008",
       "Declares 'tst execution' (copied from 5.1) without sending tst_execution_info."),
    _f("rate-zero", "HB-009",
       "Declares heartbeat rate 0 ('unknown')."),
    _f("dropouts", "HB-010",
       "Falls silent for 4 periods every 25 periods (out of radio range) and comes back with "
       "the same agent-uuid (a silence is not judged as a rate: HB-003 stays clean)."),
    _f("twin-agent", "HB-011 HB-003",
       "A second, stale process publishes heartbeats under the same name with another "
       "agent-uuid, interleaved with the unit's own."),
    # --- 5.2 sensor_info and 6 sensors -------------------------------------------------------
    _f("sensor-info-type", "SI-001",
       "Sends sensor_info with type 'SensorInformation'."),
    _f("sensor-info-rate-drift", "SI-002",
       "Sends sensor_info at 1/1.35 of its declared rate."),
    _f("sensor-listed-unpublished", "SI-003",
       "Lists 'battery_state' in sensor-data-provided but never publishes it."),
    _f("mandatory-sensor-missing", "SI-004",
       "Neither lists nor publishes the mandatory 'course' sensor."),
    _f("sensor-unlisted", "SI-005",
       "Publishes sensor/battery_state without listing it in sensor_info."),
    _f("position-deg-e7", "SENS-001",
       "Publishes latitude and longitude as integer degrees x 1e7 (MAVLink's degE7)."),
    _f("heading-signed", "SENS-002",
       "Publishes heading in (-180, 180] (atan2 output); the unit faces west at start, so "
       "heading is negative."),
    _f("speed-sentinel", "SENS-003",
       "Publishes speed -1 while it stands still ('no fix')."),
    _f("camera-url-object", "SENS-004",
       "Publishes camera_url as an object {\"url\": ...} instead of a string."),
    _f("position-jumps", "SENS-005",
       "Two positions in every five come from a second GNSS receiver with an 800 m datum "
       "offset."),
    # --- 5.3 direct_execution_info -----------------------------------------------------------
    _f("dei-type", "DEI-001",
       "Sends direct_execution_info with type 'DirectExecInfo'."),
    _f("dei-no-tasks-executing", "DEI-001",
       "Sends direct_execution_info without tasks-executing (the official Python L2 and C++ "
       "agents): DEI-001's finding alone, not also DEI-004's 'not listed'."),
    _f("dei-rate-drift", "DEI-002",
       "Sends direct_execution_info at 1/1.35 of its declared rate."),
    _f("signal-nonstandard", "DEI-003",
       "Lists a system signal '$resume' (an alias of $continue) for every task."),
    _f("tasks-executing-stale", "DEI-004",
       "Never removes ended tasks from tasks-executing."),
    _f("tasks-executing-twice", "DEI-004",
       "Lists each running task twice in tasks-executing (seen in the field).", stimulus=True),
    _f("refused-task-listed", "DEI-004",
       "Keeps the task-uuid of a start-task it refused ('failed': a task not offered, invalid "
       "parameters) in tasks-executing for good, as a phantom task (seen in the field).",
       stimulus=True),
    _f("tst-info-incomplete", "TEI-001",
       "Declares 'tst execution' and sends tst_execution_info without 'rate'."),
    _f("tst-info-rate-drift", "TEI-002",
       "Declares 'tst execution' and sends tst_execution_info at 1/1.35 of its declared rate."),
    # --- 12 direct execution: responses ------------------------------------------------------
    _f("response-no-agent-uuid", "EXEC-002 ERR-013",
       "Leaves agent-uuid out of its responses (in a signal-task response that is ERR-013's "
       "reading)."),
    _f("start-answered-started", "EXEC-003 EXEC-START-001",
       "Answers start-task 'started' (14.4.4's TST word) instead of 'running'."),
    _f("response-stale-agent-uuid", "EXEC-004",
       "Its command executor has an agent-uuid of its own, which responses carry."),
    _f("response-reuses-com-uuid", "EXEC-005",
       "Sends each response with the command's com-uuid instead of a fresh one."),
    _f("response-on-finish", "EXEC-006",
       "When a task ends it also sends an exec/response 'finished' whose response-to is the "
       "task-uuid, answering no command."),
    _f("fail-reason-empty", "EXEC-007 EXEC-START-004",
       "Refuses commands with fail-reason '' (the reason is only logged)."),
    # EXEC-ROBUST-001 is not its: a unit that never answered a ping did not stop answering;
    # the robustness scenario says could-not-test.
    _f("pong-missing", "EXEC-PING-001",
       "Never answers ping."),
    _f("pong-late", "EXEC-PING-001 EXEC-010",
       "Answers ping 3 periods late (its executor answers pings from a slow loop; past the "
       "short response timeouts of the self-test profiles, not the default 5 s at 1 Hz)."),
    _f("response-twice", "EXEC-009",
       "Publishes every response twice (a retry loop that does not wait for the PUBACK)."),
    _f("pong-response-to-uppercase", "EXEC-PING-002 EXEC-006",
       "Answers ping with the ping's com-uuid in upper case as response-to."),
    _f("start-response-no-task-uuid", "EXEC-START-002",
       "Leaves task-uuid out of the start-task response when the commander sent one."),
    _f("start-response-unpublished", "EXEC-START-001",
       "Runs start-task, but builds its response into a message that is never published "
       "(seen in the field): feedback flows, no answer comes."),
    _f("start-no-generated-task-uuid", "EXEC-START-002",
       "Generates a task-uuid for a start-task that has none, but does not return it."),
    _f("start-no-task-uuid-unanswered", "EXEC-START-001",
       "Drops a start-task without task-uuid: msg['task-uuid'] raises a KeyError in its "
       "message callback, which the MQTT library survives (no answer, no task; seen in the "
       "field). A start-task it would refuse anyway (no task object) is still refused. "
       "EXEC-START-002 is then could-not-test: no answer showed a generated task-uuid."),
    _f("dies-on-missing-task-uuid", "HB-012",
       "Its MQTT thread dies on a start-task without task-uuid (a KeyError): from then on it "
       "publishes and answers nothing, while the process lives on (seen in the field).",
       stimulus=True),
    _f("dies-on-invalid-params", "HB-012",
       "Its MQTT thread dies on a start-task whose parameters it cannot read ('waypoints: 42': "
       "a TypeError), as the public L2 agents did in some runs: from then on it publishes "
       "and answers nothing, while the process lives on.", stimulus=True),
    _f("no-final-feedback", "EXEC-START-003",
       "Sends no feedback when a task ends on its own (only on signals)."),
    _f("no-final-status", "EXEC-START-003 EXEC-SIG-002 EXEC-SIG-004",
       "Sends no final status at all: neither when a task ends on its own nor when $abort or "
       "$enough ends it (the task only leaves tasks-executing), as a unit written elsewhere "
       "did."),
    _f("accept-invalid-params", "EXEC-START-004",
       "Accepts start-task with invalid parameters ('running'); the task fails a moment "
       "later."),
    _f("accept-unknown-task", "EXEC-START-005",
       "Accepts start-task of any task name, listed or not, and runs it for a second."),
    _f("signal-unanswered", "EXEC-SIG-001 EXEC-SIG-005",
       "Executes signal-task but never answers it."),
    _f("abort-ignored", "EXEC-SIG-002",
       "Acknowledges $abort ('ok') and goes on."),
    _f("abort-running-goes-on", "EXEC-SIG-002 EXEC-SEQ-001",
       "Accepts $abort in 12.1's word ('running') and goes on: that task runs on, and says "
       "'running' again with every heartbeat (as a periodic report does)."),
    _f("pause-ignored", "EXEC-SIG-003",
       "Acknowledges $pause ('ok') but neither pauses nor says 'paused'."),
    _f("enough-aborts", "EXEC-SIG-004",
       "Ends a task on $enough with status 'aborted'."),
    _f("signal-unknown-task-ok", "EXEC-SIG-005",
       "Answers 'ok' to a signal for a task-uuid it has never seen."),
    _f("query-forgets-finished", "EXEC-QUERY-001",
       "Answers query-status from the running tasks only: an ended task is 'unknown'."),
    _f("query-unanswered", "EXEC-QUERY-001 EXEC-QUERY-002",
       "Never answers query-status (every agent seen in the field)."),
    _f("query-unknown-failed", "EXEC-QUERY-002",
       "Answers query-status of a task it does not know 'failed' ('no such task'), never seen "
       "or forgotten in a reboot (REBOOT-002 is judged against that same answer)."),
    _f("resend-executes-twice", "EXEC-RESEND-001",
       "Executes a command resent with the same com-uuid again."),
    _f("resend-unanswered", "EXEC-RESEND-002",
       "Drops a resent command silently (no second answer)."),
    _f("resend-answered-failed", "EXEC-RESEND-003",
       "Takes a resent start-task for a new one: answers it 'failed' (task-uuid in use) and "
       "sends a 'failed' feedback for the task, which runs on (seen in the field): refused, "
       "not executed twice (EXEC-RESEND-001 holds); both 'failed' contradict the first "
       "answer while the task runs (EXEC-RESEND-003, decided: it warns)."),
    # --- 12.4 feedback ------------------------------------------------------------------------
    _f("feedback-no-com-uuid", "EXEC-FB-001",
       "Leaves com-uuid out of feedback messages."),
    _f("feedback-status-typo", "EXEC-FB-002",
       "Sends a 'Starting' feedback (capitalised) before 'running'."),
    _f("feedback-stale-agent-uuid", "EXEC-FB-003",
       "Its feedback publisher has an agent-uuid of its own, which feedback carries."),
    _f("feedback-after-final", "EXEC-FB-004",
       "Sends a task's final feedback twice."),
    _f("feedback-status-done", "EXEC-FB-002",
       "Ends its tasks with feedback status 'done' where 12.4 says 'finished'."),
    _f("feedback-no-task-uuid", "EXEC-FB-001",
       "Leaves task-uuid out of feedback messages."),
    _f("task-uuid-ignored", "EXEC-START-002",
       "Runs every task under a task-uuid it generates, ignoring the one start-task gives "
       "(and answers with its own)."),
    # --- robustness and reboot ----------------------------------------------------------------
    _f("crash-on-malformed", "EXEC-ROBUST-001 EXEC-ROBUST-002 EXEC-PING-001",
       "Its command thread dies on the first command that is not a JSON object: no command is "
       "answered after that (heartbeats go on; the pings after it go unanswered)."),
    _f("malformed-unanswered", "EXEC-ROBUST-002",
       "Drops malformed commands silently, even when their com-uuid can be read (a "
       "start-task without a task object too)."),
    _f("reboot-keeps-agent-uuid", "REBOOT-001 REBOOT-002",
       "Keeps its agent-uuid across a reboot (read from a config file) but loses its history."),
    _f("reboot-remembers-history", "REBOOT-002",
       "Gets a new agent-uuid on reboot but still knows its earlier tasks (history on disk)."),
    _f("reboot-renames", "REBOOT-001",
       "Names itself anew at every start: after a reboot it comes back as '<name>_<4 hex "
       "digits>' (a random suffix per start), gone from the address it was certified at."),
    # --- errata readings ----------------------------------------------------------------------
    _f("sensor-dot-info", "ERR-001",
       "Sends sensor_info on 'sensor.info' (5.2's spelling)."),
    _f("feedback-says-success", "ERR-006",
       "Reports a finished task as 'success' in feedback (12.1's query-status word)."),
    _f("level-underscore", "ERR-008",
       "Declares the level 'direct_execution'."),
    _f("info-no-agent-uuid", "ERR-012",
       "Leaves agent-uuid out of sensor_info and direct_execution_info (5.2/5.3's examples)."),
    _f("signal-response-tst-form", "ERR-013",
       "Answers signal-task in 14.4.1's TST form: com-uuid, response 'ok', response-to, "
       "nothing else."),
    _f("uuid-counter", "ERR-014",
       "Makes com-uuids of its responses and feedback, and the task-uuids it generates, from "
       "a counter ('msg-17')."),
)

# --- 12 across steps: field bugs that only an order of commands shows (the model's rules and the
# conversation rules it extends; conformance.protocol). No scripted scenario sends that order.


def _seq(name: str, rules: str, description: str, decided: str = "") -> Fault:
    return Fault(name, tuple(rules.split()), description, "unit", True, True,
                 tuple(decided.split()))


_SEQUENCE = (
    _seq("abort-paused-resumes", "EXEC-SEQ-001",
         "Answers $abort of a paused task 'ok' and resumes it first (the handler calls "
         "continue() before cancel()): 'running' again, the vehicle moves, then 'aborted'."),
    _seq("pause-pauses-all", "EXEC-SEQ-002",
         "Pauses every running task on $pause, not only the one it names (the pause goes to "
         "the controller all tasks share); $continue resumes only the named one."),
    _seq("resend-after-end-runs-again", "EXEC-RESEND-001",
         "Forgets a start-task's com-uuid once its task has ended: the same start-task resent "
         "after the end runs the task again."),
    _seq("preempt-paused-silently", "EXEC-START-003",
         "A new task of the same kind drops a paused one from its task table: the paused task "
         "leaves tasks-executing with no final status."),
    _seq("query-paused-unknown", "EXEC-QUERY-001",
         "Answers query-status of a paused task 'unknown' (it looks among running and ended "
         "tasks only)."),
    _seq("feedback-after-abort-paused", "EXEC-FB-004",
         "A task aborted while paused says 'paused' once more after its 'aborted' (its pause "
         "timer fires after the abort)."),
    # 12.1 lists 'running' for a paused task's query ('paused' is accepted: docs/MODEL.md);
    # what no reading allows is an end the task never had.
    _seq("query-paused-finished", "EXEC-QUERY-001",
         "Answers query-status of a paused task 'finished' (a task no longer running counts "
         "as done), though it is paused and goes on when continued."),
    # 5.3: a paused task may be left out of tasks-executing, but not after being listed
    # paused (docs/MODEL.md).
    _seq("paused-dropped-from-list", "EXEC-START-003",
         "Lists a paused task in tasks-executing once, then leaves it out while it stays "
         "paused (it moves paused tasks to a table the list is not built from), with no "
         "final status."),
    _seq("resend-signal-reapplied", "EXEC-RESEND-001",
         "Remembers only start-tasks' com-uuids: a resent signal-task is applied again ($pause, "
         "$continue, the first $pause resent: the task pauses again)."),
    # EXEC-SEQ-002's condition also-aborted (decided: a task serving another may end with it)
    # warns by default; the test profiles adopt it.
    _seq("abort-aborts-all", "EXEC-SEQ-002",
         "Aborts every task on an $abort of one (the cancel goes to the controller all tasks "
         "share), each with its 'aborted' (EXEC-SEQ-002's condition also-aborted).",
         decided="EXEC-SEQ-002"),
)
SEQUENCE_FAULTS = frozenset(f.name for f in _SEQUENCE)
_ALL = _ALL + _SEQUENCE

# --- 14 TST execution (conformance.sim.tst) ------------------------------------------
# Each switches the TST level on by itself (the unit then declares 'tst execution'). All but
# tst-info-type-upper show only once TST commands are sent (stimulus).


def _tst(name: str, rules: str, description: str, stimulus: bool = True) -> Fault:
    return Fault(name, tuple(rules.split()), description, "unit", stimulus)


_TST = (
    _tst("tst-response-reuses-com-uuid", "TST-002",
         "Sends each tst/response with the command's com-uuid instead of a fresh one."),
    _tst("tst-feedback-finished", "TST-003",
         "Reports a node that ended well as 'finished' (12.4's word) instead of 'succeeded'."),
    _tst("tst-root-uuid-wrong", "TST-004",
         "Answers start-tst 'started' with the start-tst's com-uuid as root-uuid."),
    _tst("tst-common-params-only", "TST-004",
         "Reads node-uuid and execunit from 'common-params' only: for trees written as the "
         "spec's examples (common_params) it makes node-uuids of its own, so root-uuid is not "
         "the root's node-uuid."),
    _tst("tst-accept-foreign-execunit", "TST-005",
         "Starts a tree whose execunit names another unit, and runs it itself."),
    _tst("tst-resend-starts-twice", "TST-006",
         "Starts a start-tst resent with the same com-uuid again from scratch."),
    _tst("tst-resend-unanswered", "TST-007",
         "Drops a resent TST command silently (no second answer)."),
    _tst("tst-root-flag-everywhere", "TST-008",
         "Sets root-flag true in every node's feedback (copied from 14.5's examples)."),
    _tst("tst-no-final-feedback", "TST-009",
         "Sends no final status for seq and conc nodes (only their leaves report an end)."),
    _tst("tst-seq-ignores-failure", "TST-010",
         "Goes on with a seq after a child failed, and reports the seq 'succeeded'."),
    _tst("tst-signal-unknown-node-ok", "TST-011",
         "Answers 'ok' to a signal for a node-uuid it has never seen."),
    _tst("tst-abort-ignored", "TST-012",
         "Acknowledges $abort of a TST node ('ok') and goes on."),
    _tst("tst-info-stale-nodes", "TST-013",
         "Never removes ended nodes from nodes-executing in tst_execution_info."),
    _tst("tst-start-answered-running", "ERR-015",
         "Answers start-tst 'running' (start-task's word) instead of 'started'."),
    _tst("tst-info-type-upper", "ERR-018",
         "Sends tst_execution_info with type 'TSTExecutionInfo'.", stimulus=False),
)
TST_FAULTS = frozenset(f.name for f in _TST)
TST_LEVEL_FAULTS = frozenset({"level-unbacked", "tst-info-incomplete", "tst-info-rate-drift"})
"""Faults that declare 'tst execution' to bend what the unit says about it (HB-008, TEI-*)."""
_ALL = _ALL + _TST

FAULTS: dict[str, Fault] = {f.name: f for f in _ALL}
assert len(FAULTS) == len(_ALL), "duplicate fault name"

NOT_UNIT_BREAKABLE: dict[str, str] = {
    "EXEC-001": "judges commands, which the commander sends, not the unit",
    "EXEC-008": "judges the commander's reuse of a com-uuid",
    "TASK-001": "judges the parameters of a start-task command (the commander's)",
    "TASK-002": "judges the task name of a start-task command (the commander's)",
    "TASK-003": "judges the parameters of a start-task command (the commander's)",
    "TST-001": "judges TST commands (the commander's)",
    "TST-014": "judges the tree of a start-tst command (the commander's)",
    "ERR-016": "judges where a commander sends TST commands; a unit refuses start-tst on "
               "exec/command (EXEC-003 'failed')",
    "ERR-017": "unit names in TST commands (the commander's); a unit understands both forms",
    "ERR-002": "about the spec's example text; a unit copying it breaks MSG-002 (course-nan)",
    "ERR-003": "a misspelled parameter in a start-task command (the commander's)",
    "ERR-010": "a task's GeoPoint tag, in a start-task or start-tst command (the commander's); "
               "sensor/position is not judged by it (6.1 has no example)",
    "ERR-004": "observe-position parameter forms in a start-task command (the commander's)",
    "ERR-005": "a TST node name in start-tst (the commander's)",
    "ERR-007": "the signal-executor command (sent by a commander)",
    "ERR-009": "common_params of a TST node in start-tst (the commander's)",
    "ERR-011": "about the spec's text: tst_execution_info is not defined (TEI-001 judges it)",
    **{rule: "the ROS side (4, 7, 13): the reference unit speaks MQTT only; judged from ROS "
             "bags, failing on the fault bags of tests/ros/test_rosbag_rules.py"
       for rule in ("ROS-001", "ROS-002", "ROS-003", "ROS-004", "ROS-005", "ROS-006")},
}

for _fault in _ALL:
    for _rule in _fault.rules:
        assert _rule in CATALOGUE, f"fault {_fault.name}: unknown rule {_rule}"


class FaultError(ValueError):
    """An unknown fault name; the message lists close matches."""


def switches(names: str | Iterable[str], known: Mapping[str, object], what: str,
             error: type[ValueError]) -> frozenset[str]:
    """``names`` (one name or several) as a set of switches of ``known`` (faults, variants);
    ``error`` names any unknown one, with the close matches and where the list is."""
    if isinstance(names, str):
        names = (names,)
    out = set()
    for name in names:
        if name not in known:
            close = difflib.get_close_matches(str(name), known, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise error(f"unknown {what} {name!r}{hint} (waraps-conformance sim "
                        f"--list-{what}s lists them)")
        out.add(str(name))
    return frozenset(out)


def check_names(names: str | Iterable[str]) -> frozenset[str]:
    """The fault names as a set; raise ``FaultError`` naming any unknown one."""
    return switches(names, FAULTS, "fault", FaultError)


def breaking(rule_id: str) -> list[Fault]:
    """The faults that break ``rule_id``."""
    return [f for f in _ALL if rule_id in f.rules]


def unit_breakable_rules() -> list[str]:
    """Every catalogue rule a unit can break (those not in ``NOT_UNIT_BREAKABLE``)."""
    return [r for r in CATALOGUE if r not in NOT_UNIT_BREAKABLE]

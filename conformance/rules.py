"""The rule catalogue: one entry per normative statement of the WARA-PS Core System API v0.7.

Every check, fault switch and report speaks of rules by these ids. An id is stable: never
renumber, only add. The spec's own errors are entries too (``ERR-*``), each with the decision
taken; by default the readings found in practice pass with a warning (severity ``warning``)
and the built-in ``strict`` profile turns them into failures.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class Severity(str, enum.Enum):
    """How a violation of a rule counts: ``error`` fails, ``warning`` warns."""

    ERROR = "error"
    WARNING = "warning"


class Level(str, enum.Enum):
    """The API level a rule belongs to (spec 5.1 levels, plus topic naming and any message)."""

    TOPIC = "topic"
    ANY = "any"
    SENSOR = "sensor"
    DIRECT_EXECUTION = "direct execution"
    TST_EXECUTION = "tst execution"


class Mode(str, enum.Enum):
    """How a rule is judged: from any traffic (passive), from a command and its answers in the
    traffic (conversation: lint judges it where the traffic holds the command, the suite sends
    one), or only from a stimulus the suite itself controls (active)."""

    PASSIVE = "passive"
    CONVERSATION = "conversation"
    ACTIVE = "active"


class Side(str, enum.Enum):
    """Whose fault a violation is (DESIGN 'Conversations, and whose fault it is')."""

    UNIT = "unit"
    """What the unit publishes and how it answers."""
    COMMANDER = "commander"
    """What a commander sends: commands on exec/command and tst/command."""
    SENDER = "sender"
    """Whoever published the message: a rule about any message (topic, JSON, stamp)."""


@dataclass(frozen=True)
class Rule:
    id: str
    title: str
    section: str
    severity: Severity
    level: Level
    mode: Mode
    decision: str = ""
    """For errata and unclear points: what this suite decided, and why."""
    side: Side = Side.UNIT
    """Whose fault a violation is; every rule on a command topic is the commander's."""

    @property
    def is_erratum(self) -> bool:
        return self.id.startswith("ERR-")


E, W = Severity.ERROR, Severity.WARNING
T, A, S, D, X = Level.TOPIC, Level.ANY, Level.SENSOR, Level.DIRECT_EXECUTION, Level.TST_EXECUTION
P, V, C = Mode.PASSIVE, Mode.CONVERSATION, Mode.ACTIVE
K, B = Side.COMMANDER, Side.SENDER

_CATALOGUE: tuple[Rule, ...] = (
    # --- 3 Topics JSON/MQTT ---------------------------------------------------------------
    Rule("TOPIC-001", "topic does not start with '/'", "3.2 Naming Conventions", E, T, P, side=B),
    Rule("TOPIC-002", "topic is all lowercase", "3.2 Naming Conventions", E, T, P, side=B),
    Rule("TOPIC-003", "topic words are joined by '_' (no '-', '.', spaces or camelCase)",
         "3.2 Naming Conventions", E, T, P, side=B),
    Rule("TOPIC-004", "unit topic has the form PREFIX1/unit/TYPE/ROLE/UNIT/...",
         "3.1 Topic Naming Scheme", E, T, P,
         "A topic under PREFIX1/unit/ with fewer than five non-empty levels, or an empty "
         "level anywhere, cannot be attributed to a unit and fails.", side=B),
    Rule("TOPIC-005", "agent type in the topic is air, ground, surface or subsurface",
         "3.1 Topic Naming Scheme", E, T, P, side=B),
    Rule("TOPIC-006", "role in the topic is real, simulation or playback",
         "3.1 Topic Naming Scheme", W, T, P,
         "3.1 lists 'real, simulation, playback...': the list is open, so another role "
         "warns instead of failing.", side=B),
    Rule("TOPIC-007", "subtopic is one the spec defines", "3.1 Topic Naming Scheme", W, T, P,
         "Known: heartbeat, sensor_info, direct_execution_info, tst_execution_info, "
         "sensor/<name>, exec/{command,response,feedback}, tst/{command,response,feedback}. "
         "Anything else is reported (warn) and otherwise left alone.", side=B),
    Rule("TOPIC-008", "topic has no wildcard, control character, space or non-ASCII character",
         "3.2 Naming Conventions", E, T, P, side=B),
    # --- every message ----------------------------------------------------------------------
    Rule("MSG-001", "payload is UTF-8 text", "12 Direct Execution API JSON", E, A, P, side=B),
    Rule("MSG-002", "payload is valid JSON (RFC 8259: no NaN, Infinity or trailing commas)",
         "12 Direct Execution API JSON", E, A, P, side=B),
    Rule("MSG-003", "payload is a JSON object where the message is an object",
         "5 Heartbeat/Info", E, A, P, side=B),
    Rule("MSG-004", "payload is within the examinable size and nesting depth",
         "2 WARAPS API Specifications", E, A, P,
         "Not in the spec: a payload over 1 MiB or nested deeper than 64 levels is not "
         "examined further and fails; no WARA-PS message comes near either limit.", side=B),
    Rule("MSG-005", "stamp is Unix time in seconds (a double) close to the receive time",
         "5.1 General Heartbeat Message", E, A, P,
         "5.1: 'Time stamp in double (time.time() in Python, seconds in double)'. A stamp "
         "more than the profile's clock tolerance (default 30 s) from the arrival time fails; "
         "the message says when it looks like milliseconds or nanoseconds.", side=B),
    Rule("MSG-006", "name in the message equals the UNIT of its topic", "5 Heartbeat/Info",
         E, A, P, side=B),
    # --- 5.1 heartbeat ----------------------------------------------------------------------
    Rule("HB-001", "heartbeat has every field of 5.1 with its type", "5.1 General Heartbeat Message",
         E, A, P),
    Rule("HB-002", "heartbeat type is 'HeartBeat'", "5.1 General Heartbeat Message", E, A, P),
    Rule("HB-003", "heartbeat rate matches its declared rate", "5.1 General Heartbeat Message",
         E, A, P,
         "Mean period over at least 10 intervals within the profile's tolerance (default "
         "20 %), and no single gap over 1.5 declared periods (FIELD-NOTES timing jitter). A "
         "mean off by more than 3x fails after 3 intervals already (a unit declaring 5 Hz "
         "and sending every 5 s is not worth ten more intervals)."),
    Rule("HB-004", "agent-type is air, ground, surface or subsurface and matches the topic",
         "5.1 General Heartbeat Message", E, A, P),
    Rule("HB-005", "agent-uuid is a UUID", "5.1 General Heartbeat Message", E, A, P),
    Rule("HB-006", "agent-uuid stays the same while the unit lives",
         "5 Heartbeat/Info", E, A, P,
         "An agent-uuid may only change across a reboot (a silence of more than two declared "
         "periods before the new one); a flip-flop or a change without silence fails."),
    Rule("HB-007", "levels are among: sensor, direct execution, tst execution, delegation",
         "5.1 General Heartbeat Message", E, A, P),
    Rule("HB-008", "every declared level is backed by its info message",
         "5 Heartbeat/Info", E, A, P,
         "sensor -> sensor_info, direct execution -> direct_execution_info, tst execution -> "
         "tst_execution_info; delegation has no info message in v0.7 and is not checked. "
         "Decided at the end over the whole observation: info messages may come slower than "
         "the heartbeat (5), so a level fails only when observed for the profile's info_wait "
         "(30 s; at least 3 heartbeat periods) without its info message, else it is skipped."),
    Rule("HB-009", "rate is a positive number of Hz", "5.1 General Heartbeat Message", E, A, P),
    Rule("HB-010", "the unit does not fall silent (no heartbeat for 3 declared periods)",
         "5.1 General Heartbeat Message", W, A, P,
         "5.1: the heartbeat registers availability. A silence of more than 3 declared periods "
         "warns (a boat out of range is allowed to fall silent); coming back with the same "
         "agent-uuid is a resumption, with a new one a reboot (HB-006)."),
    Rule("HB-011", "one unit name is used by one live agent (not two agent-uuids at once)",
         "5 Heartbeat/Info", E, A, P,
         "Two processes publishing under one unit name alternate agent-uuids without silence; "
         "commanders cannot tell them apart."),
    Rule("HB-012", "the unit does not die (its heartbeat stops and never resumes)",
         "5.1 General Heartbeat Message", E, A, P,
         "A heartbeat silent for more than 3 periods (the declared period, or the measured "
         "mean interval when every interval was over 3 declared periods) that never resumes "
         "before the observation ends "
         "fails, naming the last command the unit received before it fell silent: agents "
         "seen in the field die on an edge-case command while the process lives on. Commands "
         "left unanswered by a dead unit are its death's evidence, not failures of their own. "
         "Silent then resumed with the same agent-uuid is HB-010 (warn), with a new one a "
         "reboot (HB-010 says so)."),
    Rule("HB-013", "the unit declares every level it acts on",
         "5.1 General Heartbeat Message", E, A, P,
         "The other direction of HB-008: a unit that answers commands or sends "
         "direct_execution_info without declaring 'direct execution' (or sensor_info and "
         "sensors without 'sensor', TST messages without 'tst execution') is filtered out by "
         "every commander that reads levels. Reported once per level."),
    Rule("MSG-007", "retained messages are not stale", "5 Heartbeat/Info", W, A, P,
         "Not in the spec: a retained heartbeat or info message whose stamp is older than 3 "
         "declared periods makes a dead unit look alive to every new subscriber.", side=B),
    # --- 5.2 sensor_info / 6 sensors ---------------------------------------------------------
    Rule("SI-001", "sensor_info has every field of 5.2 with its type (type 'SensorInfo')",
         "5.2 Sensor Level Message", E, S, P),
    Rule("SI-002", "sensor_info rate matches its declared rate", "5.2 Sensor Level Message",
         E, S, P),
    Rule("SI-003", "every sensor listed in sensor-data-provided is published",
         "5.2 Sensor Level Message", E, S, P),
    Rule("SI-004", "the mandatory sensors position, heading, course and speed are provided",
         "6.1 Mandatory Sensors", E, S, P),
    Rule("SI-005", "no sensor topic is published that sensor_info does not list",
         "5.2 Sensor Level Message", W, S, P),
    Rule("SENS-001", "sensor/position is a GeoPoint (latitude, longitude, altitude in range)",
         "6.1 Mandatory Sensors", E, S, P),
    Rule("SENS-002", "sensor/heading and sensor/course are numbers in degrees [0, 360)",
         "6.1 Mandatory Sensors", W, S, P,
         "The spec says float and states no range; degrees are implied by every angle in "
         "section 9. A value outside [0, 360) warns (a heading in (-180, 180] or in radians "
         "is a common bug, but the spec does not forbid it). The one schema rule also judges "
         "the type, so a heading that is not a number warns too."),
    Rule("SENS-003", "sensor/speed is a non-negative number (m/s)", "6.1 Mandatory Sensors",
         E, S, P),
    Rule("SENS-004", "URL sensors (camera_url, videoserver_url, *_url) are strings",
         "6.2 Optional Sensors", E, S, P),
    Rule("SENS-005", "position moves no faster than the reported speed allows",
         "6.1 Mandatory Sensors", W, S, P,
         "Not stated by the spec; a plausibility check of units (e.g. speed in km/h): the "
         "distance between two positions over their interval exceeding 3x the largest "
         "reported speed plus 5 m/s warns."),
    # --- 5.3 direct_execution_info ------------------------------------------------------------
    Rule("DEI-001", "direct_execution_info has every field of 5.3 with its type",
         "5.3 Direct Execution Level Info", E, D, P),
    Rule("DEI-002", "direct_execution_info rate matches its declared rate",
         "5.3 Direct Execution Level Info", E, D, P),
    Rule("DEI-003", "signals starting with '$' are the built-in $enough, $pause, $continue, $abort",
         "12.2.2 signal-task", E, D, P),
    Rule("DEI-004", "tasks-executing lists exactly the tasks that run",
         "5.3 Direct Execution Level Info", E, D, C),
    Rule("TEI-001", "tst_execution_info is an object with name, rate, stamp and type",
         "2.2/3.1 (tst_execution_info is named, not defined)", E, X, P,
         "v0.7 names the topic without defining the message; the suite accepts any object "
         "with name, rate, stamp, type (see ERR-011)."),
    Rule("TEI-002", "tst_execution_info rate matches its declared rate", "3.1 Topic Naming Scheme",
         E, X, P),
    # --- 12 direct execution --------------------------------------------------------------------
    Rule("EXEC-001", "exec/command matches the schema of its command", "12.2 Task Command Messages",
         E, D, P, side=K),
    Rule("EXEC-002", "exec/response has agent-uuid, com-uuid, response and response-to",
         "12.3 Response Messages", E, D, P),
    Rule("EXEC-003", "response value is one the spec defines for the command",
         "12.1 Commands", E, D, P),
    Rule("EXEC-004", "response agent-uuid equals the unit's heartbeat agent-uuid",
         "12.1 Commands", E, D, P),
    Rule("EXEC-005", "response has a fresh com-uuid of its own (not the command's)",
         "12.1 Commands", E, D, P,
         "2: 'Use UUID to identify a communication message': a response reusing the command's "
         "com-uuid breaks resend detection on the commander's side."),
    Rule("EXEC-006", "every response answers a command that was sent (response-to)",
         "12.1 Commands", E, D, P),
    Rule("EXEC-007", "a failed response carries a non-empty fail-reason", "12.1 Commands",
         E, D, P),
    Rule("EXEC-008", "a commander does not reuse a com-uuid for a different command",
         "2 WARAPS API Specifications", E, D, P,
         "2: 'Use UUID to identify a communication message' and 12.1's resend reuses it for "
         "the same command; the same com-uuid with other content makes a resend ambiguous.", side=K),
    Rule("EXEC-009", "a command is answered once, and again only when it is resent",
         "12.1 Commands", E, D, V,
         "Judged from traffic: more responses with a command's com-uuid in response-to than "
         "times the command was sent fail (12.3: a response answers a command)."),
    Rule("EXEC-010", "a command is answered within the response timeout", "12.1 Commands",
         W, D, V,
         "The spec sets no deadline; the profile's response_timeout (5 s) is the suite's. A "
         "response after it warns here, saying how late (the commander has resent or given up "
         "by then), and fails the rule of the command (EXEC-PING-001, EXEC-START-001, ...) as "
         "no response at all does, in lint as in the suite, whose scenarios wait as long."),
    Rule("EXEC-PING-001", "ping is answered with a pong within the deadline", "12.2.1 ping",
         E, D, V),
    Rule("EXEC-PING-002", "pong response-to is the ping's com-uuid", "12.3.1 ping response",
         E, D, V),
    Rule("EXEC-START-001", "start-task is answered running or failed (with a reason)",
         "12.3.3 start-task response", E, D, V),
    Rule("EXEC-START-002", "start-task response carries the task-uuid sent, or a generated one",
         "12.1 Commands", E, D, V),
    Rule("EXEC-START-003", "a started task sends feedback until a final status",
         "12.4 Feedback Messages", E, D, V,
         "From traffic: a task answered 'running' that leaves tasks-executing without a final "
         "feedback (finished, failed, aborted) fails; a task still running when the "
         "observation ends is not judged."),
    Rule("EXEC-START-004", "start-task with invalid parameters is refused with a reason",
         "12.1 Commands", E, D, V),
    Rule("EXEC-START-005", "start-task of a task not in tasks-available is refused",
         "5.3 Direct Execution Level Info", E, D, V),
    Rule("EXEC-SIG-001", "signal-task is answered", "12.2.2 signal-task", E, D, V,
         "12.3.2 is empty; the suite expects a response like start-task's (see ERR-013). "
         "From traffic: a signal answered 'ok' for a running task implies the feedback of "
         "EXEC-SIG-002/003/004 within the profile's feedback_timeout."),
    Rule("EXEC-SIG-002", "$abort ends the task with feedback 'aborted'", "12.2.2 signal-task",
         E, D, V),
    Rule("EXEC-SIG-003", "$pause gives feedback 'paused' and $continue 'running'",
         "12.2.2 signal-task", E, D, V),
    Rule("EXEC-SIG-004", "$enough ends the task with feedback 'finished'", "12.2.2 signal-task",
         E, D, V),
    Rule("EXEC-SIG-005", "a signal for an unknown task-uuid is answered 'failed'",
         "12.2.2 signal-task", E, D, C),
    Rule("EXEC-QUERY-001", "query-status answers the task's status over the whole history",
         "12.1 Commands", E, D, V,
         "From traffic: the answer agrees with the task's latest feedback before the query "
         "(running or paused: running; finished: finished, ERR-006 'success' warns; failed or "
         "aborted: failed); a task the traffic never showed is not judged in lint."),
    Rule("EXEC-QUERY-002", "query-status of a task never seen answers 'unknown'", "12.1 Commands",
         E, D, C),
    Rule("EXEC-RESEND-001", "a command resent with the same com-uuid is not executed twice",
         "12.1 Commands", E, D, V,
         "From traffic, after a resend of a start-task: a second 'running' answer under "
         "another task-uuid, a new 'running' feedback of a task that already ran or ended, "
         "the task twice in tasks-executing, or a 'failed' answer or feedback contradicting "
         "the first 'running' answer while the task runs on. Feedback after a final status "
         "caused by a resend is counted here, not under EXEC-FB-004."),
    Rule("EXEC-RESEND-002", "a command resent with the same com-uuid is answered again",
         "12.1 Commands", W, D, V,
         "12.1 says the commander resends until a response arrives, so the unit should "
         "answer again (DESIGN: 'should'): a missing second answer warns."),
    Rule("EXEC-FB-001", "exec/feedback has agent-uuid, com-uuid, task-uuid and status",
         "12.4 Feedback Messages", E, D, P),
    Rule("EXEC-FB-002", "feedback status is a standard status or a declared task-specific one",
         "12.4 Feedback Messages", E, D, P,
         "Task-specific strings are allowed (12.4), so an unknown status warns; one that is a "
         "near miss of a standard status (case, a typo) fails."),
    Rule("EXEC-FB-003", "feedback agent-uuid equals the unit's heartbeat agent-uuid",
         "12.4 Feedback Messages", E, D, P),
    Rule("EXEC-FB-004", "no feedback for a task after its final status", "12.4 Feedback Messages",
         E, D, P),
    Rule("EXEC-ROBUST-001", "no command stops the unit from answering (it still pings)",
         "12.1 Commands", E, D, V,
         "Judged from traffic: a unit that answered commands, then in the same life answers "
         "none of two or more later commands of different kinds while it still heartbeats, "
         "went deaf after the command before them; that command is named, and the unanswered "
         "ones are its evidence, not failures of their own."),
    Rule("EXEC-ROBUST-002", "a malformed command with a readable com-uuid is answered 'failed'",
         "12.1 Commands", W, D, V),
    Rule("REBOOT-001", "a reboot gives a new agent-uuid", "5 Heartbeat/Info", E, A, C),
    Rule("REBOOT-002", "after a reboot that changed agent-uuid, earlier tasks are unknown; "
         "with the same agent-uuid they are still known", "12.1 Commands", E, D, C,
         "12.1: the changing agent-uuid tells the commander that history was lost; a unit "
         "that keeps its uuid but forgets its history fails."),
    # --- 14 TST execution --------------------------------------------------------------------
    Rule("TST-001", "tst/command matches the schema of its command", "14.3 TST Command Messages",
         E, X, P, side=K),
    Rule("TST-002", "tst/response matches the schema of its response", "14.4 Response Messages",
         E, X, P),
    Rule("TST-003", "tst/feedback matches the schema and its status is a TST status",
         "14.5 Feedback Messages", E, X, P),
    Rule("TASK-001", "task parameters match the task's specification", "9 Tasks", E, D, P, side=K),
    Rule("TASK-002", "task name is a task of section 9", "9 Tasks", W, D, P,
         "Units may implement tasks beyond section 9 (5.3 tasks-available is open), so an "
         "unknown name warns; its params are then not checked.", side=K),
    Rule("TASK-003", "no parameter that the task does not define", "9 Tasks", W, D, P, side=K),
    # --- errata: the spec contradicts itself ---------------------------------------------------
    Rule("ERR-001", "sensor_info published on 'sensor.info' (5.2's spelling)",
         "5.2 vs 3.1", W, S, P,
         "5.2 says 'UNIT/sensor.info', 3.1's examples and 3.2's convention say sensor_info. "
         "sensor_info is canonical; sensor.info is accepted with a warning (strict: fail)."),
    Rule("ERR-002", "messages are valid JSON even where the spec's examples are not",
         "5.2, 5.3, 10.1.8, 12.2.2", E, A, P,
         "The examples have unquoted 'signal: $abort', trailing commas and unbalanced braces. "
         "They are read as typos: the schemas say what is meant, and a unit that copies them "
         "sends invalid JSON (MSG-002).", side=B),
    Rule("ERR-003", "look-at-bearing sent with 'use_absoiute_bearing' (10.1.1's spelling)",
         "9.3 vs 10.1.1", W, D, P,
         "10.1.1 writes 'use_absoiute_bearing'. 9.3 is canonical; the example's spelling is "
         "accepted with a warning and ignored (strict: fail).", side=K),
    Rule("ERR-004", "observe-position sent with a geopoint list or a speed list (10.1.6's forms)",
         "9.8 vs 10.1.6, 11.1.6", W, D, P,
         "The examples give 'geopoint' as a one-element list and 'speed' as [7.0]. 9.8 is "
         "canonical; the example forms are accepted with a warning (strict: fail).", side=K),
    Rule("ERR-005", "TST node 'look-at-angle' sent, a task section 9 does not define (11.1.1)",
         "11.1.1 vs 9", W, X, P,
         "11.1.1 uses look-at-angle/pan, which section 9 does not define (10.1.1 has "
         "look-at-bearing, the closest). A commander sending it warns (strict: fail); its "
         "params are not checked. A unit refuses the node like any name it does not offer "
         "(TST-005), naming look-at-bearing in the fail-reason.", side=K),
    Rule("ERR-006", "query-status of a completed task answered 'success' (12.1's word)",
         "12.1", W, D, P,
         "12.1 lists query-status results running, failed, success, unknown while responses "
         "say finished. 'finished' is canonical (as responses and feedback); 'success' is "
         "accepted with a warning (strict: fail)."),
    Rule("ERR-007", "'signal-executor' sent, which is not one of 12.1's four commands",
         "12.2.2 vs 12.1", W, D, P,
         "12.2.2 shows signal-executor, 12.1 lists four commands. It is treated as an unknown "
         "command: a unit may refuse it; a commander sending it warns.", side=K),
    Rule("ERR-008", "level written with an underscore ('direct_execution')",
         "5.1", W, A, P,
         "5.1's example writes 'direct execution' and its prose 'tst execution'. The spaced "
         "form is canonical; 'direct_execution' is accepted with a warning (strict: fail)."),
    Rule("ERR-009", "a TST node's common parameters sent under 'common-params'",
         "11, 14.3.4", W, X, P,
         "Every example writes common_params although all other keys use hyphens. common_params "
         "is canonical; 'common-params' (every implementation seen) is accepted with a warning "
         "(strict: fail). A unit understands both (TST-004); a node with both that disagree "
         "is malformed (TST-005).", side=K),
    Rule("ERR-010", "GeoPoint tagged \"type\" or not tagged (the examples say \"rostype\")",
         "6.1, 10, 11", W, A, P,
         "Every example tags rostype; 'type': 'GeoPoint' or no tag are found in practice and "
         "accepted with a warning (strict: fail). A tag with another value fails (SENS-001/"
         "TASK-001)."),
    Rule("ERR-011", "tst_execution_info is named but not defined", "3.1", W, X, P,
         "Accept an object with name, rate, stamp, type (TEI-001); its type is decided by "
         "ERR-018 and its optional list of running nodes by TST-013."),
    Rule("ERR-012", "info message sent without agent-uuid (5.2/5.3's examples)",
         "5 vs 5.2, 5.3", W, A, P,
         "5 says info messages 'should have an agent-uuid field'; the examples of 5.2 and 5.3 "
         "have none. Missing agent-uuid in an info message warns (strict: fail)."),
    Rule("ERR-013", "signal-task answered in another form than a start-task response",
         "12.3.2 (empty)", W, D, P,
         "12.3.2 is empty. The suite expects agent-uuid, com-uuid, response-to and response "
         "(running, finished, failed, ok, paused, aborted); fail-reason when failed."),
    Rule("ERR-014", "com-uuid, task-uuid or node-uuid that is not a UUID (8-4-4-4-12 hex)",
         "2, 11.1.7, 11.1.8", W, A, P,
         "2: 'Use UUID to identify a communication message'. 11.1.7's com-uuid has 11 hex "
         "digits in its last group and 11.1.8's node-uuid 9 in its first: identifiers are "
         "compared as opaque strings, so a malformed one warns (strict: fail). agent-uuid "
         "stays HB-005 (error).", side=B),
    # --- 4, 7, 13 the ROS side: judged from ROS bags (conformance.rosbag) ---------------------
    Rule("ROS-001", "the mandatory sensor topics /UNIT/sensor/position, heading, course and "
         "speed are recorded", "7.1 Mandatory Sensors", E, S, P,
         "Judged per unit that has a sensor topic in the bag or sends sensor_info (it is on "
         "the sensor level). A bag holds what was recorded: record every sensor topic of the "
         "unit."),
    Rule("ROS-002", "sensor topics have the types of section 7 (GeoPoint position, Float32 "
         "heading, course and speed, String URLs, BatteryState)",
         "7.1 Mandatory Sensors, 7.2 Optional Sensors", E, S, P,
         "A value of another type is still mapped where it can be (std_msgs/Float64 -> number, "
         "sensor_msgs/NavSatFix -> GeoPoint) so the JSON rules judge it as well; sensors that "
         "section 7 does not name are not judged by type."),
    Rule("ROS-003", "/heartbeat_info is an lrs_msgs_common/TopicMsg {string topic, string msg}",
         "4 Topics ROS", E, A, P,
         "2.3 says the heartbeat/info JSON is sent 'as std_msgs/String'; 4 defines TopicMsg, "
         "which carries the topic along. 4 is canonical: another type fails, and messages "
         "without string fields topic and msg are not linted (no topic, so no unit or kind)."),
    Rule("ROS-004", "a TopicMsg's topic is the JSON/MQTT topic of its msg "
         "(PREFIX1/unit/TYPE/ROLE/UNIT/<subtopic>)", "4 Topics ROS", E, A, P,
         "4: 'the topic used in the JSON/MQTT API is put on the msg also'. A topic that names "
         "no unit or no subtopic of the JSON API fails; a relative one ('heartbeat') is read "
         "under the bag's only unit (or --ros-unit) so that its msg is still linted. The msg is "
         "judged by the JSON rules of its topic (MSG-002, HB-001, ...)."),
    Rule("ROS-005", "the namespace of sensor and exec_command topics is the unit's name (/dji0)",
         "7 Sensor API ROS, 7.3 MQTT Bridge", E, T, P,
         "7: 'UNIT/sensor/SENSOR'; 7.3: 'NS is the namespace for the robot'. The namespace must "
         "equal UNIT of the unit's heartbeat topic exactly (no extra levels). Topics of a "
         "namespace no unit has are judged as the bag's only unit's (or --ros-unit's)."),
    Rule("ROS-006", "exec_command is a std_msgs/String carrying the JSON command",
         "13.3.2 Topics JSON", E, D, P),
    # --- 14 TST execution: how a unit runs trees (issue 10) -------------------------------------
    # Composite nodes are 'seq' (children in order) and 'conc' (children in parallel): v0.7
    # names no composite node, these are the TST system's. Leaf nodes are section-9 tasks.
    Rule("TST-004", "start-tst of a tree the unit can run is answered 'started' with root-uuid "
         "= the root's node-uuid", "14.4.4 Start TST Response", E, X, C,
         "14.4.4: response 'started', root-uuid naming the tree; 14.3.4: the root's node-uuid "
         "(generated by the unit when the commander set none). Trees written with "
         "common_params or common-params both run (ERR-009); 'running' is ERR-015's reading."),
    Rule("TST-005", "start-tst of a tree the unit cannot run is answered 'failed' with a reason, "
         "and nothing runs", "14 TST Execution API JSON", E, X, C,
         "14: 'start of execution ... or direct failure to start'. Refused: execunit of a node "
         "not this unit (the reference unit does not delegate), a node name that is neither "
         "seq, conc nor an offered task, invalid task parameters (9), a malformed tree (no "
         "name, children not a list, a node-uuid used twice, seq/conc without children), a "
         "node-uuid an earlier tree of this life used. No feedback follows a refusal."),
    Rule("TST-006", "a start-tst resent with the same com-uuid is not started twice",
         "12.1 Commands (resend), 14.3.4", E, X, C,
         "12.1's resend holds for TST commands too: no second 'active'/'running' of a node, no "
         "second tree."),
    Rule("TST-007", "a TST command resent with the same com-uuid is answered again",
         "12.1 Commands (resend), 14.4", W, X, C,
         "As EXEC-RESEND-002: the commander resends until it hears an answer, so the unit "
         "should answer again; a missing second answer warns."),
    Rule("TST-008", "root-flag is true in the feedback of the root node and false in every other "
         "node's", "14.5 Feedback Messages", E, X, C,
         "14.5's examples set root-flag true on the tree's top node; a commander tells the "
         "tree's end by it."),
    Rule("TST-009", "every node that got feedback reaches a final status, and says nothing after "
         "it", "14.5 Feedback Messages", E, X, C,
         "Final: succeeded, failed, aborted, and revoked (a node of the tree that will never "
         "run, e.g. a seq child after a failed sibling). not-active, active, waiting, running "
         "and paused are not final."),
    Rule("TST-010", "a composite node's final status follows its children's",
         "14 TST Execution API JSON", E, X, C,
         "seq runs its children in order and fails when a child fails (the rest revoked); "
         "conc runs them in parallel and succeeds when all succeed (when one fails the others "
         "are aborted). A node succeeds only if every child that ran succeeded; else it fails "
         "if one failed, else it is aborted. $enough ends a composite successfully."),
    Rule("TST-011", "signal-tst-node, signal-tst-tree and signal-unit are answered 'ok', or "
         "'failed' with a reason for an unknown node or a tree that has ended",
         "14.3, 14.4.1-14.4.3", E, X, C,
         "A reboot forgets the trees (as 12.1's history): afterwards their nodes are unknown."),
    Rule("TST-012", "$abort, $pause, $continue and $enough act on the nodes signalled",
         "14.3, 14.5", E, X, C,
         "$abort -> aborted, $pause -> paused, $continue -> running again, $enough -> the "
         "node ends as succeeded (12.2.2's meanings, with 14.5's statuses). signal-tst-tree "
         "signals the tree of the root node-uuid, signal-unit every running node of the unit."),
    Rule("TST-013", "tst_execution_info lists exactly the TST nodes that run",
         "2.7, 3.1 (tst_execution_info is named, not defined)", W, X, C,
         "Not in v0.7 (ERR-011). Modelled on 5.3's tasks-executing: 'nodes-executing', a list "
         "of {node-name, node-uuid, root-uuid}. A unit without the field is not judged; one "
         "that has it lists exactly the nodes not yet in a final status (warns otherwise)."),
    Rule("TST-014", "a start-tst tree is well formed", "14.3.4, 11", E, X, P,
         "Judges the commander. Every node has a name; children is a list; seq and conc have "
         "children and task nodes none; node-uuids are not used twice; common_params and "
         "common-params do not disagree. A node without node-uuid is allowed (14.3.4 only "
         "says it is best set): the unit generates one.", side=K),
    # --- errata of section 14 (issue 10) -------------------------------------------------------
    Rule("ERR-015", "start-tst is answered 'started'", "14.4.4 vs practice", W, X, P,
         "14.4.4 answers 'started'; units seen in practice answer 'running' (12.3.3's word for "
         "start-task). 'started' is canonical; 'running' is accepted with a warning (strict: "
         "fail) and, like 'started', opens the tree's conversation (TST-004)."),
    Rule("ERR-016", "TST commands go to a tst/command topic, not exec/command",
         "14.1 vs practice", W, X, P,
         "14.1 allows op0's tst/command (usual) and the executing unit's own (the reference "
         "unit listens on its own, and with --tst-operator on the operator's, where it acts "
         "only on commands that concern it and answers on the operator's tst/response and "
         "tst/feedback). start-tst sent to exec/command (seen in a commander GUI) is not one "
         "of 12.1's commands: a unit refuses it 'failed' naming tst/command; a commander "
         "sending it warns (strict: fail).", side=K),
    Rule("ERR-017", "unit names in TST commands are written '/NAME'", "14.3.3, 11", W, X, P,
         "14.3.3 writes signal-unit's unit '/dji21' and 11 every execunit '/op0': a ROS "
         "namespace, not a topic (3.2's no-leading-'/' is about topics). '/NAME' is canonical; "
         "a unit also understands the bare 'NAME'; a commander writing it warns (strict: fail).", side=K),
    Rule("ERR-018", "tst_execution_info's type is 'TstExecutionInfo'", "3.1 vs practice",
         W, X, P,
         "v0.7 defines no type (ERR-011). As HeartBeat, SensorInfo, DirectExecutionInfo name "
         "their topics, 'TstExecutionInfo' is canonical; 'TSTExecutionInfo' (seen) is accepted "
         "with a warning (strict: fail); any other type fails TEI-001."),
)

CATALOGUE: dict[str, Rule] = {rule.id: rule for rule in _CATALOGUE}
assert len(CATALOGUE) == len(_CATALOGUE), "duplicate rule id"


def get(rule_id: str) -> Rule:
    """The rule with this id; KeyError names close matches."""
    try:
        return CATALOGUE[rule_id]
    except KeyError:
        import difflib

        close = difflib.get_close_matches(rule_id, CATALOGUE, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise KeyError(f"unknown rule id {rule_id!r}{hint}") from None


def rules(*, level: Level | None = None, mode: Mode | None = None) -> list[Rule]:
    """The catalogue in id order, optionally filtered by level and mode."""
    return [
        r for r in _CATALOGUE
        if (level is None or r.level is level) and (mode is None or r.mode is mode)
    ]

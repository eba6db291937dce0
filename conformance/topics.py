"""Topic grammar of spec section 3: unit addresses, topic kinds and the naming conventions;
the vocabularies of 5.1 (agent types, levels).

    PREFIX1/unit/<agent-type>/<role>/<unit>/<subtopic...>

``UnitAddress`` is a frozen value that validates itself; ``parse_topic`` classifies any topic
and never raises; ``naming_violations`` checks section 3.2.
"""

from __future__ import annotations

import difflib
import enum
import functools
import re
from dataclasses import dataclass

from conformance.display import printable
from conformance.violation import Violation

AGENT_TYPES = ("air", "ground", "surface", "subsurface")  # 5.1
ROLES = ("real", "simulation", "playback")  # 3.1 ("..." : open list, TOPIC-006 warns)
MANDATORY_SENSORS = ("position", "heading", "course", "speed")  # 6.1

# 5.1: the levels a heartbeat declares in `levels`, spelled as 5.1 does (ERR-008: a space).
SENSOR_LEVEL = "sensor"
DIRECT_EXECUTION = "direct execution"
TST_EXECUTION = "tst execution"
DELEGATION = "delegation"
LEVELS = (SENSOR_LEVEL, DIRECT_EXECUTION, TST_EXECUTION, DELEGATION)


def level_name(declared: str) -> str:
    """A level as a heartbeat declares it, in 5.1's words: ``direct_execution`` is read as
    ``direct execution`` (ERR-008: the spec spells it both ways)."""
    return declared.replace("_", " ")


class TopicKind(str, enum.Enum):
    """What a topic under a unit carries (3.1, 5, 6, 12, 14)."""

    HEARTBEAT = "heartbeat"
    SENSOR_INFO = "sensor_info"
    DIRECT_EXECUTION_INFO = "direct_execution_info"
    TST_EXECUTION_INFO = "tst_execution_info"
    SENSOR = "sensor"
    EXEC_COMMAND = "exec/command"
    EXEC_RESPONSE = "exec/response"
    EXEC_FEEDBACK = "exec/feedback"
    TST_COMMAND = "tst/command"
    TST_RESPONSE = "tst/response"
    TST_FEEDBACK = "tst/feedback"
    UNKNOWN = "unknown"
    """A subtopic the spec does not define (TOPIC-007), or a topic not under a unit."""


_FIXED_SUBTOPICS = {
    "heartbeat": TopicKind.HEARTBEAT,
    "sensor_info": TopicKind.SENSOR_INFO,
    "sensor.info": TopicKind.SENSOR_INFO,  # ERR-001: 5.2's spelling, accepted with a warning
    "direct_execution_info": TopicKind.DIRECT_EXECUTION_INFO,
    "tst_execution_info": TopicKind.TST_EXECUTION_INFO,
    "exec/command": TopicKind.EXEC_COMMAND,
    "exec/response": TopicKind.EXEC_RESPONSE,
    "exec/feedback": TopicKind.EXEC_FEEDBACK,
    "tst/command": TopicKind.TST_COMMAND,
    "tst/response": TopicKind.TST_RESPONSE,
    "tst/feedback": TopicKind.TST_FEEDBACK,
}

# The periodic info messages and the level of 5.1 each one backs (HB-008).
INFO_KIND_OF_LEVEL = {
    SENSOR_LEVEL: TopicKind.SENSOR_INFO,
    DIRECT_EXECUTION: TopicKind.DIRECT_EXECUTION_INFO,
    TST_EXECUTION: TopicKind.TST_EXECUTION_INFO,
}

# 3.2: words joined by '_'. A word is letters and digits of any script ('båt0'): 3.2 names no
# character set; refusing non-ASCII is TOPIC-008's decision, not 3.2's words.
_NAME = re.compile(r"^[^\W_]+(_[^\W_]+)*$")
_BAD_CHARS = re.compile(r"[#+\s\x00-\x1f\x7f]|[^\x00-\x7f]")


class TopicError(ValueError):
    """A string that is not a unit address; the message says what is wrong and how to fix it."""


MAX_TOPIC_BYTES = 65535
"""The longest topic MQTT carries, in UTF-8 bytes (MQTT 3.1.1 1.5.3: a length-prefixed
string)."""
_NOT_IN_TOPIC = re.compile("[\x00\ud800-\udfff]")
"""What no topic may hold (MQTT 3.1.1 1.5.3): U+0000, and what UTF-8 cannot encode."""


def _quoted(text: str) -> str:
    """``text`` quoted for an error message, escaped (``display.printable``), then excerpted
    when long (a 100 KB option value; an escaped code point may take 10 characters)."""
    shown = printable(text)
    return f"'{shown}'" if len(shown) <= 200 else f"'{shown[:200]}'... ({len(text)} chars)"


def _level_problem(text: str, option: str) -> str | None:
    """Why ``text`` cannot be an MQTT topic name or filter (``option`` names what it is), or
    None: it is empty, too long, or holds U+0000 or an unencodable code point."""
    if not text:
        return f"{option} is empty"
    bad = _NOT_IN_TOPIC.search(text)
    if bad:
        return (f"{option} {_quoted(text)} holds U+{ord(bad.group()):04X}, which no MQTT topic "
                f"may hold (MQTT 3.1.1 1.5.3)")
    if len(text.encode("utf-8")) > MAX_TOPIC_BYTES:
        return (f"{option} {_quoted(text)} is longer than an MQTT topic can be "
                f"({MAX_TOPIC_BYTES} bytes)")
    return None


def filter_problem(text: str, option: str = "--topic") -> str | None:
    """Why ``text`` is not an MQTT subscription filter (MQTT 3.1.1 4.7.1: '+' a whole level,
    '#' a whole level and the last one), or None."""
    problem = _level_problem(text, option)
    if problem:
        return problem
    levels = text.split("/")
    for i, level in enumerate(levels):
        if "#" in level and (level != "#" or i != len(levels) - 1):
            return (f"{option} {_quoted(text)} is not an MQTT subscription filter ('#' only as "
                    f"the whole last level, e.g. waraps/#)")
        if "+" in level and level != "+":
            return (f"{option} {_quoted(text)} is not an MQTT subscription filter ('+' only as "
                    f"a whole level, e.g. waraps/unit/+/real/#)")
    return None


@dataclass(frozen=True, order=True)
class UnitAddress:
    """Where a unit lives: ``waraps/unit/air/simulation/dji0`` (spec 3.1).

    >>> UnitAddress.parse("waraps/unit/air/real/dji0").topic("exec/command")
    'waraps/unit/air/real/dji0/exec/command'
    """

    prefix: str
    agent_type: str
    role: str
    name: str

    @classmethod
    def parse(cls, text: str) -> UnitAddress:
        """Parse ``PREFIX1/unit/TYPE/ROLE/UNIT``; raise ``TopicError`` with a fix otherwise."""
        parts = text.strip().strip("/").split("/")
        if len(parts) != 5 or parts[1] != "unit" or not all(parts):
            raise TopicError(
                f"{_quoted(text)} is not a unit address; expected PREFIX1/unit/TYPE/ROLE/UNIT "
                f"(spec 3.1), for example waraps/unit/air/simulation/dji0"
            )
        problem = _level_problem(text, "unit address")
        if problem:
            raise TopicError(problem)
        if "+" in text or "#" in text:  # a topic name holds no wildcard (MQTT 3.1.1 4.7.1)
            raise TopicError(f"{_quoted(text)} is not a unit address: '+' and '#' are the "
                             f"wildcards of subscriptions, never in a unit's topics")
        prefix, _, agent_type, role, name = parts
        if agent_type not in AGENT_TYPES:
            raise TopicError(
                f"{_quoted(text)}: agent type {_quoted(agent_type)} is not one of "
                f"{', '.join(AGENT_TYPES)} "
                f"(spec 5.1)"
            )
        return cls(prefix, agent_type, role, name)

    @property
    def base(self) -> str:
        return f"{self.prefix}/unit/{self.agent_type}/{self.role}/{self.name}"

    def __str__(self) -> str:
        return self.base

    def topic(self, subtopic: str) -> str:
        """The full topic of a subtopic of this unit, e.g. ``heartbeat`` or ``sensor/speed``."""
        return f"{self.base}/{subtopic}"

    @property
    def is_real(self) -> bool:
        """Whether this unit is taken for hardware when nothing else is known: every role but
        ``simulation`` (docs/ARCHITECTURE.md 'Safety': fail closed; 3.1 lists real, simulation,
        playback, and a role outside the list only warns). A profile may name more simulated roles:
        ``Profile.is_simulation``."""
        return self.role != "simulation"

    def with_name(self, name: str) -> UnitAddress:
        return UnitAddress(self.prefix, self.agent_type, self.role, name)


@dataclass(frozen=True)
class ParsedTopic:
    """A classified topic. ``unit`` is None when the topic is not under ``PREFIX1/unit/``."""

    topic: str
    kind: TopicKind
    unit: UnitAddress | None = None
    sensor: str = ""
    """The SENSOR name for ``.../sensor/SENSOR`` topics."""
    subtopic: str = ""


LONG_TOPIC = 1024
"""A topic longer than this (MQTT allows 64 KiB) is parsed each time, never cached: 8192
cached 64 KiB topics would hold 2 GiB."""


def parse_topic(topic: str) -> ParsedTopic:
    """Classify a topic. Never raises: what cannot be placed is ``TopicKind.UNKNOWN``."""
    return _parse_cached(topic) if len(topic) <= LONG_TOPIC else _parse(topic)


def _parse(topic: str) -> ParsedTopic:
    parts = topic.split("/")
    if parts and parts[0] == "":  # TOPIC-001: leading '/'; classify the rest anyway
        parts = parts[1:]
    if len(parts) < 6 or parts[1] != "unit":
        return ParsedTopic(topic, TopicKind.UNKNOWN)
    prefix, _, agent_type, role, name = parts[:5]
    unit = UnitAddress(prefix, agent_type, role, name)
    sub = "/".join(parts[5:])
    kind = _FIXED_SUBTOPICS.get(sub)
    if kind is not None:
        return ParsedTopic(topic, kind, unit, subtopic=sub)
    if parts[5] == "sensor" and len(parts) == 7 and parts[6]:
        return ParsedTopic(topic, TopicKind.SENSOR, unit, sensor=parts[6], subtopic=sub)
    return ParsedTopic(topic, TopicKind.UNKNOWN, unit, subtopic=sub)


# A fleet reuses a few thousand topics millions of times: parse each once (bounded cache;
# ParsedTopic and UnitAddress are frozen, so sharing them is safe). bench/bench_lint.py.
_parse_cached = functools.lru_cache(maxsize=8192)(_parse)


GENERAL_NAMING_RULES = ("TOPIC-001", "TOPIC-002", "TOPIC-008")
"""The naming rules ``naming_violations`` examines on every topic."""
UNIT_NAMING_RULES = GENERAL_NAMING_RULES + ("TOPIC-003", "TOPIC-004", "TOPIC-005", "TOPIC-006",
                                            "TOPIC-007")
"""... and on every topic of a unit (ERR-001 too on its sensor_info topic)."""


def naming_rules(parsed: ParsedTopic) -> tuple[str, ...]:
    """The rules ``naming_violations`` examined on this topic (each passes where it found
    nothing)."""
    if parsed.unit is None:
        return GENERAL_NAMING_RULES
    if parsed.kind is TopicKind.SENSOR_INFO:
        return UNIT_NAMING_RULES + ("ERR-001",)
    return UNIT_NAMING_RULES


def naming_violations(topic: str) -> list[Violation]:
    """Every section-3 naming rule the topic breaks (TOPIC-*, ERR-001).

    PREFIX1 is exempt from TOPIC-003: 3.1's own examples of it are 'waraps-demo-2021' and
    'aiics-testing'. The levels this spec names (unit, type, role, subtopics, sensors) and the
    unit name follow 3.2.
    """
    # A fresh list: callers append to it. A long topic is not cached (LONG_TOPIC).
    return list(_naming_cached(topic) if len(topic) <= LONG_TOPIC else _naming_violations(topic))



def _did_you_mean(word: str, known: tuple[str, ...], lead: str = "") -> str:
    """``did you mean 'simulation'?`` for a near miss of one of ``known`` ('' for none)."""
    close = difflib.get_close_matches(word.lower(), known, n=1, cutoff=0.7)
    return f"{lead}did you mean {close[0]!r}?" if close else ""

def _naming_violations(topic: str) -> tuple[Violation, ...]:
    found: list[Violation] = []

    def bad(rule: str, expected: str, observed: str, detail: str = "") -> None:
        found.append(Violation.of(rule, expected=expected, observed=observed, topic=topic,
                                  detail=detail))

    if _BAD_CHARS.search(topic):
        bad("TOPIC-008", "printable ASCII without '#', '+' or spaces",
            repr(_BAD_CHARS.search(topic).group()))  # type: ignore[union-attr]
    if topic.startswith("/"):
        bad("TOPIC-001", "a topic that starts with a name (waraps/...)", topic,
            "remove the leading '/'")
    if topic != topic.lower():
        bad("TOPIC-002", "all lowercase", topic)
    parts = topic.lstrip("/").split("/")
    if len(parts) < 2 or parts[1] != "unit":
        return tuple(found)  # not unit traffic: only the general rules apply
    if len(parts) < 6 or not all(parts):
        bad("TOPIC-004", "PREFIX1/unit/TYPE/ROLE/UNIT/<subtopic> with no empty level", topic)
        return tuple(found)
    _, _, agent_type, role, name = parts[:5]
    if agent_type.lower() not in AGENT_TYPES:
        bad("TOPIC-005", " | ".join(AGENT_TYPES), agent_type, _did_you_mean(agent_type,
                                                                             AGENT_TYPES))
    if role.lower() not in ROLES:
        bad("TOPIC-006", " | ".join(ROLES), role, "3.1 lists real, simulation, playback"
            + _did_you_mean(role, ROLES, "; "))
    sub = "/".join(parts[5:])
    if sub == "sensor.info":
        bad("ERR-001", "sensor_info", "sensor.info", "5.2 writes sensor.info; 3.1 sensor_info")
    for level in [name, *parts[5:]]:
        if level == "sensor.info":
            continue
        if not _NAME.match(level.lower()):
            bad("TOPIC-003", "lowercase words joined by '_'", level)
    parsed = parse_topic(topic)
    if parsed.kind is TopicKind.UNKNOWN:
        bad("TOPIC-007", "heartbeat, sensor_info, direct_execution_info, tst_execution_info, "
            "sensor/<name>, exec/*, tst/*", sub)
    return tuple(found)
_naming_cached = functools.lru_cache(maxsize=8192)(_naming_violations)



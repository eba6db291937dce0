"""Why the unit under test is not alive: a read-only look under its prefix while the suite
waits for its first heartbeat, and the error message that look allows (a typo in the address,
a unit breaking spec 3's naming, or nothing there at all)."""

from __future__ import annotations

import difflib

from conformance.client import BrokerError, BrokerURL, MqttClient
from conformance.display import printable
from conformance.message import Message
from conformance.profile import Profile
from conformance.rules import CATALOGUE
from conformance.topics import UnitAddress
from conformance.validator import Validator

MAX_PROBE_TOPICS = 500
MAX_PROBE_PAYLOAD = 65536
"""Bytes kept of the first payload seen on each topic."""


class NotAlive(Exception):
    """The unit under test sent no heartbeat in time; the message says what was seen."""


class Probe:
    """A read-only look at ``<prefix>/#`` while waiting for the unit: which topics exist (with
    the first payload of each), for the error message when the unit is not there. Never
    publishes; keeps at most 500 topics and 64 KiB of each payload."""

    def __init__(self, broker: BrokerURL, unit: UnitAddress) -> None:
        self._topics: dict[str, bytes] = {}
        self._client: MqttClient | None = None
        self._broker, self._unit = broker, unit

    def start(self) -> None:
        def seen(m: Message) -> None:
            if m.topic not in self._topics and len(self._topics) < MAX_PROBE_TOPICS:
                self._topics[m.topic] = m.payload[:MAX_PROBE_PAYLOAD]
        try:
            self._client = MqttClient(self._broker, on_message=seen).connect()
            self._client.subscribe(f"{self._unit.prefix}/#")
            self._client.subscribe(f"/{self._unit.prefix}/#")  # TOPIC-001: a leading '/'
        except BrokerError:
            self._client = None

    def topics(self) -> dict[str, bytes]:
        return dict(self._topics)

    def close(self) -> None:
        if self._client is not None:
            self._client.close()


def not_alive(unit: UnitAddress, profile: Profile, broker: BrokerURL, *, waited: float,
              own_subtopics: set[str], seen: dict[str, bytes], timing_scale: float,
              revived: str | None = None) -> str:
    """What to tell the person whose unit sent no live heartbeat within ``waited`` seconds:
    what of it was seen, a unit at a close address, the naming rules its topics break, and
    how a restart went (``revived``; None: there was no way to restart it)."""
    topic = unit.topic("heartbeat")
    lines = [f"the unit {unit} is not alive: no heartbeat on {topic} within "
             f"{waited:.1f} s (broker {broker})."]
    if own_subtopics:
        lines.append(f"Its own topics were seen ({printable(', '.join(sorted(own_subtopics)))}"
                     f"), but no live heartbeat (retained ones do not count).")

    others = sorted({_base(t) for t in seen if t.lstrip("/").split("/")[1:2] == ["unit"]
                     and len(t.lstrip("/").split("/")) > 5} - {unit.base})
    prefix = unit.prefix
    # Only a unit whose address is close to this one is worth a line (a typo, a leading
    # '/', another role or type): other units' topics say nothing about this one.
    close = difflib.get_close_matches(unit.base, others, n=1, cutoff=0.8)
    if close:
        if _is_address(close[0]):
            lines.append(f"A unit publishes at {printable(close[0])}: did you mean --unit "
                         f"{printable(close[0])}?")
        else:
            lines.append(f"A unit publishes at {printable(close[0])}.")
        broken = _naming_broken(profile, seen, close[0])
        if broken:
            lines.append("Its topics break: " + "; ".join(broken[r] for r in sorted(broken)))
    elif others:
        lines.append(f"{len(others)} other unit(s) publish under {prefix}/, none at a "
                     "similar address.")
    if not seen:
        lines.append(f"Nothing at all was published under {prefix}/ meanwhile: is the unit "
                     f"running and connected to this broker, under this prefix?")
    if revived:
        lines.append(f"It was {revived}.")
    elif own_subtopics or not close:
        lines.append("If an earlier run left it dead (HB-012), restart it, or pass "
                     "--reboot-cmd 'COMMAND' and the suite restarts it before judging it.")
    if timing_scale == 1.0:
        lines.append("On a slow link, give it longer with --timing-scale 3.")
    return "\n".join(lines)


def _base(topic: str) -> str:
    """The unit address a topic is under (its first five levels)."""
    lead = "/" if topic.startswith("/") else ""
    return lead + "/".join(topic.lstrip("/").split("/")[:5])


def _naming_broken(profile: Profile, seen: dict[str, bytes], address: str) -> dict[str, str]:
    """Rule -> a line: the rules the topics seen under ``address`` break (a unit publishing
    where it should not, a leading '/', an unknown agent type or role, breaks the naming
    rules of spec 3: that is the finding)."""
    broken: dict[str, str] = {}
    validator = Validator(profile)
    for topic, payload in sorted(seen.items()):
        if _base(topic) != address:
            continue
        for v in validator.validate(topic, payload).violations:
            if profile.severity_of(v.rule).value == "error":
                broken.setdefault(v.rule, f"{v.rule} {CATALOGUE[v.rule].title} ({printable(topic)})")
    return broken


def _is_address(text: str) -> bool:
    try:
        UnitAddress.parse(text)
    except ValueError:
        return False
    return not text.startswith("/")

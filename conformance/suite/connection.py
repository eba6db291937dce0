"""A certification's link to the broker: the reference pair first under ``--broker embedded``,
then the suite's one MQTT client with its publish policy (docs/ARCHITECTURE.md 'Safety'), the wait
for the unit's first live heartbeat, and the connection gaps marked in the Monitor.

Data flows one way, so lint and the suite judge the same evidence alike: every message of
``<unit>/#`` goes to the ``Monitor`` (the same passive checks as the linter) and to ``Traffic``
(which the scenarios wait on).
"""

from __future__ import annotations

import statistics
import threading
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import orjson

from conformance.checks import Monitor
from conformance.checks.stall import LAG_JUMP, stamp_of
from conformance.client import BrokerURL, MqttClient
from conformance.clock import VirtualClock
from conformance.message import Message
from conformance.scenarios import Traffic
from conformance.scenarios.params import task_moves
from conformance.scenarios.reboot import intervals
from conformance.scenarios.safety import MotionGate
from conformance.scenarios.sender import Sender
from conformance.scenarios.traffic import LAG_SLACK
from conformance.sim.reference import Reference
from conformance.sim.virtual import VirtualClient, VirtualReference
from conformance.suite.events import Events, clock
from conformance.suite.probe import NotAlive, Probe, not_alive
from conformance.suite.settings import Settings
from conformance.topics import UnitAddress
from conformance.violation import Violation

MAX_INTERVALS = 20
"""Heartbeats whose intervals say how long a unit takes to be heard again (the latest)."""
HEARD_AGAIN = 5.0
"""Seconds a command waits for the unit to be heard again after a reconnect or a stall (and
two of its longest heartbeat intervals): paho's backoff after a 5 s outage brings a unit back
within about 2 s of the broker."""
SLOW_HEARTBEAT_WAITS = 2.0
"""A unit whose other topics are live while its first heartbeat is awaited is there, its
heartbeat maybe slow (a public operator's is 0.2 Hz): it gets this many first waits more
before it is judged not alive (our decision; the spec gives no deadline)."""
MAX_HEARTBEAT_BYTES = 64 * 1024
"""A heartbeat larger than this is not read for its stamp (``_fresh``; the Monitor judges it)."""

if TYPE_CHECKING:
    from conformance.sim.reference import Reference
    from conformance.sim.virtual import VirtualClient, VirtualReference

HOLDS_SAID = 5
"""Holds of the bundled reference unit said in the summary at most (each is a gap all the same)."""

Revive = tuple[str, float, Callable[[], "str | None"]]
"""How a unit that is not alive is restarted before the run: (how, in the words of the option;
seconds to wait for its heartbeat after; the restart, returning None or what went wrong)."""


@dataclass(eq=False)
class Connection:
    """The suite's connection for one certification; ``open`` it, then ``publish``."""

    settings: Settings
    monitor: Monitor
    traffic: Traffic
    monitor_lock: AbstractContextManager[Any]
    """Held while the Monitor is fed or read (the MQTT network thread feeds it)."""
    events: Events
    client: MqttClient | VirtualClient | None = field(default=None, init=False)
    reference: Reference | VirtualReference | None = field(default=None, init=False)
    """The bundled reference unit and its broker, under --broker embedded (or virtual)."""
    listeners: list[Callable[[list[Violation]], None]] = field(default_factory=list,
                                                                init=False)
    """Told the violations the Monitor finds in each message (the exploration's oracle)."""
    say: Callable[[str], None] = field(default=lambda text: None, init=False)
    """Writes a line on the terminal (the certification's)."""
    _alive: bool = field(default=False, init=False)
    _others_live: bool = field(default=False, init=False)
    """Whether a live message of the unit other than its heartbeat came (``open``)."""
    _alive_changed: threading.Condition = field(default_factory=threading.Condition, init=False)
    _gap_start: float | None = field(default=None, init=False)
    _linked: bool = field(default=False, init=False)
    """Whether the broker ever accepted the connection (before that, nothing can be lost)."""
    _unechoed: float | None = field(default=None, init=False)
    """When the earliest command the suite published that has not come back was sent: the
    broker delivers a subscriber's own messages back, so one that does not is not delivering
    (a stall)."""
    _echoed: threading.Event = field(default_factory=threading.Event, init=False)
    _heard_again: threading.Event = field(default_factory=threading.Event, init=False)
    """Clear from a reconnect (or a stall) until the unit's second fresh heartbeat after it
    (``_fresh``): it reconnects on its own time, and a command sent before it has (or
    subscribed again: its first heartbeat may be one it held, sent before its subscription;
    or before a stalled broker has worked off what it held) is lost."""
    _signal: threading.Condition = field(default_factory=threading.Condition, init=False)
    """Notified when ``_echoed`` or ``_heard_again`` is set: waited on the run's clock."""
    _beats_back: int = field(default=0, init=False)
    """Paced heartbeats since the last reconnect or stall (``_away``)."""
    _pace: float = field(default=0.5, init=False)
    """Seconds between two heartbeats' arrivals for the later one to be paced, not part of
    a burst of held ones: half the unit's period (for a unit without stamps)."""
    _lag: float | None = field(default=None, init=False)
    """How far the unit's last heartbeat stamp before ``_away`` lagged its arrival."""
    _last_beat: float | None = field(default=None, init=False)
    _away_at: float | None = field(default=None, init=False)
    """Since when the unit is away (``_away``), None once heard again."""
    _mended: int = field(default=0, init=False)
    """How often the unit was heard again after a reconnect (``gaps``)."""
    _gave_up: bool = field(default=False, init=False)
    """Whether a command already waited in vain for the unit since the last reconnect."""
    _last_arrival: float | None = field(default=None, init=False)
    _probed: float | None = field(default=None, init=False)
    _holds: int = field(default=0, init=False)
    """How often the host held the bundled reference unit (``host_held``)."""
    """The last heartbeat whose silence was probed with a ping (once per silence)."""

    def __post_init__(self) -> None:
        self.broker_url: BrokerURL = self.settings.broker
        """The broker connected to (under --broker embedded: the embedded one's address)."""
        self.motion = MotionGate(self.unit, self.settings.profile,
                                 allow_motion=self.settings.allow_motion,
                                 allow_hostile=self.settings.allow_hostile,
                                 listed=self._tasks_listed, task_moves=task_moves)
        """What may not be said to a real unit (docs/ARCHITECTURE.md 'Safety'), asked about every
        payload."""
        self._heard_again.set()  # no reconnect yet

    def host_held(self, start: float, end: float) -> None:
        """The host held the bundled reference unit's thread from ``start`` to ``end`` (or a
        unit a test runs in the suite's process: ``Runtime.on_hold``): a silence then is the
        loaded machine's, not the unit's, and is not judged. Said when it is long enough to
        matter, at most ``HOLDS_SAID`` times. Runs on the unit's thread."""
        with self.monitor_lock:
            self.monitor.host_held(start, end)
            self._holds += 1
            said = self._holds <= HOLDS_SAID and end - start >= 1.0
        if said:
            self.events.at(start, f"the host held the bundled reference unit {end - start:.1f} s "
                           f"(a loaded machine): that time is not judged")

    @property
    def unit(self) -> UnitAddress:
        return self.settings.unit

    def open(self, alive_timeout: float, revive: Revive | None = None) -> None:
        """Connect, observe ``<unit>/#`` and wait up to ``alive_timeout`` seconds for the
        unit's first live heartbeat. A unit that sends none is restarted once by ``revive``
        (``--reboot-cmd``: an earlier run may have left it dead) before it is judged not alive.

        Raises ``BrokerError`` (broker unreachable or refusing) or ``NotAlive``."""
        s = self.settings
        if s.virtual:
            self._open_virtual()
        elif s.embedded:
            # Imported here: the broker and the simulator load only for --broker embedded.

            self.reference = Reference(self.unit, faults=s.sim_faults,
                                       variants=s.sim_variants, rate=s.sim_rate,
                                       seed=s.seed, tst=s.sim_tst,
                                       tst_operator=s.tst_operator).start()
            self.broker_url = BrokerURL.parse(self.reference.url)
            self.reference.sim.runtime.on_hold = self.host_held
        probe = None if s.virtual else self._open_mqtt()
        try:
            if not self._wait_alive(alive_timeout) and self._others_live:
                more = SLOW_HEARTBEAT_WAITS * alive_timeout
                self.say(f"{self.unit}: its other topics are live, but no heartbeat came "
                         f"within {alive_timeout:.0f} s: waiting up to {more:.0f} s more (a "
                         f"slow heartbeat? the profile's alive-timeout sets the first wait)")
                alive_timeout += more
                self._wait_alive(more)
            if not self._alive:
                revived = self._revive(revive, alive_timeout) if revive else None
                if revived is None or revived[1]:
                    raise NotAlive(not_alive(
                        self.unit, s.profile, self.broker_url, waited=alive_timeout,
                        own_subtopics=self.traffic.subtopics(),
                        seen=probe.topics() if probe else {},
                        timing_scale=s.timing_scale,
                        revived=revived[1] if revived else None))
        finally:
            if probe is not None:
                probe.close()

    def _open_mqtt(self) -> Probe:
        """Connect the suite's client; returns the probe that notes what else is seen."""
        s = self.settings
        probe = Probe(self.broker_url, self.unit)
        self.client = MqttClient(self.broker_url, on_message=self._on_message,
                                 may_publish=self.may_publish,
                                 refuse_payload=self.refuse_payload,
                                 on_connection_change=self._on_connection)
        self.client.connect(timeout=5.0 * s.timing_scale)
        self.client.subscribe(self.unit.base + "/#")
        if s.tst_operator is not None:  # 14.1: commands and answers there
            self.client.subscribe(s.tst_operator.base + "/tst/#")
        probe.start()
        return probe

    def _open_virtual(self) -> None:
        """--broker virtual: the reference unit and an in-memory broker on the traffic's
        virtual clock (the test suite's matrices only: ``conformance.sim.virtual``)."""
        s = self.settings
        clock = self.traffic.clock
        assert isinstance(clock, VirtualClock), "--broker virtual runs in virtual time"
        self.reference = reference = VirtualReference(
            self.unit, clock=clock, faults=s.sim_faults, variants=s.sim_variants, rate=s.sim_rate,
            seed=s.seed, tst=s.sim_tst, tst_operator=s.tst_operator).start()
        self.client = VirtualClient(reference.broker, self._on_message, self.may_publish,
                                    self.refuse_payload, self._on_connection)
        self.client.subscribe(self.unit.base + "/#")
        if s.tst_operator is not None:  # 14.1: commands and answers there
            self.client.subscribe(s.tst_operator.base + "/tst/#")

    def _wait_alive(self, timeout: float) -> bool:
        """Whether the unit's first live heartbeat came within ``timeout`` seconds."""
        clock = self.traffic.clock
        end = clock.monotonic() + timeout
        with self._alive_changed:
            while not self._alive and (left := end - clock.monotonic()) > 0:
                clock.wait(self._alive_changed, left)
            return self._alive

    def _revive(self, revive: Revive, waited: float) -> tuple[str, str]:
        """Restart a unit that is not alive, and wait for its heartbeat: (how, "") when it
        came, else (how, what went wrong)."""
        how, timeout, restart = revive
        self.events.at(self.traffic.clock.now(), f"no heartbeat within {waited:.1f} s: "
                                                 f"restarting the unit before judging it")
        failure = restart()
        if failure is not None:
            return how, f"restarted with {how}, which failed: {failure}"
        if not self._wait_alive(timeout):
            return how, f"restarted with {how}; still no heartbeat {timeout:.0f} s later"
        self.events.at(self.traffic.clock.now(), f"the unit was not alive when the run began "
                                                 f"(an earlier run may have left it dead); "
                                                 f"restarted with {how}")
        return how, ""

    def _on_message(self, message: Message) -> None:
        """Every message of ``<unit>/#``, on the MQTT network thread: keep it quick."""
        heartbeat = not message.retain and message.topic == self.unit.topic("heartbeat")
        if not heartbeat and not message.retain and not message.topic.endswith("/command"):
            self._others_live = True  # the unit's own (a command is a commander's)
        if message.topic == self.unit.topic("exec/command"):
            if self._unechoed is not None:
                now = self.traffic.clock.now()  # the clock _unechoed was read on
                self._command_lag(max(0.0, now - self._unechoed), now)
            self._unechoed = None
            self._set(self._echoed)
        with self.monitor_lock:
            self._last_arrival = message.time
            if heartbeat and not self._heard_again.is_set():
                if self._fresh(message):
                    self._beats_back += 1
                if self._beats_back >= 2:
                    # The gap opened at the reconnect (or stall) ends here: the unit is back.
                    self.monitor.heard_again(message.time)
                    self._mended += 1
                    self._away_at = None
                    self.events.at(message.time, "the unit is heard again: judging resumes")
                    self._set(self._heard_again)
            if heartbeat:
                self._last_beat = message.time
            stalls = self.monitor.ctx.stalls.count
            found = self.monitor.feed(message)
            if self.monitor.ctx.stalls.count != stalls:
                self._say_stall(message.time)
        if found:
            for listener in list(self.listeners):
                listener(found)
        self.traffic.add(message)
        if heartbeat:
            with self._alive_changed:
                self._alive = True
                self._alive_changed.notify_all()

    def _say_stall(self, now: float) -> None:
        """A stall of the broker was found in the traffic (``checks/stall.py``)."""
        start, _ = self.monitor.ctx.stalls.found[-1]
        self.events.at(now, f"the broker stalled: nothing arrived for {now - start:.1f} s, "
                            f"then what it held at once: rates, silences and deadlines over "
                            f"it are not judged")

    def _on_connection(self, connected: bool, reason: str) -> None:
        now = self.traffic.clock.now()
        with self.monitor_lock:
            if connected:
                self._linked = True
            elif not self._linked:
                return  # refused at connect (the error says why): no link was lost
            if not connected:
                self._gap_start = now
                # Mark the gap at once: rates, silences and uuid changes across it are not
                # judged (the Monitor merges this with its end when the link comes back).
                self.monitor.connection_gap(now, now)
                if reason == "Unspecified error":  # paho's words for a socket that closed
                    reason = "the broker closed the connection or went away"
                self.events.at(now, f"broker connection lost ({reason})")
            elif self._gap_start is not None:
                start, self._gap_start = self._gap_start, None
                # Open until the unit is heard again: it reconnects on its own time, and what
                # it sent (or was sent) before it is back is unknown too.
                self.monitor.connection_gap(start, None)
                self._away()
                self.events.at(now, f"broker connection back after {now - start:.1f} s: "
                                    f"rates, silences and uuid changes over the gap, and "
                                    f"until the unit is heard again, are not judged")

    def _away(self) -> None:
        """The unit is away until heard again (after a reconnect, or a stall of the broker):
        its next two fresh heartbeats end the open gap (``monitor_lock`` held)."""
        beats = self.traffic.since(0, "heartbeat")[-MAX_INTERVALS:]
        self._pace = 0.5 * (statistics.median(intervals(beats) or [1.0]))
        stamp = stamp_of(beats[-1].body, beats[-1].time) if beats else None
        self._lag = beats[-1].time - stamp if stamp is not None else None
        self._beats_back, self._gave_up = 0, False
        self._away_at = self.traffic.clock.now()
        self._heard_again.clear()

    def away_since(self) -> float | None:
        """Since when the unit is not heard again after a reconnect or a stall; None while
        it is (the gap of the observation stays open until then)."""
        return self._away_at

    def _fresh(self, message: Message) -> bool:
        """Whether a heartbeat was sent now, not held by a stalled broker and delivered late
        (with what it held, at once or as it works off a backlog): its stamp lags its arrival
        no more than the unit's did before (``checks/stall.py``'s reading); for a unit
        without stamps, it came half a period or more after the one before."""
        body = None
        if len(message.payload) <= MAX_HEARTBEAT_BYTES:  # bounded: a unit's heartbeat is small
            try:
                body = orjson.loads(message.payload)
            except orjson.JSONDecodeError:  # (orjson refuses nesting past 1024 levels too)
                pass
        stamp = stamp_of(body, message.time)
        if stamp is not None and self._lag is not None:
            return message.time - stamp <= self._lag + LAG_JUMP
        return self._last_beat is None or message.time - self._last_beat >= self._pace

    def may_publish(self, topic: str) -> bool:
        # docs/ARCHITECTURE.md 'Safety': only the command topic of the unit under test, and the one
        # TST command topic the run was told (14.1: the unit's own, or an operator's).
        return topic == self.unit.topic("exec/command") or topic == self.settings.tst_topic

    def refuse_payload(self, topic: str, payload: bytes) -> str | None:
        # docs/ARCHITECTURE.md 'Safety': the policy, not each scenario, decides; malformed probes
        # included.
        return self.motion.refusal(payload, topic)

    def _tasks_listed(self) -> list[str]:
        """The task names the unit lists in tasks-available (5.3), as last seen."""
        info = self.traffic.latest("direct_execution_info")
        tasks = info.get("tasks-available") if info is not None else None
        names = (t.get("name") for t in tasks if isinstance(t, dict)) \
            if isinstance(tasks, list) else ()
        return [n for n in names if isinstance(n, str)]

    def _command_lag(self, lag: float, now: float) -> None:
        """The broker delivered the suite's command back ``lag`` seconds after it was sent;
        the terminal hears when it starts and stops being late (``Traffic.wait_for``)."""
        was, self.traffic.command_lag = self.traffic.command_lag, lag
        if (lag >= LAG_SLACK) != (was >= LAG_SLACK):
            self.events.at(now, f"the broker delivered the suite's command {lag:.1f} s after "
                                f"it was sent: waits for the unit's answers are lengthened as "
                                f"much" if lag >= LAG_SLACK else
                                "the broker delivers the suite's commands in time again")

    def publish(self, topic: str, payload: bytes) -> None:
        assert self.client is not None
        # QoS 1 without waiting for the PUBACK: the unit's answer is what the scenario waits
        # for, and paho resends an unacknowledged command after a reconnect.
        if self._unechoed is None and self._echoed.is_set() \
                and topic == self.unit.topic("exec/command") \
                and self.refuse_payload(topic, payload) is None:
            # (a payload the policy refuses is never sent, so never echoed: no stall)
            # Only once an echo was seen: a broker whose ACL hides the command topic from
            # the suite never echoes, and is no stall.
            self._unechoed = self.traffic.clock.now()
            self._echoed.clear()
        self.client.publish(topic, payload, qos=1, timeout=0)

    def lost_since(self) -> float | None:
        """When the link to the broker was lost, None while it is up."""
        return self._gap_start

    @property
    def is_connected(self) -> bool:
        return self.client is not None and self.client.is_connected

    def gaps(self) -> int:
        """How often the suite's path to the unit broke or mended: each link lost, and each
        time the unit was heard again after one. A command sent before a change of this count
        may never have reached the unit (the unit reconnects on its own time)."""
        return (len(self.client.gaps) if self.client else 0) + self._mended

    def wait_connected(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for the link (a command sent into a gap is lost),
        and after a reconnect (or a stall) up to ``HEARD_AGAIN`` seconds (times the timing
        scale) and two of its longest heartbeat intervals more for the unit to be heard again
        (it reconnects on its own time, by its own backoff; a command sent before it has is
        lost as well, and its silence is not judged: the gap stays open until then)."""
        if not (self.client and self.client.wait_connected(timeout)):
            return False
        if not self._heard_again.is_set() and not self._gave_up:
            clock = self.traffic.clock
            beats = self.traffic.since(0, "heartbeat")[-MAX_INTERVALS:]
            budget = HEARD_AGAIN * self.settings.timing_scale + 2 * max(intervals(beats),
                                                                        default=1.0)
            self.events.at(clock.now(), f"waiting up to {budget:.0f} s for the unit to be "
                                        f"heard again (two heartbeats) before the next command")
            if not self._wait(self._heard_again, budget):
                self.events.at(clock.now(), "the unit was not heard again: commands may be "
                                            "lost, and their silence is not judged, until it is")
                self._gave_up = True  # waited once: the next commands go out at once
                # (the gap stays open in the Monitor until the unit's heartbeats return)
        return True

    def _set(self, event: threading.Event) -> None:
        event.set()
        with self._signal:
            self._signal.notify_all()

    def _wait(self, event: threading.Event, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for ``event``, on the run's clock (virtual under
        --broker virtual: the broker double delivers only while the suite waits)."""
        clock = self.traffic.clock
        end = clock.monotonic() + timeout
        with self._signal:
            while not event.is_set() and (left := end - clock.monotonic()) > 0:
                clock.wait(self._signal, left)
        return event.is_set()

    def await_delivery(self, slack: float, budget: float, *, silent_periods: float = 3.0
                       ) -> float | None:
        """A command the suite sent has not come back within ``slack`` seconds: the broker
        stalls. Wait up to ``budget`` seconds for it to deliver again; the time since then is
        a gap of the observation either way (what the unit sent is unknown). None when it
        delivers, else when it stopped (it is then lost, as a link that never came back).
        A unit silent for ``silent_periods`` declared periods (3: HB-012's window; dead, or
        the broker frozen?) is sent one ping per silence, with nothing pending, to see
        whether the broker still delivers."""
        self._probe_silence(silent_periods)
        since = self._unechoed
        clock_now = self.traffic.clock.now
        if since is None or self._wait(self._echoed, max(0.0, since + slack - clock_now())):
            return None
        start = min(since, self._last_arrival or since)
        with self.monitor_lock:
            # Open at once: what the held burst brings is judged inside it; and after it,
            # until the unit is heard again (the burst may still be draining towards it).
            self.monitor.connection_gap(start, None)
            self._away()
        back = self._wait(self._echoed, budget)
        now = clock_now()
        self.events.at(now, f"the broker delivered nothing from {clock(start)} for "
                            f"{now - start:.1f} s (the suite's own command did not come back): "
                            f"{'it delivers again; ' if back else ''}what the unit sent "
                            f"meanwhile, and until it is heard again, is not judged")
        return None if back else start

    def _probe_silence(self, periods: float) -> None:
        """One ping when the unit has been silent for ``periods`` declared periods: its echo
        tells a dead unit from a broker that delivers nothing."""
        latest = self.traffic.latest("heartbeat")
        rate = latest.get("rate") if latest is not None else None
        if (latest is None or not isinstance(rate, (int, float)) or isinstance(rate, bool)
                or rate <= 0
                or latest.time == self._probed or self._unechoed is not None
                or not self._echoed.is_set() or self.settings.dry_run
                or self.traffic.clock.now() - latest.time <= periods / rate):
            return

        self._probed = latest.time
        self.publish(self.unit.topic("exec/command"), Sender.compose({"command": "ping"})[0])

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.reference is not None:
            self.reference.stop()
            self.reference = None

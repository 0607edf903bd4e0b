"""`reckon doctor`: checks a venue's set-up and says what is wrong in plain words (docs/doctor.md).

One `Check` per line: OK, WARN (works, but look at it) or FAIL (will not work), each with what to
do. Checks, in order:

- venue: the venue file loads (the loader's own message, with the key path), and its agents have
  the sensors their edges need;
- sources: each `--source` the edge would take, checked by its scheme's own `check`
  (edge/sources/registry.py): `SENSOR=serial://PORT?...` (the port exists and opens, then a short
  listen: do frames decode, at what rate), `SENSOR=ble://ADDRESS` and `RECEIVER=ble://scan` (bleak
  importable, an adapter present), `SENSOR=phone://HOST:PORT` (the port is free, the TLS
  certificate and the stand key are there), `mcap://FILE` (a readable log);
- chair kernels: where the venue has chairs, their merger and filter are compiled ahead of time for
  this machine (reckon/kernels.py);
- clock: this machine's kernel clock is synchronised (adjtimex);
- bus: a Zenoh session opens with the given options, a hub of the venue answers, and in a short
  window: the offset of the hub's and the edges' clocks from this one (Zenoh timestamps of their
  samples), and which agents' streams flow.

Bus limit: in peer mode (the default) a session sees only the processes it is linked to, so a
doctor linked to the hub sees the hub's outputs (`pose/live` per agent: proof that the agent's
edge reaches the hub) but not the edges' own streams; through a router (`--mode client`) it sees
those too, DeviceStatus included.
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import json
import math
import queue
import statistics
import time
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from edge.sources.registry import CheckRequest, Level, scheme
from protocol import bus as wire
from protocol import keys
from protocol.errors import ReckonError
from protocol.session import AgentKind, Mount, Session
from reckon.transport.config import BusConfig

CLOCK_WARN_MS = 50.0  # a tenth of the hub's 0.5 s collision pairing window
CLOCK_FAIL_MS = 500.0  # the whole pairing window: two chairs' impacts can no longer be paired
HUB_STREAMS = ("pose", "correction", "identity")  # what the hub publishes under an agent's key
EDGE_POSE = "pose/edge"  # the one pose stream an edge publishes
BLUETOOTH_SYSFS = Path("/sys/class/bluetooth")
LOW_BATTERY_PCT = 20.0
__all__ = ["Check", "DoctorSettings", "Level", "Report", "run_doctor"]  # Level: the sources' own (registry)


@dataclass(frozen=True)
class Check:
    """One finding: `name` is what was checked, `message` what was found, `fix` what to do."""

    name: str
    level: Level
    message: str
    fix: str = ""

    def line(self) -> str:
        return f"{self.level.value:<4} {self.name}: {self.message}" + (f" -> {self.fix}" if self.fix else "")


@dataclass(frozen=True)
class DoctorSettings:
    """What to check. `bus`: a Zenoh config (None: no bus check); the bus check needs the venue.
    Times in seconds: `listen_s` per serial device, `bus_timeout_s` for a hub to answer,
    `streams_s` watching the venue's traffic (0: not watched)."""

    venue: Path | None = None
    agent: str | None = None
    sources: tuple[str, ...] = ()
    bus: BusConfig | None = None
    listen_s: float = 1.0
    bus_timeout_s: float = 3.0
    streams_s: float = 2.0
    clock_warn_ms: float = CLOCK_WARN_MS
    bluetooth_sysfs: Path = BLUETOOTH_SYSFS  # where Linux lists Bluetooth adapters (a test points it elsewhere)


@dataclass
class Report:
    checks: list[Check] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(check.level is not Level.FAIL for check in self.checks)

    def add(self, name: str, level: Level, message: str, fix: str = "") -> None:
        self.checks.append(Check(name, level, message, fix))

    def text(self) -> str:
        fails = sum(c.level is Level.FAIL for c in self.checks)
        warns = sum(c.level is Level.WARN for c in self.checks)
        summary = f"{fails} FAIL, {warns} WARN, {len(self.checks) - fails - warns} OK"
        return "\n".join([c.line() for c in self.checks] + [summary])

    def to_json(self) -> dict[str, Any]:
        return {"ok": self.ok, "checks": [{**asdict(c), "level": c.level.value} for c in self.checks]}


def run_doctor(settings: DoctorSettings) -> Report:
    """Every check of `settings`; never raises for what it finds (that is a FAIL line)."""
    report = Report()
    session = check_venue(report, settings)
    check_sources(report, settings, session)
    check_chair_kernels(report, session)
    check_clock_sync(report)
    if settings.bus is None:
        return report
    if session is None:
        report.add("bus", Level.WARN, "not checked: the bus check needs the venue's name", "give --venue VENUE.toml")
    else:
        check_bus(report, settings.bus, settings, session)
    return report


# ---------------------------------------------------------------------------------------------
# The venue file


def check_venue(report: Report, settings: DoctorSettings) -> Session | None:
    from protocol.session_log import session_description  # light: a hub has no edge filters

    if settings.venue is None:
        report.add("venue", Level.WARN, "no venue file given; sensors and the bus cannot be checked against it",
                   "give --venue VENUE.toml")
        return None
    try:
        session = session_description(settings.venue)
    except ReckonError as error:
        report.add("venue", Level.FAIL, str(error), "fix that key; docs/session-format.md lists every key")
        return None
    sensors = sum(len(a.sensors) for a in session.agents)
    report.add("venue", Level.OK, f"{settings.venue}: venue {session.venue.name!r}, {len(session.agents)} agents, "
                                  f"{sensors} sensors, {len(session.venue.beacons)} beacons")
    needs = (Mount.SEAT, Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL)
    for agent in session.agents:
        if not agent.sensors:
            report.add(f"agent {agent.id}", Level.WARN, "has no sensors: its edge has nothing to read",
                       "add [[agents.sensors]] tables, or remove the agent")
        missing = [m.value for m in needs if agent.sensor(m) is None]
        if agent.kind is AgentKind.WHEELCHAIR and agent.sensors and missing:
            report.add(f"agent {agent.id}", Level.FAIL, f"a wheelchair without {', '.join(missing)}: its edge "
                       "refuses to start (the chair filter needs seat, left_wheel and right_wheel)",
                       "add the missing sensors, or set its kind")
    if settings.agent is not None and settings.agent not in {a.id for a in session.agents}:
        report.add("agent", Level.FAIL, f"--agent {settings.agent!r} is not in the venue file "
                   f"(agents: {', '.join(a.id for a in session.agents)})", "use one of those ids")
    return session


# ---------------------------------------------------------------------------------------------
# Device sources


def check_sources(report: Report, settings: DoctorSettings, session: Session | None) -> None:
    """Each --source by its scheme's `check`; a sensor id the venue does not know fails first."""
    for given in settings.sources:
        sensor_id, sep, url = given.partition("=")
        if not sep or urlsplit(given).scheme == "mcap":
            sensor_id, url = "", given
        name = f"source {given}"
        try:
            found = scheme(urlsplit(url).scheme)
            problem = ""
        except ReckonError as error:  # unknown, or its library missing: the registry's words
            found, problem = None, str(error)
        if (found is None or found.sensor(url)) and session is not None and not _known_sensor(
                report, name, sensor_id, session, settings):
            continue
        if found is None:
            report.add(name, Level.FAIL, problem, "use SENSOR=serial://PORT, SENSOR=ble://ADDRESS, "
                       "SENSOR=phone://HOST:PORT or mcap://FILE")
            continue
        request = CheckRequest(url, sensor_id, session, settings.venue, settings.agent, _rate_hz(session, sensor_id),
                               settings.listen_s, settings.bluetooth_sysfs)
        try:
            for finding in found.check(request):
                report.add(name, finding.level, finding.message, finding.fix)
        except ReckonError as error:  # a malformed URL: the parser's own words
            report.add(name, Level.FAIL, str(error), "fix the URL (reckon edge --help)")


def _known_sensor(report: Report, name: str, sensor_id: str, session: Session, settings: DoctorSettings) -> bool:
    agents = [a for a in session.agents if settings.agent in (None, a.id)]
    known = {s.id for a in agents for s in a.sensors}
    if sensor_id in known:
        return True
    whose = f"agent {settings.agent}" if settings.agent else "the venue"
    report.add(name, Level.FAIL, f"{sensor_id or 'no sensor id'!r} is not a sensor of {whose} "
               f"(sensors: {', '.join(sorted(known)) or 'none'})", "write SENSOR=URL with one of those ids")
    return False


def _rate_hz(session: Session | None, sensor_id: str) -> float | None:
    owner = session.sensor_owner().get(sensor_id) if session else None
    return next((s.rate_hz for s in owner.sensors if s.id == sensor_id), None) if owner else None


# ---------------------------------------------------------------------------------------------
# This machine's clock


class _Timex(ctypes.Structure):
    """Linux `struct timex` (adjtimex(2)); modes 0 only reads."""

    _fields_ = [("modes", ctypes.c_uint), ("offset", ctypes.c_long), ("freq", ctypes.c_long),
                ("maxerror", ctypes.c_long), ("esterror", ctypes.c_long), ("status", ctypes.c_int),
                ("constant", ctypes.c_long), ("precision", ctypes.c_long), ("tolerance", ctypes.c_long),
                ("time_sec", ctypes.c_long), ("time_usec", ctypes.c_long), ("tick", ctypes.c_long),
                ("ppsfreq", ctypes.c_long), ("jitter", ctypes.c_long), ("shift", ctypes.c_int),
                ("stabil", ctypes.c_long), ("jitcnt", ctypes.c_long), ("calcnt", ctypes.c_long),
                ("errcnt", ctypes.c_long), ("stbcnt", ctypes.c_long), ("tai", ctypes.c_int),
                ("reserved", ctypes.c_int * 11)]


TIME_ERROR = 5  # adjtimex's return value when the clock is not synchronised
STA_UNSYNC = 0x0040


def clock_sync() -> tuple[bool, float] | None:
    """(synchronised, maximum error in ms) from the kernel, or None where adjtimex is not there."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name, use_errno=True)
        timex = _Timex()
        state = libc.adjtimex(ctypes.byref(timex))
    except (OSError, AttributeError):
        return None
    if state < 0:
        return None
    return state != TIME_ERROR and not timex.status & STA_UNSYNC, timex.maxerror / 1000.0


def check_chair_kernels(report: Report, session: Session | None) -> None:
    """Where the venue has chairs: their compiled merger and filter are built for this machine."""
    if session is None or not any(agent.kind is AgentKind.WHEELCHAIR for agent in session.agents):
        return
    from reckon import kernels

    path = kernels.module_path(kernels.build_key())
    if path.exists():
        report.add("chair kernels", Level.OK, f"compiled ahead of time for this machine: {path.name}")
    else:
        report.add("chair kernels", Level.WARN, f"not compiled for this machine yet ({path} is missing): a chair's "
                   "edge builds it when it starts (about 10 s), or compiles it in its own process where it cannot "
                   "(numba, some 150 MiB more)", "run `python -m reckon.kernels` as the user who installed reckon "
                   "(deploy/install.sh does): it builds it, or says why it cannot")


def check_clock_sync(report: Report) -> None:
    state = clock_sync()
    if state is None:
        report.add("clock", Level.WARN, "cannot tell whether this clock is synchronised (no adjtimex here)",
                   "check NTP by hand (`timedatectl` or `chronyc tracking`)")
    elif not state[0]:
        report.add("clock", Level.WARN, "this machine's clock is not synchronised (kernel: unsynchronised)",
                   "run NTP (chrony or systemd-timesyncd) on the hub and every edge, against the same server")
    else:
        report.add("clock", Level.OK, f"synchronised, kernel's maximum error {state[1]:.0f} ms")


# ---------------------------------------------------------------------------------------------
# The bus


@dataclass
class _Traffic:
    """What the venue's traffic showed in the window."""

    streams: dict[str, Counter[str]] = field(default_factory=lambda: defaultdict(Counter))  # agent -> stream -> n
    offsets_ms: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))  # publisher -> offsets
    status: dict[str, Any] = field(default_factory=dict)  # agent/sensor -> latest DeviceStatus


def check_bus(report: Report, config: BusConfig, settings: DoctorSettings, session: Session) -> None:
    from reckon.transport.bus import BusError, Subscription, flush, open_session, wait_for_peers

    venue = session.venue.name
    where = f"listen {_setting(config, 'listen/endpoints')}, connect {_setting(config, 'connect/endpoints')}, " \
            f"mode {_setting(config, 'mode')}"
    try:
        with open_session(config) as bus, Subscription(bus, keys.all_agents(venue)) as traffic:
            try:
                hubs = wait_for_peers(bus, wire.alive_selector(venue, wire.Role.HUB), 1, settings.bus_timeout_s)
            except BusError:
                report.add("bus", Level.FAIL, f"no hub of venue {venue!r} answered within {settings.bus_timeout_s:g} s "
                           f"({where})", "start `reckon hub --venue ...` there; check --connect/--listen (the hub's "
                           "endpoint), --mode, and that a firewall lets its tcp port through")
                return
            started = time.monotonic()
            answered = flush(bus, wire.alive_selector(venue, wire.Role.HUB), settings.bus_timeout_s)
            round_trip_ms = (time.monotonic() - started) * 1e3
            if answered:
                report.add("bus", Level.OK, f"hub {wire.parse_alive(hubs[0])[2]} answers ({where}), round trip "
                                            f"{round_trip_ms:.1f} ms")
            else:
                report.add("bus", Level.WARN, f"a hub is alive but did not answer a query within "
                           f"{settings.bus_timeout_s:g} s", "the hub may be overloaded; look at its log")
            if settings.streams_s > 0:
                _report_traffic(report, settings, session, _watch(traffic, settings.streams_s))
    except BusError as error:
        report.add("bus", Level.FAIL, str(error), "check the endpoints; a listen port may be in use")


def _setting(config: BusConfig, path: str) -> str:
    """A config value as a person reads it: a list of endpoints space-separated ("none" if empty);
    anything else (a file's per-mode table) as JSON."""
    value = json.loads(config.get_json(path))
    if isinstance(value, list):
        return " ".join(map(str, value)) or "none"
    return value if isinstance(value, str) else json.dumps(value)


def _watch(traffic: Any, window_s: float) -> _Traffic:
    from google.protobuf.message import DecodeError

    from protocol.messages import DeviceStatus

    seen = _Traffic()
    deadline = time.monotonic() + window_s
    while (remaining := deadline - time.monotonic()) > 0:
        try:
            item = traffic.get(timeout=remaining)
        except queue.Empty:
            break
        if item is None or item.delete:
            continue
        try:
            _, agent, stream, sensor = keys.parse(item.key)
        except ValueError:
            continue
        name = f"{stream}/{sensor}" if stream == "pose" else stream
        seen.streams[agent][name] += 1
        publisher = ("hub" if stream in HUB_STREAMS and name != EDGE_POSE else
                     "camera tracker" if agent == keys.CAMERA else f"edge {agent}")
        if item.source_ns is not None:
            seen.offsets_ms[publisher].append((item.source_ns - item.received_ns) / 1e6)
        if stream == "status" and sensor:
            try:
                seen.status[f"{agent}/{sensor}"] = DeviceStatus.FromString(item.payload)
            except DecodeError:  # a foreign sample on a status key says nothing about the device
                continue
    return seen


def _report_traffic(report: Report, settings: DoctorSettings, session: Session, seen: _Traffic) -> None:
    window = settings.streams_s
    if "hub" not in seen.offsets_ms:
        report.add("clock offset hub", Level.WARN, f"no timestamped hub output in {window:g} s: offset unknown",
                   "run doctor again while edges are streaming (the hub publishes only what they send it)")
    for publisher, offsets in sorted(seen.offsets_ms.items()):
        offset = statistics.median(offsets)
        level = (Level.OK if abs(offset) <= settings.clock_warn_ms else
                 Level.WARN if abs(offset) <= CLOCK_FAIL_MS else Level.FAIL)
        text = (f"{publisher}'s clock is {abs(offset):.1f} ms {'ahead of' if offset > 0 else 'behind'} this one "
                f"(median of {len(offsets)} samples, the bus delay included; limit {settings.clock_warn_ms:g} ms)")
        report.add(f"clock offset {publisher}", level, text, "" if level is Level.OK else
                   "edges stamp every batch with their own clock and the hub pairs collisions within 0.5 s: "
                   "synchronise every machine to one NTP server (chrony), the hub's for instance")
    for agent in session.agents:
        if settings.agent not in (None, agent.id):
            continue
        streams = seen.streams.get(agent.id)
        if not streams:
            report.add(f"agent {agent.id}", Level.WARN, f"nothing of it on the bus in {window:g} s",
                       f"start its edge (`reckon edge --agent {agent.id} ...`) and check its log")
            continue
        rates = ", ".join(f"{stream} {count / window:.0f}/s" for stream, count in sorted(streams.items()))
        report.add(f"agent {agent.id}", Level.OK, f"flowing: {rates}")
    for device, status in sorted(seen.status.items()):
        problems = ([] if status.connected else [f"disconnected ({status.reconnects} reconnects)"])
        if 0 <= status.battery_pct < LOW_BATTERY_PCT:
            problems.append(f"battery {status.battery_pct:.0f} %")
        problems += list(status.flags)
        if problems:
            report.add(f"device {device}", Level.WARN, "; ".join(problems), "look at the device and its edge's log")
        else:
            age = status.last_sample_age_s
            report.add(f"device {device}", Level.OK, "connected" + (f", last sample {age:.1f} s ago" if age >= 0 else ""))


def finite_seconds(text: str) -> float:
    """argparse type: a finite number of seconds >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a finite number of seconds >= 0")
    return value


def register(subparsers: Any, bus_options: Any, bus_config: Any) -> None:
    """Add `reckon doctor` to the CLI. `bus_options(parser)` adds --listen/--connect/--mode;
    `bus_config(args, default_role)` turns them into a Zenoh config (both from reckon/cli/bus.py)."""
    doctor = subparsers.add_parser("doctor", help="check the venue file, devices, clocks and the bus; say what is "
                                                  "wrong (docs/doctor.md)")
    doctor.add_argument("--venue", metavar="VENUE.toml", help="the venue file (or a session log)")
    doctor.add_argument("--agent", help="only this agent's sensors and streams")
    doctor.add_argument("--source", action="append", default=[], metavar="URL",
                        help="a device as `reckon edge --source` takes it; once per device")
    doctor.add_argument("--listen-s", type=finite_seconds, default=1.0, metavar="S",
                        help="how long to listen to each serial device (default 1 s)")
    doctor.add_argument("--bus-timeout", type=finite_seconds, default=3.0, metavar="S",
                        help="how long to wait for the hub (default 3 s)")
    doctor.add_argument("--streams", type=finite_seconds, default=2.0, metavar="S",
                        help="how long to watch the venue's traffic (default 2 s; 0: not watched)")
    doctor.add_argument("--no-bus", action="store_true", help="skip the bus check")
    doctor.add_argument("--json", action="store_true", help="print one JSON object instead of the lines")
    bus_options(doctor)

    def run(args: Any, progress: Any) -> int:
        settings = DoctorSettings(venue=Path(args.venue) if args.venue else None, agent=args.agent,
                                  sources=tuple(args.source), bus=None if args.no_bus else bus_config(args, "connect"),
                                  listen_s=args.listen_s, bus_timeout_s=args.bus_timeout, streams_s=args.streams)
        report = run_doctor(settings)
        print(json.dumps(report.to_json(), indent=1) if args.json else report.text())
        return 0 if report.ok else 1

    doctor.set_defaults(run=run)

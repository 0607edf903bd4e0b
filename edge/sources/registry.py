"""Device sources by URL scheme: what `reckon edge --source` opens and what `reckon doctor` checks.

    session, source = open_sources(["seat=serial:///dev/ttyUSB0", ...], "chair01", stop, venue_toml=path)
    for message in source:  # ImuBatch, BeaconSighting, StandScan
        ...
    findings = scheme("serial").check(CheckRequest("serial:///dev/ttyUSB0", "seat", session, ...))

Each source module declares one `SCHEME = Scheme(...)`: its `open(request) -> (session, source)`
and `check(request) -> [Finding]`. `SOURCE_MODULES` says where each scheme lives; a module is
imported only when its scheme is used (a BLE source needs bleak, a phone aiohttp, a serial one
pyserial), so a missing library fails that scheme alone, naming the library.

One edge takes one scheme: the samples of one agent share one clock, and each kind of source
stamps its own (an x-IMU3 or TSND the device's, BLE notifications the host's, a phone the
phone's). A live source (not `mcap`) is written `SENSOR=URL` and needs the venue file, which says
which sensor is where; `live_session` checks both for every scheme the same way.
"""

from __future__ import annotations

import enum
import importlib
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable
from urllib.parse import urlsplit

from protocol.errors import ConfigError
from protocol.session import Agent, Session
from protocol.session_log import session_description

SOURCE_MODULES = {
    "mcap": "edge.sources.mcap",
    "serial": "edge.sources.serial",
    "ble": "edge.sources.ble",
    "phone": "edge.sources.phone.server",
}


class Level(str, enum.Enum):
    OK = "OK"
    WARN = "WARN"  # works, but look at it
    FAIL = "FAIL"  # will not work


@dataclass(frozen=True)
class Finding:
    """What a check found: `message` in plain words, `fix` what to do about it."""

    level: Level
    message: str
    fix: str = ""


@dataclass(frozen=True)
class Spec:
    """One `--source`: the sensor it feeds ("" for a source that names none, mcap), the device URL,
    and the argument as given (for error messages)."""

    sensor_id: str
    url: str
    given: str


@dataclass(frozen=True)
class OpenRequest:
    """What a scheme's `open` gets: its specs and the edge's context. `speed`, `start_at`: a replay's
    pace (x real time, 0: at once) and the wall-clock time of its first message; `reconnect_s`: how
    long a serial device that went away is waited for; `factories`: keyword arguments for the
    source (fakes in tests, e.g. BLE `client_factory`)."""

    specs: tuple[Spec, ...]
    agent_id: str
    stop: threading.Event
    venue_toml: Path | None = None
    speed: float = 1.0
    start_at: float | None = None
    reconnect_s: float = 30.0
    factories: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class CheckRequest:
    """What a scheme's `check` gets: one device URL, the sensor it is for, and what the doctor
    knows (the venue's session and file, `agent` to look for in a log, `listen_s` a device may be
    listened to, `bluetooth_sysfs` where Linux lists Bluetooth adapters)."""

    url: str
    sensor_id: str = ""
    session: Session | None = None
    venue: Path | None = None
    agent: str | None = None
    rate_hz: float | None = None  # the venue file's rate for this sensor
    listen_s: float = 1.0
    bluetooth_sysfs: Path = Path("/sys/class/bluetooth")


@dataclass(frozen=True)
class Scheme:
    """A URL scheme's source. `form`: how a --source of it is written (for messages); `sensor`:
    whether a URL of it feeds a sensor of the venue file (`mcap://` and `ble://scan` do not)."""

    name: str
    form: str
    open: Callable[[OpenRequest], tuple[Session, Iterable[Any]]]
    check: Callable[[CheckRequest], list[Finding]]
    sensor: Callable[[str], bool] = field(default=lambda url: True)


def known_schemes() -> str:
    return ", ".join(SOURCE_MODULES)


def scheme(name: str, given: str | None = None) -> Scheme:
    """The registered scheme `name`; ConfigError naming it and the known ones, or the library its
    module lacks. `given`: the --source argument, for the message."""
    where = f"--source {given!r}: " if given is not None else ""
    module_name = SOURCE_MODULES.get(name)
    if module_name is None:
        raise ConfigError(f"{where}unknown scheme {name or 'none'!r} (known: {known_schemes()}); expected "
                          f"{expected_forms()}")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ConfigError(f"{where}{name}:// sources need the {error.name} package, which is not installed "
                          "(the edge's libraries: pip install 'reckon[edge]')") from None
    found: Scheme = module.SCHEME
    return found


def expected_forms() -> str:
    return ("mcap://FILE (alone), SENSOR=serial://PORT?baud=N, SENSOR=ble://AA:BB:CC:DD:EE:FF, "
            "RECEIVER=ble://scan or SENSOR=phone://HOST:PORT")


def parse_source(given: str) -> tuple[str, Spec]:
    """(scheme name, spec) of one --source: `mcap://FILE`, or `SENSOR=URL` for a live device."""
    whole = urlsplit(given).scheme
    if whole == "mcap":
        return whole, Spec("", given, given)
    sensor_id, sep, url = given.partition("=")
    if not sep:
        if whole in SOURCE_MODULES:
            raise ConfigError(f"--source {given!r}: no sensor id in front; expected {expected_forms()}")
        return whole, Spec("", given, given)
    return urlsplit(url).scheme, Spec(sensor_id, url, given)


def open_sources(urls: list[str], agent_id: str, speed: float, stop: threading.Event,
                 venue_toml: Path | None = None, reconnect_s: float = 30.0, start_at: float | None = None, *,
                 ble_factories: Mapping[str, Any] | None = None) -> tuple[Session, Iterable[Any]]:
    """(session description, message stream) for an edge's `--source` URLs, all of one scheme.
    ConfigError naming the URL for an unknown scheme, a mix of schemes, or what the scheme refuses."""
    if not urls:
        raise ConfigError(f"no --source given; expected {expected_forms()}")
    parsed = [parse_source(url) for url in urls]
    name = parsed[0][0]
    found = scheme(name, parsed[0][1].given)
    other = next((spec for kind, spec in parsed if kind != name), None)
    if other is not None:
        scheme(urlsplit(other.url).scheme, other.given)  # an unknown scheme says so first
        raise ConfigError(f"--source {other.given!r}: {name} and {urlsplit(other.url).scheme} sources cannot be "
                          "mixed on one edge: an agent's samples need one clock, and each kind stamps its own (a "
                          "serial IMU the device's clock, BLE notifications the host's, a phone the phone's); "
                          "make every source of the agent one kind")
    request = OpenRequest(tuple(spec for _, spec in parsed), agent_id, stop, venue_toml, speed, start_at,
                          reconnect_s, dict(ble_factories or {}))
    return found.open(request)


def check_agent(session: Session, agent_id: str, where: str) -> Agent:
    """The agent `agent_id` of `session`; ConfigError naming --agent, `where` and the agents there."""
    try:
        return session.agent(agent_id)
    except KeyError:
        raise ConfigError(f"--agent {agent_id!r}: not in {where} (agents: "
                          f"{', '.join(a.id for a in session.agents)})") from None


def live_session(request: OpenRequest, kind: str, why: str = "it says which sensor is where",
                 sensors: Iterable[Spec] | None = None) -> tuple[Session, Agent]:
    """(session, agent) for live devices: the venue file is needed (`kind`, `why`: for the message);
    each of `sensors` (default: every spec) must name a sensor of the agent, once."""
    if request.venue_toml is None:
        raise ConfigError(f"--venue VENUE.toml is needed with {kind} ({why})")
    session = session_description(request.venue_toml)
    agent = check_agent(session, request.agent_id, str(request.venue_toml))
    known = {s.id for s in agent.sensors}
    given = list(request.specs if sensors is None else sensors)
    for spec in given:
        if spec.sensor_id not in known:
            raise ConfigError(f"--source {spec.given!r}: {request.agent_id} has no sensor {spec.sensor_id!r} "
                              f"(sensors: {', '.join(sorted(known)) or 'none'})")
    ids = [spec.sensor_id for spec in given]
    twice = sorted({sensor_id for sensor_id in ids if ids.count(sensor_id) > 1})
    if twice:
        raise ConfigError(f"--source {twice[0]}=...: sensor {twice[0]!r} is given twice (one device per sensor)")
    return session, agent

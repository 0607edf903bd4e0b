"""`mcap://FILE`: a session log replayed as an edge's source, paced by log time.

    for message in mcap_source(Path("game.mcap"), "chair01", speed=1.0, stop=stop):
        ...  # ImuBatch, BeaconSighting, StandScan, Pressure of chair01, as the devices sent them

The simulator's sessions and recordings replay through the same edge code as live devices. The
session description comes from the log itself unless a venue file is given.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from protocol import keys, messages
from protocol.errors import ConfigError, ReckonError
from protocol.session import Session
from protocol.session_log import LogMessages, read_description, session_description
from edge.sources.registry import CheckRequest, Finding, Level, OpenRequest, Scheme, check_agent

STREAMS = ("ImuBatch", "BeaconSighting", "StandScan", "Pressure")  # what an edge takes from a log
LOG_FIX = "give a log written by reckon (sim, import, record or a hub's -o)"


def mcap_path(url: str) -> Path:
    parts = urlsplit(url)
    return Path(parts.netloc + parts.path)


def mcap_source(path: Path, agent_ids: str | set[str] | None, speed: float, stop: threading.Event,
                start_at: float | None = None) -> Iterator[Any]:
    """Agents' IMU batches, beacon sightings and stand scans from a session log, paced by log time (speed 0: at once).

    `agent_ids`: one agent, a set, or None for all. Each ImuBatch gets `received_ns` = its log time.
    `start_at`: wall-clock time (time.time()) of the log's first message, so that several edges
    replaying one log stay in step; default: now.
    """
    wanted = {agent_ids} if isinstance(agent_ids, str) else agent_ids

    def accept(topic: str, name: str) -> bool:
        if name not in STREAMS:
            return False
        return wanted is None or keys.parse(topic)[1] in wanted

    first_log = first_wall = None
    for log_time, _, message in LogMessages(path, accept):
        if speed > 0:
            if first_log is None:
                first_log = log_time
                first_wall = time.monotonic() + (0.0 if start_at is None else start_at - time.time())
            wait = (log_time - first_log) * 1e-9 / speed - (time.monotonic() - first_wall)
            if wait > 0 and stop.wait(wait):
                return
        if stop.is_set():
            return
        if messages.type_name(message) == "ImuBatch" and not message.received_ns:
            message.received_ns = log_time
        yield message


def open_mcap(request: OpenRequest) -> tuple[Session, Iterable[Any]]:
    """One log, alone: this agent's messages from it."""
    if len(request.specs) != 1:
        raise ConfigError(f"--source {request.specs[1].given!r}: mcap://FILE goes alone (one log per edge)")
    path = mcap_path(request.specs[0].url)
    session = session_description(request.venue_toml) if request.venue_toml else read_description(path)
    check_agent(session, request.agent_id, str(path))
    return session, mcap_source(path, request.agent_id, request.speed, request.stop, request.start_at)


def check_mcap(request: CheckRequest) -> list[Finding]:
    """The log opens, has a session description and (with `agent`) that agent's messages."""
    from mcap.reader import make_reader

    path = mcap_path(request.url)
    try:
        session = read_description(path)
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
    except ReckonError as error:  # names the file already
        return [Finding(Level.FAIL, str(error), LOG_FIX)]
    except (OSError, ValueError) as error:  # the mcap reader's own errors on a damaged file
        return [Finding(Level.FAIL, f"{path}: not a readable session log ({error})", LOG_FIX)]
    count = summary.statistics.message_count if summary and summary.statistics else 0
    agents = {c.topic.split("/")[2] for c in summary.channels.values() if c.topic.count("/") >= 3} if summary else set()
    if request.agent is not None and request.agent not in agents:
        return [Finding(Level.FAIL, f"{path} has no messages of agent {request.agent!r} (has "
                        f"{', '.join(sorted(agents))})", "use one of those agents or another log")]
    return [Finding(Level.OK, f"{path}: venue {session.venue.name!r}, {count} messages, {len(agents)} agents")]


SCHEME = Scheme("mcap", "mcap://FILE", open_mcap, check_mcap, sensor=lambda url: False)

"""Zenoh key expressions (also used as MCAP topics), built in one place.

Layout: `reckon/<venue>/<agent>/<stream>[/<sensor>]`. Venue, agent and sensor ids are single
key chunks: letters, digits, `-` and `_` only, so no id can inject `/`, `*` or `$`.
"""

from __future__ import annotations

import re

from protocol.errors import ConfigError

ROOT = "reckon"
_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


def check_id(value: str, where: str) -> str:
    """Return `value` if it is a valid id chunk, else raise ConfigError naming `where`."""
    if not isinstance(value, str) or not _ID.match(value):
        raise ConfigError(f"{where}: id {value!r} must be 1-64 characters of A-Z a-z 0-9 _ -")
    return value


def imu(venue: str, agent: str, sensor: str) -> str:
    return f"{ROOT}/{venue}/{agent}/imu/{sensor}"


def clock(venue: str, agent: str, sensor: str) -> str:
    """A device's clock against the edge host's (ClockSample): what the hub's clock offsets need of
    the raw stream, which goes out only while someone subscribes to it."""
    return f"{ROOT}/{venue}/{agent}/clock/{sensor}"


def beacon(venue: str, agent: str, sensor: str) -> str:
    return f"{ROOT}/{venue}/{agent}/beacon/{sensor}"


def pressure(venue: str, agent: str, sensor: str) -> str:
    """A barometer's readings (Pressure), e.g. a phone's."""
    return f"{ROOT}/{venue}/{agent}/pressure/{sensor}"


def truth(venue: str, agent: str) -> str:
    return f"{ROOT}/{venue}/{agent}/truth/pose"


def contact(venue: str, agent: str) -> str:
    return f"{ROOT}/{venue}/{agent}/truth/contact"


def truth_length(venue: str, agent: str) -> str:
    return f"{ROOT}/{venue}/{agent}/truth/length"


def length(venue: str, agent: str) -> str:
    """A swimmer's finished lengths (SwimLength), from the edge."""
    return f"{ROOT}/{venue}/{agent}/length"


def scan(venue: str, agent: str) -> str:
    """QR calibration stand scans of a pedestrian's phone (StandScan), from the edge."""
    return f"{ROOT}/{venue}/{agent}/event/scan"


def status(venue: str, agent: str, sensor: str) -> str:
    """A device's health (DeviceStatus), from its edge."""
    return f"{ROOT}/{venue}/{agent}/status/{sensor}"


def pose(venue: str, agent: str, track: str = "live") -> str:
    return f"{ROOT}/{venue}/{agent}/pose/{track}"


def impact(venue: str, agent: str) -> str:
    return f"{ROOT}/{venue}/{agent}/event/impact"


def correction(venue: str, agent: str) -> str:
    return f"{ROOT}/{venue}/{agent}/correction"


def field(venue: str, agent: str) -> str:
    """The edge's magnetometer readings for the hub's field map (FieldReading)."""
    return f"{ROOT}/{venue}/{agent}/field"


def field_map(venue: str, agent: str) -> str:
    """The hub's map of the hall's magnetic field, for one agent's edge (FieldMap)."""
    return f"{ROOT}/{venue}/{agent}/field_map"


def fix(venue: str, agent: str) -> str:
    """Manual or video position fixes of one agent, into the hub."""
    return f"{ROOT}/{venue}/{agent}/fix"


# Cameras share the venue's key space under the reserved agent chunk CAMERA (no agent may take it).
CAMERA = "camera"


def camera_tracks(venue: str, camera: str) -> str:
    """An external tracker's frames (CameraFrame) from one camera."""
    return f"{ROOT}/{venue}/{CAMERA}/tracks/{camera}"


def camera_truth(venue: str, camera: str) -> str:
    """Simulator truth for a camera's tracks (TruthTrackLabel)."""
    return f"{ROOT}/{venue}/{CAMERA}/truth_tracks/{camera}"


# The hub's venue-wide outputs share it under the reserved agent chunk HUB, as cameras do under CAMERA.
HUB = "hub"
RESERVED = (CAMERA, HUB)


def pose_batch(venue: str, track: str = "live") -> str:
    """Every agent's poses of one track, several to a message (PoseBatch), from the hub:
    `reckon/<venue>/hub/poses/<track>`. Not matched by `all_agents(venue, "pose/<track>")`, so a
    consumer of single poses never also gets them batched."""
    return f"{ROOT}/{venue}/{HUB}/poses/{track}"


def identity(venue: str, agent: str) -> str:
    """The hub's TrackIdentity of one agent: which camera track it is."""
    return f"{ROOT}/{venue}/{agent}/identity"


def all_agents(venue: str, stream: str = "**") -> str:
    """Selector for one stream kind of every agent, e.g. `reckon/demo/*/imu/*`."""
    return f"{ROOT}/{venue}/*/{stream}"


def parse(key: str) -> tuple[str, str, str, str | None]:
    """Split a key into (venue, agent, stream, sensor or None); ValueError if not ours."""
    parts = key.split("/")
    if len(parts) < 4 or parts[0] != ROOT:
        raise ValueError(f"key {key!r} is not under {ROOT}/<venue>/<agent>/<stream>")
    return parts[1], parts[2], parts[3], "/".join(parts[4:]) or None

"""Venue (session) TOML files built from keyword arguments, one writer for the whole suite.

    write_venue(tmp_path / "hall.toml", "hall",
                stands=[{"id": "entrance", "x_m": 3.3, "y_m": 33.55, "heading_deg": -90.0}],
                agents=[agent_table("walker", "pedestrian", sensors=[sensor_table("phone", "hand", rate_hz=100.0)])])

`[venue]` gets `name` and every other keyword (lists of tables such as beacons and stands as
inline tables); each agent becomes an `[[agents]]` table. Any key is written as given, so a test
of the loader can pass an unknown key or a non-finite number on purpose.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def sensor_table(id: str, mount: str, **fields: Any) -> dict[str, Any]:
    """One `[[agents.sensors]]` entry."""
    return {"id": id, "mount": mount, **fields}


def agent_table(id: str, kind: str | None = None, sensors: list[dict[str, Any]] | None = None,
          **fields: Any) -> dict[str, Any]:
    """One `[[agents]]` table; `kind` and `sensors` left out when not given (the loader's defaults)."""
    out: dict[str, Any] = {"id": id}
    if kind is not None:
        out["kind"] = kind
    out.update(fields)
    if sensors is not None:
        out["sensors"] = sensors
    return out


def venue_toml(name: str, agents: Sequence[dict[str, Any]] = (), **venue: Any) -> str:
    """The text of a venue file: `[venue]` with `name` and `venue`'s keys, then one `[[agents]]` per agent."""
    lines = ["[venue]", f"name = {_value(name)}"] + [f"{_key(k)} = {_value(v)}" for k, v in venue.items()]
    for entry in agents:
        lines += ["", "[[agents]]"] + [f"{_key(k)} = {_value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"


def write_venue(path: Path, name: str, agents: Sequence[dict[str, Any]] = (), **venue: Any) -> Path:
    """Write `venue_toml(name, agents, **venue)` to `path`; returns `path`."""
    path.write_text(venue_toml(name, agents, **venue), encoding="utf-8")
    return path


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    raise TypeError(f"{value!r}: no TOML form for a {type(value).__name__}")

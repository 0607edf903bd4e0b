"""Pedestrian simulator: people walking a building with a phone held flat in the hand or in a
trouser pocket, stopping at QR calibration stands, as the indoor-navigation paper's experiments
(docs/simulator-pedestrian.md).

`simulate_pedestrian(output, seed, people, preset, mount)` writes a session log (MCAP);
`simulate_walker` gives one walker's streams and truth without a file. Presets: `paper` (its
12-point corridor map, tables 4-5, and its 4-minute route) and `floorplan` (an office floor with
rooms and a hall, polygons with holes). Modules, in data-flow order: params, venues, person ->
path -> timeline -> phone -> sensors -> simulate -> session; calibration measures the paper's
speed model and stand-to-turn heading error on generated walks. `reckon sim pedestrian` is in
reckon/cli/sim.py.

Names are imported on first use (PEP 562), so importing the package loads none of numpy, scipy
and shapely.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "PedestrianParams": "params", "describe": "params", "error_free": "params", "params_with_overrides": "params",
    "PedestrianSummary": "session", "simulate_pedestrian": "session", "stand_key": "session",
    "MOUNTS": "simulate", "PhoneStream": "simulate", "WalkerRun": "simulate", "simulate_walker": "simulate",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)

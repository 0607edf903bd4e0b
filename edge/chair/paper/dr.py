"""The wheelchair paper's dead reckoning (Hasegawa et al., eq. 1-2): constant memory.

Each step moves the chair by its travel `d` along the heading of the step before:
x_t = d_{t-1} cos(psi_{t-1}) + x_{t-1}, y_t = d_{t-1} sin(psi_{t-1}) + y_{t-1}.
`step` is the streaming form; `dead_reckon` is the same sum vectorised (a test shows they agree).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PaperDrState:
    x_m: float
    y_m: float
    heading_rad: float  # psi of the previous step: used for the next displacement


def step(state: PaperDrState, travel_m: float, heading_rad: float) -> PaperDrState:
    """Advance by `travel_m` (signed: backward is negative) along the previous heading (eq. 1-2)."""
    return PaperDrState(
        x_m=state.x_m + travel_m * np.cos(state.heading_rad),
        y_m=state.y_m + travel_m * np.sin(state.heading_rad),
        heading_rad=heading_rad,
    )


def dead_reckon(start: PaperDrState, travel_m: np.ndarray, heading_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions after each step; `travel_m[k]` is moved along `heading_rad[k-1]` (start heading for k=0).

    Returns (x_m, y_m) arrays of len(travel_m) + 1, starting at the start position.
    """
    previous = np.concatenate([[start.heading_rad], heading_rad[:-1]])
    x = start.x_m + np.concatenate([[0.0], np.cumsum(travel_m * np.cos(previous))])
    y = start.y_m + np.concatenate([[0.0], np.cumsum(travel_m * np.sin(previous))])
    return x, y

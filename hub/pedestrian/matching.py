"""What every pedestrian map matcher takes and gives, so the hub and the evaluation can use either.

A matcher receives one pedestrian's dead-reckoned poses in time order (per step, about 2 Hz, or at
a fixed rate) and returns a matched pose for each. When the dead reckoning is reset to a known
pose (a QR stand scan), the caller says so with `reset` before passing the first pose after it,
so the jump is not taken for a walk.

Implementations: hub/pedestrian/paper.py (the indoor-navigation paper's turn snap, the baseline)
and hub/pedestrian/particles.py (ours, a particle filter over the walkable area).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class DeadReckonedPose:
    """One dead-reckoned pose; heading counter-clockwise from +x. `covariance` is 3x3 over
    (x m, y m, heading rad), None when the dead reckoning gives none."""

    time_ns: int
    x_m: float
    y_m: float
    heading_rad: float
    covariance: np.ndarray | None = None


class SnapStage(str, enum.Enum):
    """The paper's snap has two moments: the position when a turn is detected, the heading when
    the turn has ended."""

    POSITION = "position"
    HEADING = "heading"


@dataclass(frozen=True)
class SnapRecord:
    """One snap decision of the paper's matcher, for scoring turn snaps against the true junction.

    `valid`: the sec. 3.5 rule held (no other point within `rule_radius_m` = X tan 3 deg of the
    target, X the distance from the previous point). `applied`: the pose was actually moved.
    `direction_deg`: at the HEADING stage, the corridor direction chosen.
    """

    time_ns: int
    stage: SnapStage
    point_id: str
    valid: bool
    applied: bool
    distance_m: float  # from the pose before the snap to the point
    rule_radius_m: float
    conflicting_point_id: str | None = None
    direction_deg: float | None = None


@dataclass(frozen=True)
class MatchedPose:
    """A matcher's output for one input pose; `snap` is set when the paper's matcher decided a
    snap at this pose (the particle filter never sets it); `fallback` when the map contradicted
    the dead reckoning and this pose is the dead reckoning's own track (hub/pedestrian/guard.py)."""

    time_ns: int
    x_m: float
    y_m: float
    heading_rad: float
    covariance: np.ndarray
    snap: SnapRecord | None = None
    fallback: bool = False


class MapMatcher(Protocol):
    def update(self, pose: DeadReckonedPose) -> MatchedPose:
        """The matched pose for the next dead-reckoned pose (poses in time order)."""
        ...

    def reset(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        """The dead reckoning restarted from this known pose; the next pose continues from it."""
        ...

    refined_lag_steps: int  # how many poses the refined track lags the live one; 0: no refined track

    def refined(self) -> list[MatchedPose]:
        """Poses refined by later evidence since the last call (a matcher without a lag: none)."""
        ...

    def flush(self) -> list[MatchedPose]:
        """End of the stream: the refined poses still waiting."""
        ...


def wrap_angle_rad(angle_rad: np.ndarray | float) -> np.ndarray | float:
    """Angle(s) wrapped to [-pi, pi); a float for a float."""
    wrapped = (np.asarray(angle_rad) + np.pi) % (2.0 * np.pi) - np.pi
    return float(wrapped) if wrapped.ndim == 0 else wrapped

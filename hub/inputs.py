"""What every hub checks of an input before it changes anything: its values are numbers."""

from __future__ import annotations

import math
from typing import Any


def check_pose(pose: Any) -> list[float]:
    """An EstimatedPose's covariance as floats (a slice of the repeated field: a list). ValueError naming
    the agent, the time and the values if x, y, heading or the covariance hold NaN or inf: one sum for
    all twelve (NaN and inf carry through it), as the check runs for every pose."""
    values = pose.covariance[:]
    if not math.isfinite(pose.x_m + pose.y_m + pose.heading_rad + sum(values)):
        raise ValueError(f"EstimatedPose of {pose.agent_id} at {pose.timestamp_ns}: x_m {pose.x_m}, y_m {pose.y_m}, "
                         f"heading_rad {pose.heading_rad}, covariance {values}: every value must be finite")
    return values

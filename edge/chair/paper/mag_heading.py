"""Heading from the seat magnetometer, as the paper proposes (no gyro, no calibration).

The paper says only "heading from the geomagnetic sensor under the seat" (sec. 3.2.3). Read
faithfully: the horizontal field in the chair frame, seat assumed level (no tilt compensation, no
hard/soft-iron calibration), referenced to the court with one known start heading (the paper gives
the start pose from video). Chair frame: x forward, y left, z up; heading counter-clockwise from
the court x axis.
"""

from __future__ import annotations

import numpy as np

START_AVERAGE_S = 1.0  # average the field over the first second to fix the court reference


def magnetometer_heading(time_ns: np.ndarray, mag_chair: np.ndarray, start_heading_rad: float) -> np.ndarray:
    """Unwrapped heading (rad) per sample from (N, 3) chair-frame field (any unit).

    In the chair frame the horizontal field points at angle (north - heading); the court angle of
    north is fixed so that the first second's mean reading gives `start_heading_rad`.
    """
    field_angle = np.arctan2(mag_chair[:, 1], mag_chair[:, 0])
    first = time_ns <= time_ns[0] + int(START_AVERAGE_S * 1e9)
    start_angle = np.arctan2(np.mean(np.sin(field_angle[first])), np.mean(np.cos(field_angle[first])))
    north_rad = start_heading_rad + start_angle
    heading = np.unwrap(north_rad - field_angle)
    return heading - 2 * np.pi * np.round((heading[0] - start_heading_rad) / (2 * np.pi))

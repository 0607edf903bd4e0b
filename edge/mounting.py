"""Sensor mounting: pick signed axes out of sensor-frame arrays, rotate seat data to the chair frame.

Chair frame: x forward, y left, z up (right-handed). Axis names are "+x", "-y", ... as in the
session description (`protocol.session.Sensor`).
"""

from __future__ import annotations

import numpy as np

_INDEX = {"x": 0, "y": 1, "z": 2}


def signed_axis(values: np.ndarray, axis: str) -> np.ndarray:
    """Column `axis` ("+x".."-z") of an (N, 3) array, negated for "-"."""
    sign = -1.0 if axis[0] == "-" else 1.0
    return sign * values[..., _INDEX[axis[1]]]


def seat_to_chair(values: np.ndarray, forward_axis: str, left_axis: str) -> np.ndarray:
    """Rotate (N, 3) seat-sensor vectors into the chair frame (forward, left, up)."""
    forward = signed_axis(values, forward_axis)
    left = signed_axis(values, left_axis)
    # up = forward x left, expressed through the sensor axes
    unit_f = _unit(forward_axis)
    unit_l = _unit(left_axis)
    up_vector = np.cross(unit_f, unit_l)
    up = values @ up_vector
    return np.stack([forward, left, up], axis=-1)


def _unit(axis: str) -> np.ndarray:
    vector = np.zeros(3)
    vector[_INDEX[axis[1]]] = -1.0 if axis[0] == "-" else 1.0
    return vector

"""Two-pass attitude over one buffered length: the causal filter's transients kept out of the length.

The causal AHRS of edge/swim_bins.py (a complementary filter, time constant 1/gain = 2 s) is tilted
by the push-off and the glide (0.1-1 g along the body for 0.3-2.5 s) and takes seconds to recover:
its gravity estimate leaks into the horizontal acceleration as a decaying curve that starts at the
push-off, inside the length, which the straight-line drift removal of edge/swim_length.py cannot
remove. Run the same filter backwards in time over the buffered length, from the touch (where it
starts from the causal filter's attitude) to the push-off, and the same disturbances leave their
transients *before* the push-off, outside the length; its own start-up error sits at the touch.
So the length takes the backward pass near its push-off and the causal pass near its touch, with
a smooth crossfade in the middle where both have settled (docs/swim-estimator.md).

The backward pass runs at the rows' 100 Hz on the rows' mean specific force and offset-corrected
rate (edge/swim_bins.py keeps them): time reversed, the rate changes sign, the specific force does
not. Memory: the rows of one length (bounded by the tracker's buffer), nothing kept between calls.
"""

from __future__ import annotations

import imufusion
import numpy as np

from edge.swim_bins import (ACC, ACCELERATION_REJECTION_DEG, AHRS_GAIN, BIN_HZ, DV_X, DV_Y, G, GYR, GYRO_RANGE_DPS,
                            HEAD_X, HEAD_Y, QUAT, RECOVERY_S)

# Share of the push-off..touch time over which the backward pass hands over to the causal one
# (smoothstep). Each pass's transient lasts 2-4 s from its start (the push-off's for the causal,
# the touch's for the backward); a 15-60 s length has settled in its middle third.
CROSSFADE_SHARE = (1.0 / 3.0, 2.0 / 3.0)


def _rotation(q: np.ndarray) -> np.ndarray:
    """Earth-from-body rotation matrix of the unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def backward_pass(rows: np.ndarray, first: int, last: int) -> tuple[np.ndarray, np.ndarray]:
    """The attitude filter run from row `last` back to row `first`, starting from the causal
    quaternion at the end of row `last`. Returns (dv, head), each (last - first + 1) x 2: per row
    the earth-frame horizontal velocity change (m/s) and the body's forward axis on the horizontal
    plane at the row's end, like the rows' DV_X/DV_Y and HEAD_X/HEAD_Y columns."""
    settings = imufusion.AhrsSettings()
    settings.gain = AHRS_GAIN
    settings.acceleration_rejection = ACCELERATION_REJECTION_DEG
    settings.gyroscope_range = GYRO_RANGE_DPS
    settings.sample_rate = BIN_HZ
    settings.rejection_timeout = int(RECOVERY_S * BIN_HZ)
    ahrs = imufusion.Ahrs()
    ahrs.set_settings(settings)
    ahrs.skip_startup()
    ahrs.set_quaternion(np.array(rows[last, QUAT], dtype=float))
    n = last - first + 1
    dv, head = np.zeros((n, 2)), np.zeros((n, 2))
    dt = 1.0 / BIN_HZ
    accel, gyro = rows[:, ACC], rows[:, GYR]
    r_end = _rotation(ahrs.get_quaternion())
    for k in range(last, first - 1, -1):
        j = k - first
        head[j] = r_end[:2, 0]
        ahrs.update_no_magnetometer(-gyro[k], accel[k])  # time reversed: the rotation undone
        r_start = _rotation(ahrs.get_quaternion())
        # the row's specific force at its mid-time attitude; gravity is vertical, so the
        # horizontal part needs no subtraction
        dv[j] = (0.5 * (r_end + r_start) @ accel[k])[:2] * G * dt
        r_end = r_start
    return dv, head


def crossfade_weight(n: int) -> np.ndarray:
    """Weight of the backward pass over n rows from the push-off to the touch: 1, a smoothstep
    down over CROSSFADE_SHARE, 0."""
    share = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(n)
    lo, hi = CROSSFADE_SHARE
    u = np.clip((share - lo) / (hi - lo), 0.0, 1.0)
    return 1.0 - u * u * (3.0 - 2.0 * u)


def two_pass(rows: np.ndarray, push: int, touch: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
    """(dv, head) for rows[push..stop]: the backward pass blended into the causal one over
    push..touch (crossfade_weight), the causal one alone from the touch to `stop` (the turn)."""
    dv = rows[push:stop + 1, [DV_X, DV_Y]].copy()
    head = rows[push:stop + 1, [HEAD_X, HEAD_Y]].copy()
    back_dv, back_head = backward_pass(rows, push, touch)
    w = crossfade_weight(touch - push + 1)[:, None]
    n = touch - push + 1
    dv[:n] = w * back_dv + (1.0 - w) * dv[:n]
    head[:n] = w * back_head + (1.0 - w) * head[:n]
    return dv, head

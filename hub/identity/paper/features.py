"""The camera-identity paper's two features and its regression (Kawai et al., sec. 3.1-3.3).

The paper matches a camera track to a worn sensor through one observation (sec. 3.1, fig. 2): the
absolute horizontal speed of a person and the absolute vertical acceleration of the waist are
linearly related (r = 0.91 at 20 fps). Both features here are taken at frame times:

- `vertical_acceleration`: tilt corrected (the paper pre-corrects the sensor tilt, sec. 4.2) by
  projecting on the gravity direction, gravity removed, absolute value, then averaged over a
  window of about two steps. The paper gives no window; per-frame raw |a_v| swings between 0 and
  ~0.4 g within every stride, so r = 0.91 implies some averaging over the step cycle.
- `track_speed`: the horizontal speed of a track from its positions (sec. 3.2 "frame
  difference"), as the slope of a least-squares line through the positions in the same window, so
  that head-position noise (a few cm, x 20 fps) does not swamp walking speed.

`fit_model` is the regression of fig. 2 plus Ave and SD of eq. 1, measured on labelled data.
Pure numpy, no I/O; bad input raises ValueError naming the value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# About two steps at a normal cadence (~2 steps/s): averages the step cycle out of |a_v| and
# head-position noise out of speed. The same window is used for both features on purpose.
FEATURE_WINDOW_S = 1.0
# The gravity direction is the mean acceleration over this window: long against a stride, short
# against posture changes (sitting down tilts the pelvis, and so a waist sensor, by 10-30 deg).
GRAVITY_WINDOW_S = 4.0
MIN_FIT_SAMPLES = 3  # two points fit any line exactly; three are the least that leave a residual


@dataclass(frozen=True)
class PaperModel:
    """Fig. 2's regression and eq. 1's constants, measured beforehand on labelled data.

    vertical_g = slope_g_per_mps * speed_mps + intercept_g. `ave_abs_error_g` and
    `sd_abs_error_g` are the mean and standard deviation of the per-frame absolute error of that
    prediction on correctly labelled frames (Ave and SD of eq. 1). `window_s` is the feature
    window the model was fitted with; `identify` computes track speeds with it.
    """

    slope_g_per_mps: float
    intercept_g: float
    ave_abs_error_g: float
    sd_abs_error_g: float
    correlation: float = float("nan")  # Pearson r of the fit (the paper: 0.91)
    samples: int = 0
    window_s: float = FEATURE_WINDOW_S
    # Diagnostics of the other reading of eq. 1 (SD over fragments' MAE), when fragments are given.
    fragment_mae_mean_g: float = float("nan")
    fragment_mae_sd_g: float = float("nan")

    def predict(self, speed_mps: np.ndarray) -> np.ndarray:
        """Predicted vertical acceleration (g) for horizontal speeds (m/s): P_eval of sec. 3.3."""
        return self.slope_g_per_mps * np.asarray(speed_mps, dtype=float) + self.intercept_g

    def pruning_limit_g(self, length_s: np.ndarray) -> np.ndarray:
        """alpha_i = Ave + SD / sqrt(L_i) (eq. 1) for fragments L_i seconds long."""
        return self.ave_abs_error_g + self.sd_abs_error_g / np.sqrt(np.asarray(length_s, dtype=float))  # eq. 1


def check_times(name: str, time_ns: np.ndarray, strictly: bool = True) -> np.ndarray:
    """`time_ns` as a 1-D int64 array; ValueError naming the first place it goes backwards."""
    times = np.asarray(time_ns)
    if times.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {times.shape}")
    if times.size and not np.issubdtype(times.dtype, np.integer):
        raise ValueError(f"{name} must be integer nanoseconds, got dtype {times.dtype}")
    steps = np.diff(times)
    bad = np.flatnonzero(steps <= 0 if strictly else steps < 0)
    if bad.size:
        k = int(bad[0])
        relation = "does not increase" if strictly else "goes backwards"
        raise ValueError(f"{name} {relation} at index {k + 1}: {int(times[k + 1])} after {int(times[k])}")
    return times.astype(np.int64, copy=False)


def check_length(name: str, values: np.ndarray, expected: int) -> None:
    if len(values) != expected:
        raise ValueError(f"{name} has {len(values)} rows, expected {expected} (one per time_ns)")


def window_mean(sample_ns: np.ndarray, values: np.ndarray, centre_ns: np.ndarray,
                half_width_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of `values` over samples within +-half_width_ns of each centre, and their count.

    Prefix sums make this O((N + M) log N); a centre with no sample gets NaN.
    """
    cumulative = np.concatenate([np.zeros((1,) + values.shape[1:]), np.cumsum(values, axis=0)])
    low = np.searchsorted(sample_ns, centre_ns - half_width_ns, side="left")
    high = np.searchsorted(sample_ns, centre_ns + half_width_ns, side="right")
    count = high - low
    sums = cumulative[high] - cumulative[low]
    shape = (-1,) + (1,) * (values.ndim - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count.reshape(shape) > 0, sums / count.reshape(shape), np.nan)
    return mean, count


def vertical_acceleration(time_ns: np.ndarray, accel_g: np.ndarray, frame_ns: np.ndarray,
                          window_s: float = FEATURE_WINDOW_S,
                          gravity_window_s: float = GRAVITY_WINDOW_S) -> np.ndarray:
    """S_eval of sec. 3.3: mean |vertical body acceleration| (g) around each frame time.

    time_ns (N,) strictly increasing; accel_g (N, 3) in any sensor frame (the projection on the
    local gravity direction makes the axes and a tilt irrelevant). Returns (F,) for frame_ns (F,),
    NaN where no sample lies within window_s / 2 of the frame.
    """
    times = check_times("imu time_ns", time_ns)
    accel = np.asarray(accel_g, dtype=float)
    if accel.ndim != 2 or accel.shape[1] != 3:
        raise ValueError(f"accel_g must be (N, 3), got shape {accel.shape}")
    check_length("accel_g", accel, len(times))
    frames = check_times("frame_ns", frame_ns)
    if not (window_s > 0 and gravity_window_s > 0):
        raise ValueError(f"window_s {window_s} and gravity_window_s {gravity_window_s} must be > 0")
    if not np.all(np.isfinite(accel)):
        raise ValueError(f"accel_g has a non-finite value at row {int(np.flatnonzero(~np.isfinite(accel))[0] // 3)}")
    if times.size == 0:
        return np.full(len(frames), np.nan)
    gravity, _ = window_mean(times, accel, times, int(gravity_window_s * 0.5e9))
    gravity_norm = np.linalg.norm(gravity, axis=1)
    # a . g_hat - |g| = (a - g) . g_hat: the body's own acceleration along the vertical.
    vertical = np.abs(np.einsum("ij,ij->i", accel - gravity, gravity / gravity_norm[:, None]))
    mean, _ = window_mean(times, vertical, frames, int(window_s * 0.5e9))
    return mean


def track_speed(time_ns: np.ndarray, x_m: np.ndarray, y_m: np.ndarray,
                window_s: float = FEATURE_WINDOW_S) -> np.ndarray:
    """Horizontal speed (m/s) at each row of one fragment: |slope| of a line fit over the window.

    The fit over the rows within +-window_s / 2 is the frame difference of sec. 3.2 with the
    noise averaged out; at a fragment's ends the window is one-sided. NaN where fewer than two
    rows fall in the window (a one-row fragment has no speed).
    """
    times = check_times("track time_ns", time_ns)
    x = np.asarray(x_m, dtype=float)
    y = np.asarray(y_m, dtype=float)
    check_length("x_m", x, len(times))
    check_length("y_m", y, len(times))
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("track x_m / y_m has a non-finite value")
    if window_s <= 0:
        raise ValueError(f"window_s {window_s} must be > 0")
    if times.size == 0:
        return np.zeros(0)
    seconds = (times - times[0]) * 1e-9  # relative to the fragment start: keeps the sums small
    columns = np.column_stack([seconds, seconds * seconds, x, seconds * x, y, seconds * y])
    mean, count = window_mean(times, columns, times, int(window_s * 0.5e9))
    t, tt, mx, tx, my, ty = mean.T
    variance = tt - t * t
    with np.errstate(invalid="ignore", divide="ignore"):
        velocity_x = (tx - t * mx) / variance
        velocity_y = (ty - t * my) / variance
    speed = np.hypot(velocity_x, velocity_y)
    return np.where(count >= 2, speed, np.nan)


def fit_model(speeds_mps: np.ndarray, verticals_g: np.ndarray, fragment_ids: np.ndarray | None = None,
              window_s: float = FEATURE_WINDOW_S) -> PaperModel:
    """Fig. 2's least-squares line and eq. 1's Ave and SD from labelled frames.

    speeds_mps and verticals_g: one pair per labelled frame (a track row and the vertical
    acceleration of the person it truly is). Non-finite pairs are skipped. fragment_ids (same
    length, optional) names each frame's fragment; it only adds the per-fragment MAE diagnostics.
    Raises ValueError for mismatched lengths or fewer than 3 usable pairs or constant speed.
    """
    speeds = np.asarray(speeds_mps, dtype=float).ravel()
    verticals = np.asarray(verticals_g, dtype=float).ravel()
    check_length("verticals_g", verticals, len(speeds))
    if fragment_ids is not None:
        check_length("fragment_ids", np.asarray(fragment_ids), len(speeds))
    usable = np.isfinite(speeds) & np.isfinite(verticals)
    if int(usable.sum()) < MIN_FIT_SAMPLES:
        raise ValueError(f"fit_model needs at least {MIN_FIT_SAMPLES} finite (speed, vertical) pairs, "
                         f"got {int(usable.sum())}")
    s, v = speeds[usable], verticals[usable]
    if np.ptp(s) == 0:
        raise ValueError(f"fit_model: every speed is {s[0]} m/s; a slope needs varied speeds")
    slope, intercept = np.polyfit(s, v, 1)
    errors = np.abs(v - (slope * s + intercept))
    correlation = float(np.corrcoef(s, v)[0, 1]) if np.ptp(v) > 0 else float("nan")
    mae_mean = mae_sd = float("nan")
    if fragment_ids is not None:
        labels = np.asarray(fragment_ids)[usable]
        _, inverse = np.unique(labels, return_inverse=True)
        maes = np.bincount(inverse, weights=errors) / np.bincount(inverse)
        mae_mean = float(maes.mean())
        mae_sd = float(maes.std(ddof=1)) if len(maes) > 1 else float("nan")
    return PaperModel(float(slope), float(intercept), float(errors.mean()), float(errors.std(ddof=1)),
                      correlation, int(usable.sum()), float(window_s), mae_mean, mae_sd)

"""The indoor-navigation paper's dead reckoning (methods.md section 3), as written: our baseline.

Nakagome, Saito, Mori (Chiba Tech), seeds/003: a phone held flat in front, read on a 50 Hz timer.
    cadence f   = the highest bin of the FFT of the last 5 s of acceleration      (section 3.1)
    speed   V   = (0.001 f)^2 + 0.37 H f,  H height (m), f (Hz), V (m/s)          (eq. 2)
                  [eq. 1, frequency only: V = (60 f / 18.59)^(1/0.42) / 60]
    attitude    = Euler-angle kinematics from the body rates (eq. 5), roll and pitch corrected
                  by the gravity the accelerometer sees (eq. 6): an extended Kalman filter
                  (the paper's "state equation" and "observation equation")
    heading     = the Euler yaw psi; no magnetometer (unusable on the 12th floor, fig. 4-8)
    position    x += V dt cos(heading), y += V dt sin(heading)                    (section 3.3)
    stand       sets position, heading and attitude (pitch = the stand's tilt, roll 0)

Our readings of what the paper leaves open or prints garbled (see also "Flagged" below):
- Eq. 1 as printed, V = f / 18.59^(1/0.42), gives 0.0017 at f = 1.8 Hz. Its source [4]
  (Yamazaki & Sato) relates cadence to speed as n = 18.59 V^0.42 with n in steps/min and V in
  m/min (80 m/min -> 117 steps/min); inverted, V = (n / 18.59)^(1/0.42): 1.8 Hz = 108 steps/min
  -> 66 m/min = 1.10 m/s. The printed form misplaces the parenthesis and drops the unit change.
- Eq. 2 as printed: the height-scaled cadence model "step length 0.37 H, times cadence", with a
  quadratic term. We keep the printed coefficients with f in Hz (steps/s), H in m and V in m/s:
  0.37 * 1.74 m * 1.8 Hz = 1.16 m/s, and (0.001 f)^2 = 3e-6 m/s is negligible, so eq. 2 is in
  effect V = 0.37 H f. Why this unit reading: tables 1 and 2 are the same 86 m walk under eq. 1
  and eq. 2, so their ratio per person (1.071, 1.069, 0.892 for 169/174/179 cm) is V2(f) / V1(f)
  at that person's cadence. Solved for f, this reading gives 1.74, 1.78 and 2.07 Hz (speeds
  1.15, 1.14, 1.36 m/s), matching the 1.8 Hz of fig. 3. The other reading, 0.001 f^2 in
  per-minute units (0.001 n^2 + 0.37 H n, m/min), needs 1.98-2.39 Hz at 1.5-1.9 m/s: a near-jog
  that fig. 3 does not show. (The tables are separate runs, so this assumes each person kept
  their cadence; it picks the units, not the coefficients.)
- Which acceleration: the paper says only "the phone's acceleration". We use |a| by default
  (`cadence_signal="magnitude"`): orientation-free, so the speed module does not depend on the
  heading module, as in the paper's module diagram; for a phone held flat |a| ~ a_z, the vertical.
  "vertical" (a projected on the estimated vertical) is selectable. The window mean is removed
  (else the DC bin always wins); no taper; the peak is the bin itself (resolution 1 / 5 s = 0.2 Hz).
- Timing: the paper reads the sensors on a 50 Hz timer interrupt, so the FFT window holds the
  latest acceleration sampled on a 50 Hz grid (sample-and-hold); attitude and position integrate
  with each sample's own dt from the timestamps.
- Before the window is full after a stand the paper "inputs a constant speed" (section 5) without
  the value: we use eq. 2 at `start_cadence_hz` = 1.8 Hz (fig. 3). After a gap the window
  restarts and the last speed is held until it is full again.
- Axes. Eq. 6's signs (a_z = -g lying flat) fix a z-down body frame, which Android's (x right,
  y top, z out of the screen; +g on z lying flat) is not. We read the phone as forward-right-down:
  body (x, y, z) = (y, x, -z) of Android, the world as north-east-down with north = venue +x and
  east = venue -y. Then eq. 5 and 6 hold as printed for what Android reports, theta is the tilt of
  the top of the screen (the stand's tilt), phi the roll about the forward axis, and the venue
  heading (counter-clockwise from +x) is -psi.
- Eq. 6's gains are not given: gyro noise `gyro_noise_sd_rad_s` = 0.02 rad/s and accelerometer
  noise `accel_noise_sd_ms2` = 1 m/s^2 (hand and gait accelerations) give a time constant of
  about 5 s for the gravity correction.
- Gimbal lock is kept as the paper has it (section 5: quaternions are their future work): at
  pitch +-90 deg tan(theta) and sec(theta) blow up. Samples within 10 deg of it are counted.
- Bad input: a sample whose time does not advance is ignored (`backwards`); a non-finite value
  is skipped (`nonfinite`); a gap over `gap_s` is counted (`gaps`), restarts the FFT window and is
  not integrated (neither attitude nor position: the motion over it is unknown).
- Uncertainty (ours; the paper has none): per output a 3x3 covariance over (x, y, heading),
  propagated through the motion's Jacobian with along-track noise `speed_sd_fraction` of the
  distance (table 2: -5.0 .. +0.9 %) and heading noise from drift and turn scale; a stand sets it
  to the stand's own error (table 3: 2.1 deg rms).

Flagged in the paper: eq. 1 and eq. 2 (above); heights printed "169m, 174m, 179m" (cm); tables 1-2
give "error (m)" as truth - estimate but "error rate" as estimate - truth; eq. 4 calls dt the
"sampling rate (ms)" (it is the period, and with rad/s it must be in s); the legend of eq. 6 calls
the accelerations omega; section 3.2 compares fig. 11 with "fig. 4" (the magnetometer), meaning
fig. 9 (the raw gyro).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from edge.pedestrian.estimator import PdrStep, PhoneSample, wrap
from protocol.errors import ConfigError
from protocol.messages import STANDARD_GRAVITY_MS2

GIMBAL_WARNING_COS = math.cos(math.radians(80.0))  # |pitch| within 10 deg of 90: counted
EQ1_GAIN = 18.59  # eq. 1 via [4]: cadence (steps/min) = 18.59 * speed (m/min) ** 0.42
EQ1_EXPONENT = 0.42
EQ2_STEP_PER_HEIGHT = 0.37  # eq. 2: step length (m) = 0.37 H
EQ2_QUADRATIC = 0.001  # eq. 2: (0.001 f)^2, as printed


def speed_eq1_m_s(cadence_hz: float) -> float:
    """Eq. 1 (frequency only), read as V = (n / 18.59)^(1/0.42) with n = 60 f steps/min, V m/min."""
    return (60.0 * cadence_hz / EQ1_GAIN) ** (1.0 / EQ1_EXPONENT) / 60.0


def speed_eq2_m_s(cadence_hz: float, height_m: float) -> float:
    """Eq. 2 (height-scaled cadence): V = (0.001 f)^2 + 0.37 H f; f Hz, H m, V m/s."""
    return (EQ2_QUADRATIC * cadence_hz) ** 2 + EQ2_STEP_PER_HEIGHT * height_m * cadence_hz


@dataclass(frozen=True)
class PaperPdrSettings:
    sample_rate_hz: float = 50.0  # the paper's timer: the FFT grid
    window_s: float = 5.0  # FFT window (section 3.1)
    hop_s: float = 0.5  # FFT recomputed this often (the paper does not say)
    output_period_s: float = 0.5  # one PdrStep this often
    gap_s: float = 0.25  # a longer sampling interval is a gap
    cadence_signal: Literal["magnitude", "vertical"] = "magnitude"
    speed_model: Literal["eq2", "eq1"] = "eq2"  # the paper uses eq. 2
    start_cadence_hz: float = 1.8  # the constant speed before the window fills: eq. 2 at fig. 3's cadence
    min_cadence_hz: float = 0.0  # 0: the paper, any bin above DC; raise to ignore slow hand drift
    still_amplitude_ms2: float = 0.0  # 0: the paper, never still; > 0: speed 0 when the peak is lower
    use_attitude: bool = True  # False: eq. 4, the raw z gyro integrated (the paper's fig. 9-10)
    gyro_noise_sd_rad_s: float = 0.02  # EKF process noise (ours: the paper gives none)
    accel_noise_sd_ms2: float = 1.0  # EKF observation noise of eq. 6 (ours)
    gravity_ms2: float = STANDARD_GRAVITY_MS2  # g of eq. 6
    stand_attitude_sd_rad: float = 0.02  # roll/pitch after a stand
    stand_position_sd_m: float = 0.3
    stand_heading_sd_rad: float = 0.037  # table 3: 2.1 deg rms after 40 m and a turn
    speed_sd_fraction: float = 0.05  # table 2: -5.0 .. +0.9 %
    heading_drift_sd_rad_per_sqrt_s: float = 0.004
    gyro_scale_sd: float = 0.01  # heading error per radian turned

    def __post_init__(self) -> None:
        positive = ("sample_rate_hz", "window_s", "hop_s", "output_period_s", "gap_s", "start_cadence_hz",
                    "gyro_noise_sd_rad_s", "accel_noise_sd_ms2", "gravity_ms2")
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"pdr_paper.{name} must be > 0, got {getattr(self, name)}")
        if self.window_s * self.sample_rate_hz < 4:
            raise ConfigError(f"pdr_paper.window_s {self.window_s} holds fewer than 4 samples at "
                              f"{self.sample_rate_hz} Hz")
        if self.cadence_signal not in ("magnitude", "vertical"):
            raise ConfigError(f"pdr_paper.cadence_signal must be magnitude or vertical, got {self.cadence_signal!r}")
        if self.speed_model not in ("eq2", "eq1"):
            raise ConfigError(f"pdr_paper.speed_model must be eq2 or eq1, got {self.speed_model!r}")


@dataclass(frozen=True)
class PaperPdrState:
    """A frozen snapshot (diagnostics and tests). Angles in rad; roll/pitch/yaw in the paper's
    forward-right-down frame (venue heading = -yaw_rad)."""

    time_ns: int
    stood: bool  # a stand has set the pose
    x_m: float
    y_m: float
    heading_rad: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    attitude_covariance: np.ndarray  # 2x2 over (roll, pitch)
    raw_heading_rad: float  # eq. 4: the raw z gyro integrated since the stand
    cadence_hz: float  # the last FFT peak; nan before the first
    peak_amplitude_ms2: float
    speed_m_s: float
    window_fill: int  # samples in the FFT window
    covariance: np.ndarray  # 3x3 over (x, y, heading)
    outputs: int
    gaps: int
    backwards: int
    nonfinite: int
    near_gimbal_lock: int
    relevelled: int  # attitude blown up through gimbal lock: roll and pitch taken from gravity again


ATTITUDE_VARIANCE_LIMIT = 100.0  # rad^2: far past any meaningful roll/pitch uncertainty


class PaperPdr:
    """`step(sample) -> list[PdrStep]` (at most one per output period), `reset_to_stand(...)`."""

    def __init__(self, settings: PaperPdrSettings = PaperPdrSettings(), height_m: float = 1.70):
        if not 0.5 <= height_m <= 2.5:  # the session file's bounds (protocol/session.py)
            raise ConfigError(f"pdr_paper height_m must be in [0.5, 2.5] m, got {height_m}")
        self.settings = settings
        self.height_m = height_m
        self.tick_ns = round(1e9 / settings.sample_rate_hz)
        self.window = np.zeros(round(settings.window_s * settings.sample_rate_hz))  # ring buffer
        self.window_index = self.window_fill = self.ticks_since_fft = 0
        self.next_tick_ns = -1  # -1: the grid restarts at the next sample
        self.held_signal_ms2 = 0.0
        self.hop_ticks = max(1, round(settings.hop_s * settings.sample_rate_hz))
        self.cadence_hz = math.nan
        self.peak_amplitude_ms2 = 0.0
        self.speed_m_s = self._speed(settings.start_cadence_hz)
        self.time_ns = -1
        self.roll_rad = self.pitch_rad = self.yaw_rad = 0.0
        self.attitude_covariance = np.diag([1.0, 1.0])  # replaced by gravity on the first sample
        self.raw_heading_rad = 0.0
        self.stood = False
        self.x_m = self.y_m = 0.0
        self.covariance = np.diag([1e6, 1e6, math.pi ** 2])
        self.next_output_ns = 0
        self.last_output_ns = 0
        self.distance_since_output_m = 0.0
        self.turn_since_output_rad = 0.0
        self.outputs = self.gaps = self.backwards = self.nonfinite = self.near_gimbal_lock = self.relevelled = 0

    # -- speed (section 3.1, eq. 1-2) -------------------------------------------------------------
    def _speed(self, cadence_hz: float) -> float:
        if self.settings.speed_model == "eq1":
            return speed_eq1_m_s(cadence_hz)
        return speed_eq2_m_s(cadence_hz, self.height_m)

    def _restart_window(self) -> None:
        self.window_index = self.window_fill = self.ticks_since_fft = 0
        self.next_tick_ns = -1

    def _feed_window(self, time_ns: int, signal_ms2: float) -> None:
        """The 50 Hz timer: each tick takes the latest sample (ticks between samples hold the
        previous one). At most gap_s * rate ticks per call: a longer interval restarts the grid."""
        if self.next_tick_ns < 0:
            self.next_tick_ns = time_ns
        while self.next_tick_ns < time_ns:
            self._push(self.held_signal_ms2)
        self.held_signal_ms2 = signal_ms2
        if self.next_tick_ns == time_ns:
            self._push(signal_ms2)

    def _push(self, value: float) -> None:
        self.next_tick_ns += self.tick_ns
        self.window[self.window_index] = value
        self.window_index = (self.window_index + 1) % len(self.window)
        self.window_fill = min(self.window_fill + 1, len(self.window))
        self.ticks_since_fft += 1
        if self.window_fill == len(self.window) and self.ticks_since_fft >= self.hop_ticks:
            self.ticks_since_fft = 0
            self._cadence_from_fft()

    def _cadence_from_fft(self) -> None:
        """Section 3.1: the highest-amplitude frequency of the window. The ring is not reordered:
        a circular shift leaves the magnitude spectrum unchanged."""
        settings = self.settings
        count = len(self.window)
        spectrum = np.abs(np.fft.rfft(self.window - self.window.mean()))
        frequencies = np.arange(len(spectrum)) * (1e9 / self.tick_ns) / count
        spectrum[(frequencies <= 0.0) | (frequencies < settings.min_cadence_hz)] = -1.0
        peak = int(np.argmax(spectrum))
        self.cadence_hz = float(frequencies[peak])
        self.peak_amplitude_ms2 = 2.0 * float(spectrum[peak]) / count
        still = self.peak_amplitude_ms2 < settings.still_amplitude_ms2
        self.speed_m_s = 0.0 if still else self._speed(self.cadence_hz)

    # -- attitude (section 3.2, eq. 5-6) ----------------------------------------------------------
    def _level_from_gravity(self, accel_frd: tuple[float, float, float]) -> None:
        """Eq. 6 solved for roll and pitch: the first sample's attitude (before any stand)."""
        ax, ay, az = accel_frd
        self.roll_rad = math.atan2(-ay, -az)
        self.pitch_rad = math.atan2(ax, math.hypot(ay, az))
        self.attitude_covariance = np.diag([self.settings.stand_attitude_sd_rad ** 2] * 2)

    def _predict(self, gyro_frd: tuple[float, float, float], dt_s: float) -> None:
        """Eq. 5, integrated over dt with the sample's rates; the EKF's Jacobian of its first two rows."""
        wx, wy, wz = gyro_frd
        sin_r, cos_r = math.sin(self.roll_rad), math.cos(self.roll_rad)
        tan_p, cos_p = math.tan(self.pitch_rad), math.cos(self.pitch_rad)  # the singularity, as printed
        if abs(cos_p) < GIMBAL_WARNING_COS:
            self.near_gimbal_lock += 1
        across = sin_r * wy + cos_r * wz
        roll_rate = wx + across * tan_p  # eq. 5, row 1
        pitch_rate = cos_r * wy - sin_r * wz  # row 2
        yaw_rate = across / cos_p  # row 3
        jacobian = np.array([[1.0 + dt_s * (cos_r * wy - sin_r * wz) * tan_p, dt_s * across / cos_p ** 2],
                             [-dt_s * across, 1.0]])
        self.roll_rad = wrap(self.roll_rad + roll_rate * dt_s)
        self.pitch_rad += pitch_rate * dt_s
        self.yaw_rad = wrap(self.yaw_rad + yaw_rate * dt_s)
        process = (self.settings.gyro_noise_sd_rad_s * dt_s) ** 2
        self.attitude_covariance = jacobian @ self.attitude_covariance @ jacobian.T + process * np.eye(2)

    def _correct(self, accel_frd: tuple[float, float, float]) -> None:
        """Eq. 6 as the EKF's observation of roll and pitch (yaw is not observed)."""
        g = self.settings.gravity_ms2
        sin_r, cos_r = math.sin(self.roll_rad), math.cos(self.roll_rad)
        sin_p, cos_p = math.sin(self.pitch_rad), math.cos(self.pitch_rad)
        predicted = np.array([g * sin_p, -g * sin_r * cos_p, -g * cos_r * cos_p])  # eq. 6
        jacobian = np.array([[0.0, g * cos_p], [-g * cos_r * cos_p, g * sin_r * sin_p],
                             [g * sin_r * cos_p, g * cos_r * sin_p]])
        covariance = self.attitude_covariance
        innovation_cov = jacobian @ covariance @ jacobian.T + self.settings.accel_noise_sd_ms2 ** 2 * np.eye(3)
        try:
            if not (np.all(np.abs(covariance) < ATTITUDE_VARIANCE_LIMIT) and math.isfinite(self.roll_rad + self.pitch_rad)):
                raise np.linalg.LinAlgError("attitude diverged")
            gain = np.linalg.solve(innovation_cov, jacobian @ covariance).T
        except np.linalg.LinAlgError:
            # Through gimbal lock (a phone upright in a pocket) eq. 5's tan(pitch) blows the attitude
            # up: the paper's method has no answer; start roll and pitch again from gravity, counted.
            self.relevelled += 1
            self._level_from_gravity(accel_frd)
            return
        correction = gain @ (np.asarray(accel_frd) - predicted)
        self.roll_rad = wrap(self.roll_rad + float(correction[0]))
        self.pitch_rad += float(correction[1])
        self.attitude_covariance = (np.eye(2) - gain @ jacobian) @ covariance

    def heading_rad(self) -> float:
        """Venue heading of the forward axis (counter-clockwise from +x): -psi, or eq. 4's raw gyro."""
        return wrap(-self.yaw_rad) if self.settings.use_attitude else wrap(self.raw_heading_rad)

    # -- the sample loop --------------------------------------------------------------------------
    def step(self, sample: PhoneSample) -> list[PdrStep]:
        """Feed one sample; returns the output whose period it closes (none before a stand)."""
        if self.time_ns >= 0 and sample.time_ns <= self.time_ns:
            self.backwards += 1
            return []
        values = (*sample.accel_ms2, *sample.gyro_rads)
        if not all(math.isfinite(value) for value in values):
            self.nonfinite += 1
            return []
        ax, ay, az, gx, gy, gz = values
        accel_frd, gyro_frd = (ay, ax, -az), (gy, gx, -gz)  # Android (right, top, out) -> forward-right-down
        first = self.time_ns < 0
        dt_s = 0.0 if first else (sample.time_ns - self.time_ns) * 1e-9
        self.time_ns = sample.time_ns
        if first:
            self._level_from_gravity(accel_frd)
        elif dt_s > self.settings.gap_s:
            self.gaps += 1
            self._restart_window()
            dt_s = 0.0  # not integrated: the motion over a gap is unknown
        heading_before = self.heading_rad()
        if dt_s > 0.0:
            self._predict(gyro_frd, dt_s)
            self.raw_heading_rad = wrap(self.raw_heading_rad + gz * dt_s)  # eq. 4
        self._correct(accel_frd)
        self._feed_window(sample.time_ns, self._cadence_signal(accel_frd))
        if not self.stood:
            return []
        heading = self.heading_rad()
        self.turn_since_output_rad += abs(wrap(heading - heading_before))
        travel_m = self.speed_m_s * dt_s  # section 3.3
        self.x_m += travel_m * math.cos(heading)
        self.y_m += travel_m * math.sin(heading)
        self.distance_since_output_m += travel_m
        if sample.time_ns < self.next_output_ns:
            return []
        return [self._output(sample.time_ns, heading)]

    def _cadence_signal(self, accel_frd: tuple[float, float, float]) -> float:
        ax, ay, az = accel_frd
        if self.settings.cadence_signal == "magnitude":
            return math.sqrt(ax * ax + ay * ay + az * az)
        sin_r, cos_r = math.sin(self.roll_rad), math.cos(self.roll_rad)
        sin_p, cos_p = math.sin(self.pitch_rad), math.cos(self.pitch_rad)
        return sin_p * ax - sin_r * cos_p * ay - cos_r * cos_p * az  # up component (minus the down row)

    def _output(self, time_ns: int, heading: float) -> PdrStep:
        """One PdrStep; the covariance propagated over the period (our model, see the docstring)."""
        settings = self.settings
        distance = self.distance_since_output_m
        cos_h, sin_h = math.cos(heading), math.sin(heading)
        jacobian = np.array([[1.0, 0.0, -distance * sin_h], [0.0, 1.0, distance * cos_h], [0.0, 0.0, 1.0]])
        along = np.array([cos_h, sin_h, 0.0])
        noise = (settings.speed_sd_fraction * distance) ** 2 * np.outer(along, along)
        noise[2, 2] += (settings.heading_drift_sd_rad_per_sqrt_s ** 2 * (time_ns - self.last_output_ns) * 1e-9
                        + (settings.gyro_scale_sd * self.turn_since_output_rad) ** 2)
        self.covariance = jacobian @ self.covariance @ jacobian.T + noise
        self.outputs += 1
        self.last_output_ns = time_ns
        period_ns = round(settings.output_period_s * 1e9)
        self.next_output_ns += period_ns * ((time_ns - self.next_output_ns) // period_ns + 1)  # skip missed periods
        self.distance_since_output_m = self.turn_since_output_rad = 0.0
        return PdrStep(time_ns, self.x_m, self.y_m, heading, distance, self.covariance.copy(), self.outputs)

    def reset_to_stand(self, time_ns: int, x_m: float, y_m: float, heading_rad: float,
                       tilt_rad: float | None = 0.0, heading_sd_rad: float | None = None) -> None:
        """A calibration stand: the phone at (x_m, y_m), its forward axis (top of the screen) at
        `heading_rad`, the top raised by `tilt_rad` (pitch; roll 0). `heading_sd_rad` is not used:
        the paper takes the stand as exact. None keeps the filter's roll
        and pitch. Restarts the FFT window: the paper's constant start speed until it is full."""
        settings = self.settings
        if tilt_rad is not None:
            self.roll_rad, self.pitch_rad = 0.0, float(tilt_rad)
            self.attitude_covariance = np.diag([settings.stand_attitude_sd_rad ** 2] * 2)
        self.yaw_rad = wrap(-heading_rad)
        self.raw_heading_rad = wrap(heading_rad)
        self.x_m, self.y_m = x_m, y_m
        self.covariance = np.diag([settings.stand_position_sd_m ** 2, settings.stand_position_sd_m ** 2,
                                   settings.stand_heading_sd_rad ** 2])
        self.stood = True
        self._restart_window()
        self.cadence_hz = math.nan
        self.speed_m_s = self._speed(settings.start_cadence_hz)
        if time_ns > self.time_ns:
            self.time_ns = time_ns
        self.last_output_ns = self.time_ns
        self.next_output_ns = self.time_ns + round(settings.output_period_s * 1e9)
        self.distance_since_output_m = self.turn_since_output_rad = 0.0

    def snapshot(self) -> PaperPdrState:
        return PaperPdrState(self.time_ns, self.stood, self.x_m, self.y_m, self.heading_rad(), self.roll_rad,
                             self.pitch_rad, self.yaw_rad, self.attitude_covariance.copy(),
                             wrap(self.raw_heading_rad), self.cadence_hz, self.peak_amplitude_ms2, self.speed_m_s,
                             self.window_fill, self.covariance.copy(), self.outputs, self.gaps, self.backwards,
                             self.nonfinite, self.near_gimbal_lock, self.relevelled)

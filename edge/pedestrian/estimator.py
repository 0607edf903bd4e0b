"""Our phone pedestrian dead reckoning: per-step output, quaternion attitude, learned step length.

Inputs are what Android reports (PhoneSample): accelerometer m/s^2 (gravity included), gyroscope
rad/s, magnetometer uT, in the phone frame (x right, y to the top of the screen, z out of it).
- Attitude: x-io Fusion's AHRS (`imufusion.Ahrs`, quaternion: no gimbal lock, unlike the paper's
  Euler angles) fed with the gyro after Fusion's offset algorithm (`imufusion.Bias`: re-learns the
  gyro bias whenever the phone is still). Levelled from gravity on the first sample.
- Steps: edge/pedestrian/steps.py (peaks of low-passed |a|); step length = K * Weinberg amplitude, K a
  per-user state re-learned between two calibration stands (surveyed over dead-reckoned
  displacement between them, bounded to [k_min, k_max] and smoothed).
- Walking direction: the heading of the device's forward axis (settings.forward_axis, +y for a
  phone held flat in front), averaged over the step as a unit vector (the body sways +-5 deg
  within a stride). With `direction_from_acceleration` (a pocket), plus the walking direction
  relative to that axis, read from the horizontal acceleration (edge/pedestrian/direction.py: principal
  axis, sign from the gait) in a frame turning with the phone, so the gyro still carries turns.
- Magnetometer: a gated aid only (the paper found it unusable on upper floors): edge/pedestrian/magnetic.py.
- Uncertainty: a 3x3 covariance over (x, y, heading), propagated per step through the motion's
  Jacobian with along-track (step length) and heading (gyro drift, scale) noise, kept inside a 4x4
  that adds the step length's scale error (K off for this walker): a per-step 8 % scatter averages
  out over a walk, a wrong K does not, it stretches the whole track (docs/pdr-estimator.md, "How
  honest the edge's covariance is").
Heading: counter-clockwise from the venue's +x axis, radians.

`PdrEstimator` is a small class because imufusion's Ahrs is a mutable C object; its state is
fixed-size (no lists grow); `snapshot()` returns it as a frozen PdrState. dt comes from the
timestamps; a gap over `gap_s` sets a counter, a timestamp that does not advance is ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import imufusion
import numpy as np

from edge.pedestrian import direction as pdr_direction

from edge.pedestrian import steps as pdr_steps
from edge.pedestrian.direction import DirectionSettings, DirectionState
from edge.pedestrian.magnetic import MagneticAid, MagneticSettings, VenueField
from edge.pedestrian.steps import StepSettings, StepState
from protocol.messages import STANDARD_GRAVITY_MS2

DEGREES_PER_RADIAN = 180.0 / math.pi
STAND_AXIS = np.array([0.0, 1.0, 0.0])  # a stand's corner holds the phone flat, its top (+y) at the stand's heading


@dataclass(frozen=True)
class PhoneSample:
    """One phone sample: unix or boot ns, m/s^2, rad/s, uT (None: no magnetometer reading)."""

    time_ns: int
    accel_ms2: tuple[float, float, float]
    gyro_rads: tuple[float, float, float]
    mag_ut: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class PdrStep:
    """The pose after one step. covariance over (x_m, y_m, heading_rad)."""

    time_ns: int
    x_m: float
    y_m: float
    heading_rad: float
    step_length_m: float
    covariance: np.ndarray
    count: int


@dataclass(frozen=True)
class PdrSettings:
    sample_rate_hz: float = 50.0  # nominal rate for Fusion's settings; dt itself comes from timestamps
    ahrs_gain: float = 0.5  # Fusion's default complementary gain
    acceleration_rejection_deg: float = 10.0  # Fusion's default: hand accelerations past this are not gravity
    rejection_timeout_s: float = 5.0  # Fusion's default recovery time
    gyro_range_dps: float = 2000.0  # phone gyros: +-2000 deg/s
    bias_threshold_dps: float = 3.0  # Fusion offset algorithm: still below this ...
    bias_period_s: float = 3.0  # ... for this long
    forward_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)  # phone flat in front: the top of the screen
    # Where a step goes: False: the heading of forward_axis (a phone held in front); True:
    # forward_axis's heading plus the walking direction relative to it, read from the acceleration
    # (edge/pedestrian/direction.py, in a frame turning with the phone: a pocket, however it sits).
    direction_from_acceleration: bool = False
    direction: DirectionSettings = field(default_factory=DirectionSettings)
    # Extra per-step heading noise when the direction is read from the acceleration (its spread
    # between steps, and the sign's chance to be wrong, are larger than a held phone's axis).
    direction_heading_sd_rad: float = 0.05
    # K (m per Weinberg unit): 0.43, the best of 0.38-0.46 on ILC walks 1-5 (0.38 left them about
    # 14 % short; docs/pdr-estimator.md). Re-learned per user between stands.
    step_gain_m: float = 0.43
    step_gain_min_m: float = 0.25  # bounds of a learned K: steps 0.35-1.0 m for typical amplitudes
    step_gain_max_m: float = 0.6
    step_gain_smoothing: float = 0.5  # weight of a newly learned K against the previous one
    stair_tread_m: float = 0.28  # a step's horizontal length on a stair: building codes' going 0.25-0.30 m
    step_gain_min_sum: float = 10.0  # learn K only over this many Weinberg units (about 10 steps)
    step_gain_min_displacement_m: float = 10.0  # ... and stands this far apart (a 3 deg heading error is 5 %)
    step_length_sd_fraction: float = 0.08  # per-step length error (Weinberg: ~8 % of distance)
    # The scale error of K for a walker it was not learned on (relative SD), shared by every step
    # until a second stand re-learns K: 0.16, chosen from 0.12-0.16 on the ILC site 1 tune half
    # (every other walk of each floor) as the one whose NEES at the waypoints has the median an
    # honest 2-D covariance has (1.39: 1.35 there, 0.94 on the report half); the walks' own best
    # scales spread 0.52-1.15 (docs/pdr-estimator.md).
    step_scale_sd: float = 0.16
    heading_drift_sd_rad_per_sqrt_s: float = 0.004  # residual gyro bias, walking sway
    gyro_scale_sd: float = 0.01  # heading error per radian turned (phone gyro scale)
    stand_position_sd_m: float = 0.3  # a QR stand's pose fix (algorithms.md)
    stand_heading_sd_rad: float = 0.05  # about 3 deg, the paper's calibration error
    gap_s: float = 0.25
    steps: StepSettings = field(default_factory=StepSettings)
    magnetic: MagneticSettings = field(default_factory=MagneticSettings)


@dataclass(frozen=True)
class PdrState:
    """A frozen snapshot of the estimator (diagnostics and tests)."""

    time_ns: int
    x_m: float
    y_m: float
    heading_offset_rad: float  # venue heading = device forward heading in Fusion's frame + this
    covariance: np.ndarray
    quaternion: np.ndarray
    gyro_offset_dps: np.ndarray
    step_gain_m: float
    steps: StepState
    stand_x_m: float | None
    stand_y_m: float | None
    weinberg_since_stand: float
    gaps: int
    backwards: int
    step_scale_sd: float  # the relative SD of K for this walker (the 4x4's scale entry)


class PdrEstimator:
    """`step(sample) -> list[PdrStep]`; `reset_to_stand(...)` applies a calibration stand."""

    def __init__(self, settings: PdrSettings = PdrSettings(), venue_field: VenueField | None = None):
        """`venue_field`: the venue's undisturbed Earth field; None: the magnetometer is not used."""
        self.settings = settings
        self.magnetic = MagneticAid(venue_field, settings.magnetic) if venue_field is not None else None
        ahrs_settings = imufusion.AhrsSettings(
            sample_rate=settings.sample_rate_hz, convention=imufusion.CONVENTION_NWU, gain=settings.ahrs_gain,
            gyroscope_range=settings.gyro_range_dps, acceleration_rejection=settings.acceleration_rejection_deg,
            magnetic_rejection=0.0, rejection_timeout=settings.rejection_timeout_s)
        self.ahrs = imufusion.Ahrs()
        self.ahrs.set_settings(ahrs_settings)
        self.bias = imufusion.Bias()
        self.bias.set_settings(imufusion.BiasSettings(sample_rate=settings.sample_rate_hz,
                                                      stationary_threshold=settings.bias_threshold_dps,
                                                      stationary_period=settings.bias_period_s))
        self.forward = np.array(settings.forward_axis, dtype=float)
        self.direction = DirectionState()
        self.time_ns = -1
        self.x_m = self.y_m = 0.0
        self.heading_offset_rad = 0.0
        # over (x m, y m, heading rad, step-length scale): the published covariance is its top-left 3x3
        self.covariance = np.diag([1e6, 1e6, math.pi ** 2, settings.step_scale_sd ** 2])  # no pose until a stand
        self.step_gain_m = settings.step_gain_m
        self.steps = StepState()
        self.stand: tuple[float, float] | None = None
        self.pending_stand: tuple[int, float, float, float, float | None, float | None] | None = None
        self.weinberg_since_stand = 0.0
        self.direction_sum = np.zeros(2)  # forward axis heading over the current step, unit vectors summed
        self.turn_since_step_rad = 0.0
        self.last_heading_rad = 0.0
        self.gaps = self.backwards = 0
        self.on_stairs = False  # set by the caller from the barometer (edge/pedestrian/floors.on_stairs)

    def device_heading_rad(self, rotation: np.ndarray | None = None) -> float:
        """Heading of the forward axis in Fusion's earth frame (counter-clockwise about up)."""
        return self.axis_heading_rad(self.forward, rotation)

    def axis_heading_rad(self, axis: np.ndarray, rotation: np.ndarray | None = None) -> float:
        """Heading of a phone axis in Fusion's earth frame (counter-clockwise about up)."""
        if rotation is None:
            rotation = imufusion.quaternion_to_matrix(self.ahrs.get_quaternion())
        pointing = rotation @ axis
        return math.atan2(pointing[1], pointing[0])

    def step(self, sample: PhoneSample) -> list[PdrStep]:
        """Feed one sample; returns the step completed by it (at most one)."""
        if self.time_ns >= 0 and sample.time_ns <= self.time_ns:
            self.backwards += 1
            return []
        accel_g = np.asarray(sample.accel_ms2, dtype=float) / STANDARD_GRAVITY_MS2
        gyro_dps = self.bias.update(np.asarray(sample.gyro_rads, dtype=float) * DEGREES_PER_RADIAN)
        if self.time_ns < 0:
            self.ahrs.set_quaternion(levelled_quaternion(accel_g))
            self.ahrs.skip_startup()  # levelled already; Fusion would zero the heading during its startup
            self.last_heading_rad = self.device_heading_rad()
            self.time_ns = sample.time_ns
            if self.pending_stand is not None:  # scanned before the first sample: applied on a levelled attitude
                stand, self.pending_stand = self.pending_stand, None
                self.reset_to_stand(*stand)
        else:
            dt_s = (sample.time_ns - self.time_ns) * 1e-9
            if dt_s > self.settings.gap_s:
                self.gaps += 1
            self.ahrs.set_sample_period(dt_s)
            self.ahrs.update_no_magnetometer(gyro_dps, accel_g)
        self.time_ns = sample.time_ns
        rotation = imufusion.quaternion_to_matrix(self.ahrs.get_quaternion())
        heading = self.device_heading_rad(rotation)
        if self.magnetic is not None and sample.mag_ut is not None:
            self.magnetic.add(rotation, sample.mag_ut)
        self.turn_since_step_rad += abs(wrap(heading - self.last_heading_rad))
        self.last_heading_rad = heading
        self.direction_sum += (math.cos(heading), math.sin(heading))
        if self.settings.direction_from_acceleration:
            linear = rotation @ np.asarray(sample.accel_ms2, dtype=float)
            linear[2] -= STANDARD_GRAVITY_MS2
            self.direction = pdr_direction.step(self.settings.direction, self.direction, sample.time_ns,
                                                (float(linear[0]), float(linear[1]), float(linear[2])), heading)
        self.steps, event = pdr_steps.step(self.settings.steps, self.steps, sample.time_ns, sample.accel_ms2)
        return [] if event is None else [self._advance(event)]

    def _advance(self, event: pdr_steps.StepEvent) -> PdrStep:
        settings = self.settings
        heading = self._step_direction_rad() + self.heading_offset_rad
        # On a stair a step is one tread, whatever the bounce says (the body rises instead of striding)
        length = settings.stair_tread_m if self.on_stairs else self.step_gain_m * event.weinberg
        self.weinberg_since_stand += event.weinberg
        cos_h, sin_h = math.cos(heading), math.sin(heading)
        self.x_m += length * cos_h
        self.y_m += length * sin_h
        scaled = 0.0 if self.on_stairs else length  # a tread's length is not K's
        jacobian = np.array([[1.0, 0.0, -length * sin_h, scaled * cos_h], [0.0, 1.0, length * cos_h, scaled * sin_h],
                             [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
        along = np.array([cos_h, sin_h, 0.0, 0.0])
        heading_var = (settings.heading_drift_sd_rad_per_sqrt_s ** 2 * event.duration_s
                       + (settings.gyro_scale_sd * self.turn_since_step_rad) ** 2)
        noise = (settings.step_length_sd_fraction * length) ** 2 * np.outer(along, along)
        noise[2, 2] += heading_var
        if settings.direction_from_acceleration:
            noise[2, 2] += settings.direction_heading_sd_rad ** 2
        self.covariance = jacobian @ self.covariance @ jacobian.T + noise
        self.direction_sum[:] = 0.0
        self.turn_since_step_rad = 0.0
        if self.magnetic is not None:
            measured = self.magnetic.measurement()
            if measured is not None and self.stand is not None:
                heading += self._magnetic_update(self.magnetic, measured)
        return PdrStep(event.time_ns, self.x_m, self.y_m, wrap(heading), length, self.covariance[:3, :3].copy(),
                       event.count)

    def _step_direction_rad(self) -> float:
        """The step's direction in Fusion's frame: the forward axis's heading averaged over the step,
        or from the acceleration (pdr_direction); the forward axis while that has nothing to read."""
        axis = math.atan2(self.direction_sum[1], self.direction_sum[0])
        if self.settings.direction_from_acceleration:
            offset = pdr_direction.offset_rad(self.settings.direction, self.direction)
            return axis if offset is None else axis + offset
        return axis

    def _magnetic_update(self, magnetic: MagneticAid, measured_offset_rad: float) -> float:
        """Kalman update of (x, y, heading) by one step's magnetic offset measurement: the
        position moves too, by its correlation with the heading it was walked on. Returns the
        heading change (0 when gated out)."""
        innovation = wrap(measured_offset_rad - self.heading_offset_rad)
        variance = self.covariance[2, 2] + self.settings.magnetic.heading_sd_rad ** 2
        if innovation ** 2 > self.settings.magnetic.gate_sigma ** 2 * variance:
            magnetic.rejected += 1
            return 0.0
        gain = self.covariance[:, 2] / variance
        self.x_m += gain[0] * innovation
        self.y_m += gain[1] * innovation
        self.heading_offset_rad = wrap(self.heading_offset_rad + gain[2] * innovation)
        self.covariance = self.covariance - np.outer(gain, self.covariance[2, :])
        magnetic.used += 1
        return float(gain[2] * innovation)

    def reset_to_stand(self, time_ns: int, x_m: float, y_m: float, heading_rad: float,
                       tilt_rad: float | None = 0.0, heading_sd_rad: float | None = None) -> None:
        """A calibration stand scan: the phone lies on the stand at (x_m, y_m), its top (+y) at
        `heading_rad` (known to `heading_sd_rad`; None or 0: a real stand's stand_heading_sd_rad),
        tilted `tilt_rad` about its x axis (None: keep the AHRS's own tilt).
        With a previous stand known, K is re-learned from the surveyed displacement between the
        two stands over the dead-reckoned one (bounded, smoothed; skipped below step_gain_min_sum
        Weinberg units or step_gain_min_displacement_m: too little to tell K from noise)."""
        settings = self.settings
        if self.time_ns < 0:
            self.pending_stand = (time_ns, x_m, y_m, heading_rad, tilt_rad, heading_sd_rad)
            return
        scale_variance = float(self.covariance[3, 3])
        if self.stand is not None and self.weinberg_since_stand >= settings.step_gain_min_sum:
            # The surveyed displacement between the stands over the dead-reckoned one: the walk
            # between them need not be straight (a route through corridors), only the heading good.
            surveyed_m = math.hypot(x_m - self.stand[0], y_m - self.stand[1])
            reckoned_m = math.hypot(self.x_m - self.stand[0], self.y_m - self.stand[1])
            if min(surveyed_m, reckoned_m) >= settings.step_gain_min_displacement_m:
                learned = min(max(self.step_gain_m * surveyed_m / reckoned_m, settings.step_gain_min_m),
                              settings.step_gain_max_m)
                self.step_gain_m += settings.step_gain_smoothing * (learned - self.step_gain_m)
                # The learned K's own relative error: both stands' position errors over the surveyed
                # distance; the smoothing blends it with the previous K's as independent estimates.
                measured_variance = 2.0 * settings.stand_position_sd_m ** 2 / surveyed_m ** 2
                weight = settings.step_gain_smoothing
                scale_variance = (1.0 - weight) ** 2 * scale_variance + weight ** 2 * measured_variance
        if tilt_rad is not None:
            yaw = self.axis_heading_rad(STAND_AXIS) - math.pi / 2.0  # the levelled phone's +y at yaw + 90 deg
            self.ahrs.set_quaternion(quaternion_multiply(axis_angle(2, yaw), axis_angle(0, tilt_rad)))
        # The stand holds the phone's top at heading_rad, whatever axis the phone walks along later
        # (a pocket: its screen's normal); the gyro carries the frame from the stand into the pocket.
        self.heading_offset_rad = wrap(heading_rad - self.axis_heading_rad(STAND_AXIS))
        self.x_m, self.y_m = x_m, y_m
        self.stand = (x_m, y_m)
        self.weinberg_since_stand = 0.0
        self.direction_sum[:] = 0.0
        self.turn_since_step_rad = 0.0
        # The phone left its mount for the stand: how it sits when it goes back is unknown.
        self.direction = DirectionState()
        heading_sd = heading_sd_rad if heading_sd_rad else settings.stand_heading_sd_rad
        self.covariance = np.diag([settings.stand_position_sd_m ** 2, settings.stand_position_sd_m ** 2, heading_sd ** 2,
                                   scale_variance])  # K's error stays the walker's; the track restarts here

    def snapshot(self) -> PdrState:
        return PdrState(self.time_ns, self.x_m, self.y_m, self.heading_offset_rad, self.covariance[:3, :3].copy(),
                        np.array(self.ahrs.get_quaternion()), np.array(self.bias.get_offset()), self.step_gain_m,
                        self.steps, None if self.stand is None else self.stand[0],
                        None if self.stand is None else self.stand[1], self.weinberg_since_stand, self.gaps,
                        self.backwards, math.sqrt(float(self.covariance[3, 3])))


def wrap(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def axis_angle(axis: int, angle_rad: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by angle_rad about earth axis 0, 1 or 2."""
    quaternion = np.zeros(4)
    quaternion[0] = math.cos(angle_rad / 2.0)
    quaternion[1 + axis] = math.sin(angle_rad / 2.0)
    return quaternion


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def levelled_quaternion(accel_g: np.ndarray) -> np.ndarray:
    """The attitude with zero yaw whose up axis is the measured gravity (specific force)."""
    up = accel_g / max(float(np.linalg.norm(accel_g)), 1e-9)
    roll = math.atan2(up[1], up[2])
    pitch = math.atan2(-up[0], math.hypot(up[1], up[2]))
    return quaternion_multiply(axis_angle(1, pitch), axis_angle(0, roll))

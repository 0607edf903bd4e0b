"""The waist's motion within steps, added to a person's pelvis path (activities.Plan).

Stepping speed v = the path's horizontal speed, or on the spot `turn_step_lever_m` x yaw rate
(turning steps), zero while sitting down, seated or rising. From v:
- step frequency f = sqrt(60 v / (W r)) / 60 (constant walk ratio W; r shortens backward and side
  steps at one cadence), clipped to the documented range, with step-to-step jitter (CV 2-3 %);
- step length s = v / f and the inverted pendulum's peak-to-peak bounce h = l - sqrt(l^2 - (s/2K)^2)
  (Zijlstra & Hof 2003), times the person's bounce factor and a per-step jitter. The vertical pelvis
  position is z = -h/2 (cos phi + c2/4 cos 2 phi), lowest at double support (phi = 0 mod 2 pi), so the
  vertical acceleration swings about (h/2)(2 pi f)^2 at the step frequency; with h ~ s^2 that grows
  like v^2, and the heel-strike transient at each foot contact (a Gaussian, peak ~ speed) adds a
  part linear in v. Both together give the paper's near-linear speed-acceleration relation;
- forward speed swings within a step by recovery x g h / v (pendulum energy exchange), fastest at
  double support; the pelvis sways sideways at stride frequency and rotates (yaw +-4 deg, list +-4
  deg, tilt +-2 deg at about 1.3 m/s, Saunders et al. 1953), scaled with speed.
Sitting: the pelvis drops from standing sensor height to seat + `seated_sensor_above_seat_m`
(minimum jerk over the transition), pitches forward up to `sit_pitch_deg` mid-transition and sits
at `seated_pitch_deg`. The head (what a camera tracks) leans forward of the pelvis with the pitch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

from sim_devices.room.activities import Activity, Plan
from sim_devices.room.params import GaitParams, RoomParams
from sim_devices.room.person import Person, bounce_m, step_frequency_hz

STANDARD_GRAVITY = 9.80665
SPEED_SMOOTH_S = 0.4  # stepping speed is averaged over this (a step) before setting cadence and bounce
JITTER_TIME_S = 0.5  # correlation time of step-to-step jitter (about one step)
SWAY_FULL_MPS = 0.5  # lateral sway and pelvis rotation reach their figure at this speed ...
ROTATION_REFERENCE_MPS = 1.3
SURGE_FULL_MPS = 0.3  # the within-step surge fades out below this translation speed (turning on the spot)  # ... and rotation scales with speed / this (Saunders' figures at ordinary speed)
STILL_ACTIVITIES = (Activity.SIT_DOWN, Activity.SEATED, Activity.STAND_UP)


@dataclass(frozen=True)
class BodyMotion:
    """One person's pelvis and head at the IMU rate: world frame, x y z in m, angles in rad."""

    pelvis_m: np.ndarray  # (n, 3) pelvis centre
    yaw_rad: np.ndarray  # (n,) facing + pelvic rotation
    pitch_rad: np.ndarray  # (n,) forward lean positive
    roll_rad: np.ndarray  # (n,) left side up positive
    heel_strike_mps2: np.ndarray  # (n,) vertical transient at foot contacts (added to the acceleration)
    head_xy_m: np.ndarray  # (n, 2) head top, horizontal
    step_frequency_hz: np.ndarray  # (n,) 0 when not stepping
    stepping_speed_mps: np.ndarray  # (n,)


def body_motion(plan: Plan, index: int, person: Person, params: RoomParams, rng: np.random.Generator) -> BodyMotion:
    """Add steps, sway, rotation and sitting to person `index`'s path; draws from `rng` in a fixed order."""
    gait = params.gait
    rate = params.sensors.rate_hz
    n = len(plan.time_s)
    activity = plan.activity[:, index]
    x, y, facing = plan.x_m[:, index], plan.y_m[:, index], plan.heading_rad[:, index]
    vx, vy = np.gradient(x, 1.0 / rate), np.gradient(y, 1.0 / rate)
    speed = np.hypot(vx, vy)
    yaw_rate = np.gradient(facing, 1.0 / rate)
    still = np.isin(activity, STILL_ACTIVITIES)
    stepping = _average(np.where(still, 0.0, np.hypot(speed, gait.turn_step_lever_m * yaw_rate)), rate, SPEED_SMOOTH_S)
    ratio = _average(_step_ratio(activity, params), rate, SPEED_SMOOTH_S)
    jitter = 1.0 + gait.step_time_cv * _red_noise(n, rate, rng)
    amplitude_jitter = np.maximum(1.0 + gait.step_amplitude_cv * _red_noise(n, rate, rng), 0.2)
    frequency = np.clip(step_frequency_hz(stepping, person.walk_ratio_m_per_spm, ratio, params) * jitter,
                        gait.min_step_frequency_hz, gait.max_step_frequency_hz)
    phase = 2.0 * math.pi * np.cumsum(frequency) / rate
    step_length = stepping / frequency
    bounce = bounce_m(step_length, person.leg_length_m, params) * person.bounce_factor * amplitude_jitter
    vertical = -0.5 * bounce * (np.cos(phase) + 0.25 * gait.second_harmonic * np.cos(2.0 * phase))
    # pendulum energy exchange: forward speed swing (peak to peak) = recovery g h / v, at most half of v
    swing = np.minimum(gait.energy_recovery * STANDARD_GRAVITY * bounce / np.maximum(stepping, 1e-3), 0.5 * stepping)
    surge = 0.5 * swing / (2.0 * math.pi * frequency) * np.sin(phase)
    # along the travel direction, faded out below SURGE_FULL_MPS (v / max(|v|, V0) is continuous; a
    # direction from a near-zero velocity would jump)
    mean_v = np.stack([_average(vx, rate, SPEED_SMOOTH_S), _average(vy, rate, SPEED_SMOOTH_S)], axis=1)
    along = mean_v / np.maximum(np.hypot(mean_v[:, 0], mean_v[:, 1]), SURGE_FULL_MPS)[:, None]
    level = np.clip(stepping / SWAY_FULL_MPS, 0.0, 1.0)
    # side steps carry the pelvis sideways already: no sway on top (faded in and out, never switched)
    forwards = 1.0 - _average((activity == Activity.WALK_SIDEWAYS).astype(float), rate, SPEED_SMOOTH_S)
    sway = gait.lateral_sway_m * person.sway_factor * level * forwards * np.sin(0.5 * phase)
    x_pelvis = x + surge * along[:, 0] - sway * np.sin(facing)
    y_pelvis = y + surge * along[:, 1] + sway * np.cos(facing)
    drop, posture = _sitting(plan, index, person, params)
    rotation_scale = person.sway_factor * np.clip(stepping / ROTATION_REFERENCE_MPS, 0.0, 1.5)
    yaw = facing - math.radians(gait.pelvic_rotation_deg) * rotation_scale * np.cos(0.5 * phase)
    roll = math.radians(gait.pelvic_list_deg) * rotation_scale * np.sin(0.5 * phase)
    pitch = posture + math.radians(gait.pelvic_tilt_deg) * rotation_scale * np.sin(phase)
    lean = gait.trunk_lean_share * (person.height_m - person.sensor_height_m) * np.sin(posture)
    head = np.stack([x_pelvis + lean * np.cos(facing), y_pelvis + lean * np.sin(facing)], axis=1)
    pelvis = np.stack([x_pelvis, y_pelvis, person.sensor_height_m + drop + vertical], axis=1)
    heel = _heel_strikes(phase, stepping, person, params)
    return BodyMotion(pelvis, yaw, pitch, roll, heel, head, np.where(stepping > 0.05, frequency, 0.0), stepping)


def _step_ratio(activity: np.ndarray, params: RoomParams) -> np.ndarray:
    ratio = np.ones(len(activity))
    ratio[activity == Activity.WALK_BACKWARD] = params.gait.backward_step_ratio
    ratio[(activity == Activity.WALK_SIDEWAYS) | (activity == Activity.TURN)] = params.gait.sideways_step_ratio
    return ratio


def _average(values: np.ndarray, rate: float, window_s: float) -> np.ndarray:
    """Centred moving average over `window_s` (edges use the samples there are)."""
    width = max(1, int(round(window_s * rate)))
    kernel = np.ones(width)
    total = np.convolve(values, kernel, mode="same")
    count = np.convolve(np.ones(len(values)), kernel, mode="same")
    return total / count


def _red_noise(n: int, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-SD smooth noise varying over about JITTER_TIME_S: white noise low-passed (zero phase).

    Smooth, not merely continuous: the jitter multiplies positions whose second difference is the
    accelerometer signal, and a random walk's per-sample steps would read as broadband noise."""
    white = rng.normal(0.0, 1.0, n)
    if n < 64:
        return np.zeros(n)
    sos = butter(2, 1.0 / (2.0 * math.pi * JITTER_TIME_S), fs=rate, output="sos")
    smooth = np.asarray(sosfiltfilt(sos, white, padlen=min(n - 1, int(4 * rate))))
    return smooth / max(float(smooth.std()), 1e-12)


def _heel_strikes(phase: np.ndarray, stepping: np.ndarray, person: Person, params: RoomParams) -> np.ndarray:
    """Vertical transients (m/s^2) at each foot contact (phase crossing a multiple of 2 pi)."""
    gait = params.gait
    rate = params.sensors.rate_hz
    contact = np.flatnonzero(np.diff(np.floor(phase / (2.0 * math.pi))) > 0) + 1
    impulses = np.zeros(len(phase))
    impulses[contact] = gait.heel_strike_g_per_mps * STANDARD_GRAVITY * person.heel_strike_factor * stepping[contact]
    width = gait.heel_strike_ms * 1e-3 * rate
    reach = int(math.ceil(4.0 * width))
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) / width) ** 2)
    # zero-mean over the step: the body does not gain vertical speed from a heel strike
    pulses = np.convolve(impulses, kernel, mode="same")
    return pulses - _average(pulses, rate, 1.0 / max(params.gait.min_step_frequency_hz, 1e-3))


def _sitting(plan: Plan, index: int, person: Person, params: RoomParams) -> tuple[np.ndarray, np.ndarray]:
    """(height change m, posture pitch rad) from the person's sit-downs, seated spells and stand-ups."""
    gait = params.gait
    full_drop = (params.room.seat_height_m + gait.seated_sensor_above_seat_m) - person.sensor_height_m
    seated = plan.activity[:, index] == Activity.SEATED
    drop = np.where(seated, full_drop, 0.0)
    pitch = np.where(seated, math.radians(gait.seated_pitch_deg), 0.0)
    for transition in (t for t in plan.transitions if t.person == index):
        _profile(transition.start, transition.end, transition.down, full_drop, gait, drop, pitch)
    return drop, pitch


def _profile(start: int, end: int, down: bool, full_drop: float, gait: GaitParams, drop: np.ndarray,
             pitch: np.ndarray) -> None:
    """Write one transition's profile over samples [start, end) (clipped to the session)."""
    if start >= len(drop):
        return
    s = np.linspace(0.0, 1.0, max(end - start, 1))
    share = s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)
    if not down:
        share = 1.0 - share
    lean = math.radians(gait.sit_pitch_deg) * np.sin(math.pi * s) ** 2
    stop = min(end, len(drop))
    drop[start:stop] = (full_drop * share)[:stop - start]
    pitch[start:stop] = (lean + math.radians(gait.seated_pitch_deg) * share)[:stop - start]

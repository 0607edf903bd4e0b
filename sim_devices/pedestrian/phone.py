"""Where the phone is and how it is turned, sample by sample, and the exact signals that follow.

Frames. Venue: x, y on the floor, z up; headings counter-clockwise from +x. Phone (Android): x to
the right of the screen, y to its top edge, z out of the screen. A phone lying flat with its top
towards heading psi has R = Rz(psi - 90 deg); pitch raises the top edge (about phone x), roll
turns about phone y: R = Rz(yaw - 90 deg) Rx(pitch) Ry(roll) (phone-to-venue).

- Hand: ahead of and right of the body centre at elbow height, bouncing with the body; yaw = body
  yaw (path heading + torso sway) + the grip's yaw offset + wrist sway; pitch and roll = the grip's
  + arm swing at step frequency + slow wander. A new grip (offset, pitch, roll) is taken over
  `GRIP_CHANGE_S` at random times while walking, and after each stand.
- Pocket: on the front of the right thigh, `along_thigh_m` below the hip joint; the thigh swings
  (flexion positive) at stride frequency. Per insertion (the start, and after each stand): top up
  or down, screen out or in, a rotation about the thigh axis in +-pocket_angle_max_deg, a tilt.
- Stand: during a stand window the phone moves (position linearly, attitude by slerp, smoothstep
  in time) from its mount to the stand's corner, lies still at the stand's pose (heading, tilt)
  plus a placement yaw error, and is picked up the same way.

Signals: specific force = R^T (second difference of the position + g z) in g; angular rate =
vee(R^T dR/dt) in deg/s; field = R^T B(position) in uT.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from protocol.messages import STANDARD_GRAVITY_MS2 as STANDARD_GRAVITY
from protocol.session import Mount, Stand
from sim_devices.common import angular_rate, small_rotation
from sim_devices.pedestrian.params import PedestrianParams
from sim_devices.pedestrian.path import SmoothPath
from sim_devices.pedestrian.person import Person
from sim_devices.pedestrian.timeline import Timeline

GRIP_CHANGE_S = 0.6  # a new grip is taken over this long
WANDER_TONES = 5  # sinusoids making up the slow hand wander, 0.2-2 Hz
THIGH_FRONT_M = 0.07  # the pocket lies on the front of the thigh, this far from its axis (half a thigh depth)
# The path's curvature jumps where an arc meets a straight, so its tangent's turn rate steps; the
# body's yaw follows it smoothed over this SD (a turn is prepared over a step), which keeps the
# hand (0.35 m ahead) from an impulse of tangential acceleration.
YAW_SMOOTHING_S = 0.15


@dataclass(frozen=True)
class StandWindow:
    """One phone's visit to a stand, in walker time (s): placed from `place_s`, still from `still_s`
    to `pick_s`, back at its mount at `done_s`."""

    stand: Stand
    place_s: float
    still_s: float
    pick_s: float
    done_s: float
    placement_rad: float

    @property
    def scan_s(self) -> float:
        return (self.still_s + self.pick_s) / 2.0


@dataclass(frozen=True)
class PhoneMotion:
    position_m: np.ndarray  # (n, 3) venue frame
    rotation: np.ndarray  # (n, 3, 3) phone-to-venue
    windows: tuple[StandWindow, ...]
    holds: tuple[dict, ...]  # each grip or insertion: start time and its draws (truth)


def flat_rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(n, 3, 3) Rz(yaw - 90 deg) Rx(pitch) Ry(roll), radians."""
    euler = np.stack([yaw - math.pi / 2, pitch, roll], axis=1)
    return Rotation.from_euler("ZXY", euler).as_matrix()


def _wander(time_s: np.ndarray, sd: float, rng: np.random.Generator) -> np.ndarray:
    frequencies = rng.uniform(0.2, 2.0, WANDER_TONES)
    phases = rng.uniform(0.0, 2 * math.pi, WANDER_TONES)
    tones = np.sin(2 * math.pi * frequencies[None, :] * time_s[:, None] + phases[None, :])
    return sd * math.sqrt(2.0 / WANDER_TONES) * tones.sum(axis=1)


def _body_path(path: SmoothPath, timeline: Timeline) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, body yaw) per sample: the path point and its tangent, smoothed over YAW_SMOOTHING_S."""
    x, y, heading = path.at(timeline.s_m)
    step_s = float(timeline.time_s[1] - timeline.time_s[0]) if len(timeline.time_s) > 1 else 1.0
    return x, y, gaussian_filter1d(heading, YAW_SMOOTHING_S / step_s, mode="nearest")


def _hold_starts(timeline: Timeline, windows: list[StandWindow], rate_per_min: float,
                 rng: np.random.Generator) -> list[tuple[float, bool]]:
    """(time, smooth) of each new grip or insertion: 0, random times while walking, each pick-up."""
    duration = float(timeline.time_s[-1])
    count = rng.poisson(rate_per_min * duration / 60.0)
    candidates = np.sort(rng.uniform(0.0, duration, count))
    moving = np.interp(candidates, timeline.time_s, timeline.speed_mps) > 0.3
    starts = [(0.0, False)] + [(float(t), True) for t in candidates[moving]]
    starts += [(w.pick_s, False) for w in windows]
    return sorted(starts)


def _segments(time_s: np.ndarray, starts: list[tuple[float, bool]], values: np.ndarray) -> np.ndarray:
    """Per sample, each hold's value (rows of `values`), smoothed over GRIP_CHANGE_S where `smooth`."""
    out = np.repeat(values[:1], len(time_s), axis=0)
    for index, (start, smooth) in enumerate(starts[1:], start=1):
        weight = np.clip((time_s - start) / GRIP_CHANGE_S, 0.0, 1.0) if smooth else (time_s >= start).astype(float)
        weight = weight * weight * (3 - 2 * weight)
        out = out + weight[:, None] * (values[index] - values[index - 1])[None, :]
    return out


def hand_pose(path: SmoothPath, timeline: Timeline, person: Person, params: PedestrianParams,
              starts: list[tuple[float, bool]], rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    hand, gait = params.hand, params.gait
    t, share, phase = timeline.time_s, timeline.speed_share, timeline.phase
    x, y, heading = _body_path(path, timeline)
    draws = np.column_stack([rng.normal(0.0, hand.yaw_offset_sd_deg, len(starts)),
                             rng.normal(hand.pitch_mean_deg, hand.attitude_sd_deg, len(starts)),
                             rng.normal(0.0, hand.attitude_sd_deg, len(starts))])
    grip = np.radians(_segments(t, starts, draws))
    stride = math.pi * phase
    body_yaw = heading + math.radians(gait.torso_yaw_deg) * share * np.sin(stride)
    lateral = gait.lateral_sway_m * share * np.cos(stride)
    forward_x, forward_y = np.cos(heading), np.sin(heading)
    offset_x = hand.forward_m * np.cos(body_yaw) + hand.right_m * np.sin(body_yaw)
    offset_y = hand.forward_m * np.sin(body_yaw) - hand.right_m * np.cos(body_yaw)
    bounce = hand.bounce_ratio * gait.bounce_m * share * np.cos(2 * math.pi * phase)
    position = np.column_stack([
        x - lateral * forward_y + offset_x + _wander(t, hand.tremor_m, rng),
        y + lateral * forward_x + offset_y + _wander(t, hand.tremor_m, rng),
        params.people.hand_height_ratio * person.height_m + bounce + _wander(t, hand.tremor_m, rng)])
    sway, tremor = math.radians(hand.sway_deg), math.radians(hand.tremor_deg)
    yaw = body_yaw + grip[:, 0] + math.radians(hand.yaw_sway_deg) * share * np.sin(stride) + _wander(t, tremor, rng)
    pitch = grip[:, 1] + sway * share * np.cos(2 * stride) + _wander(t, tremor, rng)
    roll = grip[:, 2] + sway * share * np.sin(stride) + _wander(t, tremor, rng)
    holds = [{"time_s": s, "yaw_offset_deg": float(d[0]), "pitch_deg": float(d[1]), "roll_deg": float(d[2])}
             for (s, _), d in zip(starts, draws)]
    return position, flat_rotation(yaw, pitch, roll), holds


# Phone axes in the thigh frame (x' front, y' left, z' up along the thigh): top up, screen out.
_POCKET_BASE = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def pocket_pose(path: SmoothPath, timeline: Timeline, person: Person, params: PedestrianParams,
                starts: list[tuple[float, bool]], rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    pocket, gait = params.pocket, params.gait
    t, share, phase = timeline.time_s, timeline.speed_share, timeline.phase
    x, y, heading = _body_path(path, timeline)
    stride = math.pi * phase
    body_yaw = heading + math.radians(gait.torso_yaw_deg) * 0.5 * share * np.sin(stride)  # pelvis turns less
    lateral = gait.lateral_sway_m * share * np.cos(stride) - pocket.lateral_m  # right pocket
    thigh = np.radians(pocket.thigh_mean_deg * np.minimum(share, 1.0)
                       + pocket.thigh_swing_deg * share * np.sin(stride))
    hip = np.column_stack([x - lateral * np.sin(body_yaw), y + lateral * np.cos(body_yaw),
                           params.people.hip_height_ratio * person.height_m
                           + gait.bounce_m * share * np.cos(2 * math.pi * phase)])
    body = Rotation.from_euler("Z", body_yaw[:, None]).as_matrix()
    thigh_rotation = body @ Rotation.from_euler("Y", -thigh[:, None]).as_matrix()
    local = np.array([THIGH_FRONT_M, 0.0, -pocket.along_thigh_m])
    position = hip + thigh_rotation @ local
    holds, mounts = [], []
    for start, _ in starts:
        top_down, screen_in = bool(rng.random() < 0.5), bool(rng.random() < 0.5)
        angle = float(rng.uniform(-pocket.pocket_angle_max_deg, pocket.pocket_angle_max_deg))
        tilt = small_rotation(rng, pocket.tilt_sd_deg)
        flip = np.diag([-1.0, -1.0, 1.0]) if top_down else np.eye(3)
        turn = np.diag([-1.0, 1.0, -1.0]) if screen_in else np.eye(3)
        mounts.append(Rotation.from_euler("Z", math.radians(angle)).as_matrix() @ _POCKET_BASE @ flip @ turn @ tilt)
        holds.append({"time_s": start, "top_down": top_down, "screen_in": screen_in, "thigh_angle_deg": angle})
    index = np.searchsorted(np.array([s for s, _ in starts]), t, side="right") - 1
    rotation = thigh_rotation @ np.stack(mounts)[index]
    return position, rotation, holds


def stand_windows(timeline: Timeline, stands: dict[str, Stand], phones: int, params: PedestrianParams,
                  rng: np.random.Generator) -> list[list[StandWindow]]:
    """Per phone, its stand windows: at each stand stop the phones are placed one after the other.
    At the walk's first stand the first phone is already on it when the recording starts."""
    timing = params.stand
    out: list[list[StandWindow]] = [[] for _ in range(phones)]
    for stop in timeline.stops:
        if not stop.stand_id:
            continue
        begin = stop.start_s
        for phone in range(phones):
            place = begin - timing.place_s if begin == 0.0 and phone == 0 else begin
            still = place + timing.place_s
            pick = still + timing.still_s
            error = math.radians(float(rng.normal(0.0, timing.placement_deg)))
            out[phone].append(StandWindow(stands[stop.stand_id], place, still, pick, pick + timing.pick_s, error))
            begin = pick + timing.pick_s
    return out


def phone_motion(mount: Mount, path: SmoothPath, timeline: Timeline, person: Person, windows: list[StandWindow],
                 params: PedestrianParams, rng: np.random.Generator) -> PhoneMotion:
    rate = params.hand.grip_change_per_min if mount is Mount.HAND else 0.0
    starts = _hold_starts(timeline, windows, rate, rng)
    pose = hand_pose if mount is Mount.HAND else pocket_pose
    position, rotation, holds = pose(path, timeline, person, params, starts, rng)
    t = timeline.time_s
    for window in windows:
        stand = window.stand
        target_p = np.array([stand.x_m, stand.y_m, params.stand.height_m])
        target_r = flat_rotation(np.array([math.radians(stand.heading_deg) + window.placement_rad]),
                                 np.array([math.radians(stand.tilt_deg)]), np.zeros(1))[0]
        weight = np.where(t < window.still_s, (t - window.place_s) / params.stand.place_s,
                          1.0 - (t - window.pick_s) / params.stand.pick_s)
        weight = np.clip(np.where((t >= window.still_s) & (t <= window.pick_s), 1.0, weight), 0.0, 1.0)
        weight[(t < window.place_s) | (t > window.done_s)] = 0.0
        weight = weight * weight * (3 - 2 * weight)
        rows = np.flatnonzero(weight > 0)
        if not len(rows):
            continue
        w = weight[rows]
        position[rows] = (1 - w)[:, None] * position[rows] + w[:, None] * target_p[None, :]
        start = Rotation.from_matrix(rotation[rows])
        relative = (start.inv() * Rotation.from_matrix(np.repeat(target_r[None], len(rows), axis=0))).as_rotvec()
        rotation[rows] = (start * Rotation.from_rotvec(w[:, None] * relative)).as_matrix()
    return PhoneMotion(position, rotation, tuple(windows), tuple(holds))


def exact_signals(motion: PhoneMotion, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Error-free (specific force g, angular rate deg/s), (n, 3) each, in the phone frame."""
    position = motion.position_m
    accel = np.empty_like(position)
    accel[1:-1] = (position[2:] - 2.0 * position[1:-1] + position[:-2]) * rate_hz * rate_hz
    accel[0], accel[-1] = accel[1], accel[-2]
    accel[:, 2] += STANDARD_GRAVITY
    specific = np.einsum("nji,nj->ni", motion.rotation, accel) / STANDARD_GRAVITY
    return specific, np.degrees(angular_rate(motion.rotation, rate_hz))

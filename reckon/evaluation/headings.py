"""The three headings the paper's dead reckoning is run with: true, video-derived, magnetometer.

The paper never recorded the magnetometer in its game; it used the movement direction read off
10 fps video (sec. 4.1). `video_heading` rebuilds that from the truth: positions sampled at 10 fps
with tracking noise, smoothed, differenced; direction held while the chair is nearly still.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from edge.chair.paper.mag_heading import magnetometer_heading
from reckon.evaluation.inputs import FRAME_HZ, GRID_HZ, AgentInputs, EvalInputs



@dataclass(frozen=True)
class VideoModel:
    """How the paper's video-derived heading is rebuilt."""

    # Position noise of video tracking, 1 sigma per axis per frame. Commercial multi-camera
    # tracking is about 0.1 m (Linke et al. 2020, PLoS ONE 15:e0230179, TRACAB); hand or
    # single-camera annotation of practice footage, as in the paper, is worse (assumption:
    # 0.2-0.3 m). Default: the middle value.
    position_noise_m: float = 0.15
    smoothing_frames: int = 5  # centred moving average, 0.5 s: what an analyst's smoother would do
    min_speed_mps: float = 0.3  # below this the direction of motion is noise: hold the last one
    # Video clock minus sensor clock. The paper does not say how video and sensors were aligned;
    # 0 assumes perfectly. Used only to show what a misalignment would cost (`reckon calibrate`).
    sync_offset_s: float = 0.0


class HeadingSource(str, enum.Enum):
    TRUE = "true"
    VIDEO = "video"
    SENSORS = "sensors"


def true_heading(agent: AgentInputs) -> np.ndarray:
    if agent.truth_heading_rad is None:
        raise ValueError(f"agent {agent.agent.id}: no truth, so no true heading")
    return agent.truth_heading_rad


def video_heading(inputs: EvalInputs, agent: AgentInputs, rng: np.random.Generator,
                  model: VideoModel = VideoModel()) -> np.ndarray:
    """Movement direction from noisy 10 fps positions, on the grid (unwrapped).

    Direction of motion points backwards during a backward push, while eq. 1-2 move the chair by
    signed wheel travel along psi; so psi is the motion direction turned by pi where the wheels
    roll backwards (the only reading of the paper under which backward pushes come out right).
    """
    if agent.truth_x_m is None:
        raise ValueError(f"agent {agent.agent.id}: no truth, so no video")
    frames = inputs.frame_index
    noise = rng.normal(0.0, model.position_noise_m, size=(len(frames), 2))
    x = _smooth(agent.truth_x_m[frames] + noise[:, 0], model.smoothing_frames)
    y = _smooth(agent.truth_y_m[frames] + noise[:, 1], model.smoothing_frames)
    vx = np.gradient(x) * FRAME_HZ
    vy = np.gradient(y) * FRAME_HZ
    direction = np.arctan2(vy, vx)
    moving = np.hypot(vx, vy) >= model.min_speed_mps
    held = np.empty_like(direction)
    last = agent.start_pose()[2]  # the start heading is known, as the start position is
    for k in range(len(direction)):
        if moving[k]:
            last = direction[k]
        held[k] = last
    # the heading used at sensor time t is the one the video shows at t + offset
    heading = np.interp(np.arange(len(inputs.grid_ns)) + model.sync_offset_s * GRID_HZ, frames, np.unwrap(held))
    backward = np.concatenate([agent.travel_m, [0.0]]) < 0.0
    return heading + np.pi * backward


def sensor_heading(inputs: EvalInputs, agent: AgentInputs) -> np.ndarray:
    if agent.seat_mag is None:
        raise ValueError(f"agent {agent.agent.id}: the seat sensor has no magnetometer")
    start_heading = agent.start_pose()[2]
    heading = magnetometer_heading(agent.seat_time_ns, agent.seat_mag, start_heading)
    return np.interp(inputs.grid_ns, agent.seat_time_ns, heading)


def headings(inputs: EvalInputs, source: HeadingSource, rng: np.random.Generator,
             video: VideoModel = VideoModel()) -> list[np.ndarray]:
    """Heading on the grid for every agent from `source`."""
    if source is HeadingSource.TRUE:
        return [true_heading(a) for a in inputs.agents]
    if source is HeadingSource.VIDEO:
        return [video_heading(inputs, a, rng, video) for a in inputs.agents]
    return [sensor_heading(inputs, a) for a in inputs.agents]


def _smooth(values: np.ndarray, frames: int) -> np.ndarray:
    if frames <= 1:
        return values
    kernel = np.ones(frames) / frames
    padded = np.pad(values, (frames // 2, frames - 1 - frames // 2), mode="edge")
    return np.convolve(padded, kernel, mode="valid")



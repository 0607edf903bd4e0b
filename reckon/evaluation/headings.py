"""The three headings the paper's dead reckoning is run with: true, video-derived, magnetometer.

The paper never recorded the magnetometer in its game; it used the movement direction read off
10 fps video (sec. 4.1). `video_heading` rebuilds that from the truth: positions sampled at 10 fps
with tracking noise, smoothed, differenced; direction held while the chair is nearly still.
"""

from __future__ import annotations

import enum

import numpy as np

from edge.mag_heading import magnetometer_heading
from reckon.evaluation.inputs import FRAME_HZ, AgentInputs, EvalInputs

# Position noise of video tracking, 1 sigma per axis per frame. Commercial multi-camera tracking
# is about 0.1 m (Linke et al. 2020, PLoS ONE 15:e0230179, TRACAB); hand or single-camera
# annotation of practice footage, as in the paper, is worse (assumption: 0.2-0.3 m). Middle value.
VIDEO_POSITION_NOISE_M = 0.15
VIDEO_SMOOTHING_FRAMES = 5  # centred moving average, 0.5 s: what an analyst's smoother would do
VIDEO_MIN_SPEED_MPS = 0.3  # below this the direction of motion is noise: hold the last one


class HeadingSource(str, enum.Enum):
    TRUE = "true"
    VIDEO = "video"
    SENSORS = "sensors"


def true_heading(agent: AgentInputs) -> np.ndarray:
    if agent.truth_heading_rad is None:
        raise ValueError(f"agent {agent.agent.id}: no truth, so no true heading")
    return agent.truth_heading_rad


def video_heading(inputs: EvalInputs, agent: AgentInputs, rng: np.random.Generator) -> np.ndarray:
    """Movement direction from noisy 10 fps positions, on the grid (unwrapped).

    Direction of motion points backwards during a backward push, while eq. 1-2 move the chair by
    signed wheel travel along psi; so psi is the motion direction turned by pi where the wheels
    roll backwards (the only reading of the paper under which backward pushes come out right).
    """
    if agent.truth_x_m is None:
        raise ValueError(f"agent {agent.agent.id}: no truth, so no video")
    frames = inputs.frame_index
    noise = rng.normal(0.0, VIDEO_POSITION_NOISE_M, size=(len(frames), 2))
    x = _smooth(agent.truth_x_m[frames] + noise[:, 0])
    y = _smooth(agent.truth_y_m[frames] + noise[:, 1])
    vx = np.gradient(x) * FRAME_HZ
    vy = np.gradient(y) * FRAME_HZ
    direction = np.arctan2(vy, vx)
    moving = np.hypot(vx, vy) >= VIDEO_MIN_SPEED_MPS
    held = np.empty_like(direction)
    last = agent.start_pose()[2]  # the start heading is known, as the start position is
    for k in range(len(direction)):
        if moving[k]:
            last = direction[k]
        held[k] = last
    heading = np.interp(np.arange(len(inputs.grid_ns)), frames, np.unwrap(held))
    backward = np.concatenate([agent.travel_m, [0.0]]) < 0.0
    return heading + np.pi * backward


def sensor_heading(inputs: EvalInputs, agent: AgentInputs) -> np.ndarray:
    if agent.seat_mag is None:
        raise ValueError(f"agent {agent.agent.id}: the seat sensor has no magnetometer")
    start_heading = agent.start_pose()[2]
    heading = magnetometer_heading(agent.seat_time_ns, agent.seat_mag, start_heading)
    return np.interp(inputs.grid_ns, agent.seat_time_ns, heading)


def headings(inputs: EvalInputs, source: HeadingSource, rng: np.random.Generator) -> list[np.ndarray]:
    """Heading on the grid for every agent from `source`."""
    if source is HeadingSource.TRUE:
        return [true_heading(a) for a in inputs.agents]
    if source is HeadingSource.VIDEO:
        return [video_heading(inputs, a, rng) for a in inputs.agents]
    return [sensor_heading(inputs, a) for a in inputs.agents]


def _smooth(values: np.ndarray) -> np.ndarray:
    kernel = np.ones(VIDEO_SMOOTHING_FRAMES) / VIDEO_SMOOTHING_FRAMES
    padded = np.pad(values, VIDEO_SMOOTHING_FRAMES // 2, mode="edge")
    return np.convolve(padded, kernel, mode="valid")



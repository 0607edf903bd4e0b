"""Per-agent inputs on a common time grid, read from a session log.

The paper's method uses the sensors' own timestamps as if all clocks agreed (it never aligns them),
so the grid is in device time; truth is interpolated onto the same times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from edge.chair.paper.impacts import detect_impacts
from edge.mounting import seat_to_chair, signed_axis
from edge.chair.paper.wheel import chair_travel_m, travel_from_rotation_m, wheel_rotation_deg
from protocol.errors import InputError
from protocol.session import Agent, Mount
from protocol.session_log import ImuSeries, SessionData

GRID_HZ = 200.0  # the paper's sensor rate
FRAME_HZ = 10.0  # the paper's video frame rate: errors are scored per frame, as in the paper
GRID_PER_FRAME = int(GRID_HZ / FRAME_HZ)


@dataclass
class AgentInputs:
    agent: Agent
    travel_m: np.ndarray  # chair travel per grid step (len grid - 1), signed
    truth_x_m: np.ndarray | None  # on the grid
    truth_y_m: np.ndarray | None
    truth_heading_rad: np.ndarray | None  # unwrapped
    seat_time_ns: np.ndarray | None
    seat_accel_g: np.ndarray | None  # chair frame
    seat_gyro_dps: np.ndarray | None  # chair frame
    seat_mag: np.ndarray | None  # chair frame, gauss
    raw: dict[str, ImuSeries]  # the agent's sensors as logged (sensor frame), for the live-path merger

    def start_pose(self) -> tuple[float, float, float]:
        """The known start pose: from truth where there is truth, else the session description."""
        heading = self.agent.start_heading_rad if self.truth_heading_rad is None else float(self.truth_heading_rad[0])
        if self.truth_x_m is not None:
            return float(self.truth_x_m[0]), float(self.truth_y_m[0]), heading
        return self.agent.start_x_m, self.agent.start_y_m, heading


@dataclass
class EvalInputs:
    grid_ns: np.ndarray  # int64, GRID_HZ from the session start
    agents: list[AgentInputs]

    @property
    def frame_index(self) -> np.ndarray:
        """Grid indices of the 10 Hz frames."""
        return np.arange(0, len(self.grid_ns), GRID_PER_FRAME)

    @property
    def frame_ns(self) -> np.ndarray:
        return self.grid_ns[self.frame_index]


def agent_impacts(inputs: EvalInputs, threshold_g: float) -> list[tuple[int, str]]:
    """(time_ns, agent) of every seat impact above `threshold_g`, over all agents."""
    impacts = []
    for agent in inputs.agents:
        if agent.seat_accel_g is not None:
            impacts += [(i.time_ns, agent.agent.id) for i in detect_impacts(agent.seat_time_ns, agent.seat_accel_g, threshold_g)]
    return impacts


def build_inputs(data: SessionData) -> EvalInputs:
    """Chair travel, truth and seat data per agent on one 200 Hz grid. InputError if unusable."""
    start, end = data.start_ns, data.end_ns
    if end - start < 1e9:
        raise InputError(f"session spans {(end - start) / 1e9:.3f} s; at least 1 s of data is needed")
    grid = start + np.arange(0, end - start + 1, int(1e9 / GRID_HZ), dtype=np.int64)
    agents = []
    for agent in data.session.agents:
        wheels = []
        for mount in (Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL):
            sensor = agent.sensor(mount)
            series = data.imu.get(sensor.id) if sensor else None
            if series is None or len(series.time_ns) < 2:
                raise InputError(f"agent {agent.id}: no {mount.value} samples; the paper's method needs both wheels")
            rotation = wheel_rotation_deg(series.time_ns, signed_axis(series.gyro_dps, sensor.spin_axis))
            wheels.append(travel_from_rotation_m(np.interp(grid, series.time_ns, rotation), agent.wheel_diameter_m))
        travel = np.diff(chair_travel_m(wheels[0], wheels[1]))
        seat = agent.sensor(Mount.SEAT)
        seat_series = data.imu.get(seat.id) if seat else None
        seat_time = seat_accel = seat_gyro = seat_mag = None
        if seat_series is not None and len(seat_series.time_ns):
            seat_time = seat_series.time_ns
            seat_accel = seat_to_chair(seat_series.accel_g, seat.forward_axis, seat.left_axis)
            seat_gyro = seat_to_chair(seat_series.gyro_dps, seat.forward_axis, seat.left_axis)
            if seat_series.mag_gauss is not None:
                seat_mag = seat_to_chair(seat_series.mag_gauss, seat.forward_axis, seat.left_axis)
        truth = data.truth.get(agent.id)
        tx = ty = th = None
        if truth is not None and len(truth.time_ns) >= 2:
            tx = np.interp(grid, truth.time_ns, truth.x_m)
            ty = np.interp(grid, truth.time_ns, truth.y_m)
            if np.all(np.isfinite(truth.heading_rad)):  # truth from a CSV may have positions only
                th = np.interp(grid, truth.time_ns, np.unwrap(truth.heading_rad))
        agents.append(AgentInputs(agent, travel, tx, ty, th, seat_time, seat_accel, seat_gyro, seat_mag,
                                  {s.id: data.imu[s.id] for s in agent.sensors if s.id in data.imu}))
    return EvalInputs(grid, agents)

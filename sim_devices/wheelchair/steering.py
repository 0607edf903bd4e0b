"""Steering: each player's (speed, yaw-rate) command towards its tactical target, at 20 Hz.

Drive when the target is ahead (speed planned to stop on it), pivot on the spot when it is well
off the nose, push backward when it is behind and close, hold still with hysteresis when there
(turning only to face the play). Players avoid accidental hits with a sampling velocity obstacle
(`_steer_around`); a player making a block drives straight at its victim instead, which is where
most contacts come from (docs/simulator.md).
"""

from __future__ import annotations

import math

import numpy as np

from sim_devices.wheelchair.params import SimParams

CONTROL_HZ = 20.0  # tactical and steering update rate
TURN_GAIN_PER_S = 6.0  # yaw-rate command per rad of heading error
PIVOT_ERROR_RAD = 1.0  # heading error above which a moving chair pivots before driving (57 deg)
BACKWARD_ERROR_RAD = 2.0  # target this far behind the nose (115 deg) ...
BACKWARD_RANGE_M = 2.0  # ... and this close is reached by pushing backward
BACKWARD_GAIN_PER_S = 1.2  # backward speed per m of distance left (slow, short pushes)
FACE_START_RAD = 0.35  # a holding player turns to face when off by more than this (20 deg) ...
FACE_STOP_RAD = 0.05  # ... until within this
APPROACH_BRAKE_SHARE = 0.7  # plan arrivals with this share of the braking limit
AVOID_RANGE_M = 4.0  # other chairs farther than this are ignored
AVOID_HORIZON_S = 1.5  # look-ahead for near misses with moving chairs
AVOID_CLEARANCE_M = 1.1  # centre-to-centre distance kept (discs touch at 0.9 m)
AVOID_LOOKAHEAD_M = 2.0  # a detour must keep this much of its path inside the court
AVOID_STEPS_RAD = np.radians([0, 15, -15, 30, -30, 45, -45, 60, -60, 80, -80, 100, -100])  # candidate detours
AVOID_CONE_RAD = math.radians(20.0)  # chairs within this of the travel direction limit the speed


class Controller:
    """(speed m/s, yaw-rate rad/s) commands towards targets, with hold and facing hysteresis."""

    def __init__(self, players: int, params: SimParams, top_speed: np.ndarray, yaw_max: np.ndarray):
        self.params = params
        self.top_speed = top_speed.tolist()
        self.yaw_max = yaw_max.tolist()
        court = params.court
        self.bounds = (0.0, court.length_m, 0.0, court.width_m)
        self.holding = [True] * players
        self.turning = [False] * players

    def commands(self, positions: np.ndarray, headings: np.ndarray, speeds: np.ndarray, velocities: np.ndarray,
                 targets: np.ndarray, facing: np.ndarray, hold: np.ndarray,
                 charging: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (m/s) and yaw-rate (rad/s) commands; `charging[i]` = drive into others on purpose (a block)."""
        speed = np.zeros(len(headings))
        yaw = np.zeros(len(headings))
        moving = np.concatenate([positions, velocities], axis=1)
        for i in range(len(headings)):
            others = None if charging[i] else np.delete(moving, i, axis=0)
            speed[i], yaw[i] = self._one(i, *positions[i].tolist(), float(headings[i]), float(speeds[i]),
                                         *targets[i].tolist(), float(facing[i]), bool(hold[i]), others)
        return speed, yaw

    def _one(self, i: int, x: float, y: float, heading: float, speed: float, tx: float, ty: float, face: float,
             hold: bool, others: np.ndarray | None) -> tuple[float, float]:
        game, chair = self.params.game, self.params.chair
        if hold:
            self.holding[i], self.turning[i] = True, False
            return 0.0, 0.0
        distance = math.hypot(tx - x, ty - y)
        if self.holding[i] and distance > game.leave_m:
            self.holding[i] = False
        elif not self.holding[i] and distance < game.arrive_m:
            self.holding[i] = True
        yaw_max = self.yaw_max[i]
        if self.holding[i]:
            return 0.0, self._face(i, _wrap(face - heading), yaw_max)
        direction = math.atan2(ty - y, tx - x)
        bearing = _wrap(direction - heading)
        if abs(bearing) > BACKWARD_ERROR_RAD and distance < BACKWARD_RANGE_M:
            error = _wrap(bearing - math.pi)
            room = math.inf
            if others is not None and len(others):
                room = _steer_around(x, y, speed, direction, distance, others, self.bounds)[1]
            backward = min(chair.backward_speed_mps, BACKWARD_GAIN_PER_S * distance,
                           math.sqrt(2.0 * APPROACH_BRAKE_SHARE * chair.brake_mps2 * room))
            return -backward, _clip(TURN_GAIN_PER_S * error, yaw_max)
        room = math.inf
        if others is not None and len(others):
            direction, room = _steer_around(x, y, speed, direction, distance, others, self.bounds)
            bearing = _wrap(direction - heading)
        if abs(bearing) > PIVOT_ERROR_RAD:
            return 0.0, math.copysign(yaw_max, bearing)
        approach = math.sqrt(2.0 * APPROACH_BRAKE_SHARE * chair.brake_mps2 * min(distance, room))
        return min(self.top_speed[i], approach) * math.cos(bearing) ** 2, _clip(TURN_GAIN_PER_S * bearing, yaw_max)

    def _face(self, i: int, error: float, yaw_max: float) -> float:
        """Yaw-rate command of a holding player: turn to face the play, with hysteresis."""
        if abs(error) > FACE_START_RAD:
            self.turning[i] = True
        elif abs(error) < FACE_STOP_RAD:
            self.turning[i] = False
        return _clip(TURN_GAIN_PER_S * error, yaw_max) if self.turning[i] else 0.0


def _steer_around(x: float, y: float, speed: float, direction: float, distance: float,
                  others: np.ndarray, bounds: tuple[float, float, float, float]) -> tuple[float, float]:
    """Travel direction nearest the wanted one that keeps clear of the other chairs, and the room (m) along it.

    `others` rows are (x, y, vx, vy). A sampling velocity obstacle: for candidate directions
    (wanted +- AVOID_STEPS_RAD), with both chairs keeping their velocities (own: `speed`, at
    least 0.5 m/s) for AVOID_HORIZON_S, the closest approach to every chair nearer than the
    target is found; the first candidate that stays AVOID_CLEARANCE_M clear is taken, else the
    one with the widest miss. Others moving are doing the same. A detour whose first
    AVOID_LOOKAHEAD_M leaves `bounds` (x_low, x_high, y_low, y_high) counts as no clearance.
    """
    offsets = others[:, :2] - (x, y)
    gaps = np.hypot(offsets[:, 0], offsets[:, 1])
    relevant = gaps < min(distance + AVOID_CLEARANCE_M, AVOID_RANGE_M)
    if relevant.any():
        offsets_r, velocities = offsets[relevant], others[relevant, 2:]
        candidates = direction + AVOID_STEPS_RAD
        own = max(abs(speed), 0.5) * np.stack([np.cos(candidates), np.sin(candidates)], 1)  # (C, 2)
        closing = velocities[None, :, :] - own[:, None, :]  # (C, M, 2)
        rate = np.maximum(np.einsum("cmk,cmk->cm", closing, closing), 1e-9)
        when = np.clip(-np.einsum("mk,cmk->cm", offsets_r, closing) / rate, 0.0, AVOID_HORIZON_S)
        miss = np.hypot(*np.moveaxis(offsets_r[None] + closing * when[..., None], 2, 0)).min(axis=1)  # (C,)
        reach = min(distance, AVOID_LOOKAHEAD_M)
        end_x, end_y = x + reach * np.cos(candidates), y + reach * np.sin(candidates)
        inside = (end_x >= bounds[0]) & (end_x <= bounds[1]) & (end_y >= bounds[2]) & (end_y <= bounds[3])
        miss = np.where(inside, miss, miss - AVOID_RANGE_M)
        clear = np.flatnonzero(miss >= AVOID_CLEARANCE_M)
        direction = float(candidates[clear[0]] if len(clear) else candidates[int(np.argmax(miss))])
    angles = np.arctan2(offsets[:, 1], offsets[:, 0])
    ahead = np.abs((angles - direction + math.pi) % (2.0 * math.pi) - math.pi) < AVOID_CONE_RAD
    room = float(np.min(gaps[ahead & (gaps < AVOID_RANGE_M)], initial=math.inf)) - AVOID_CLEARANCE_M
    return direction, max(room, 0.0)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _clip(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))

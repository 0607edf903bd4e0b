"""Attitude of each body segment (pelvis, upper trunk, head) and of a kickboard, over a set.

Frames. World: x along the lanes, y across, z up. Body (every segment): x towards the head, y the
swimmer's left, z out of the back; a supine (backstroke) body has z pointing down. A segment's
attitude is yaw (about world z, left positive), pitch (head up positive), roll (about the body x
axis), R = Rz(yaw) Ry(-pitch) Rx(roll) [Rx(pi) when supine].

Each segment = the timeline's base (heading of travel, rest/turn pitch, push-off roll) + the
swimming posture weighted by `timeline.swim` (the trunk's inclination; the head's neck pitch;
the board's nose-up pitch) + stroke motions weighted by `timeline.activity`, with cycle phase
phi and per-cycle amplitude jitter:

| segment | roll | pitch | yaw |
|---|---|---|---|
| pelvis | hip roll sin(phi - 0.3) + half the breath roll + kick roll | pelvis_pitch sin(n phi + 1) | hip_yaw cos(phi) |
| trunk | shoulder roll sin(phi) + breath roll | trunk_pitch sin(n phi + 0.5) | shoulder_yaw cos(phi + 0.3) |
| head | follows head_follow of the trunk's roll; on a breath turns to head_breath_roll | trunk pitch + neck pitch + head lift on a forward breath + sighting | head_yaw cos(phi) |
| board | board_roll sin(phi + 1) | board pitch | board_yaw sin(phi) |

n = strokes per cycle (one pitch wave per arm stroke). Crawl breathes on the roll peak of every
`breath_every`-th arm stroke (stroke k rolls to the side (-1)^k, so every 3rd alternates sides);
breaststroke and butterfly breathe forward (head lift) in every `breath_every`-th cycle. At rest
every segment sways slowly (`walls.rest_sway_deg`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.swim.params import SwimParams
from sim_devices.swim.swimmer import Swimmer
from sim_devices.swim.timeline import Timeline

BREATH_WIDTH = 0.8  # a breath lasts this share of its stroke (crawl) or cycle (forward breathing)
SWAY_HZ = (0.23, 0.31, 0.37)  # rest sway frequencies (roll, pitch, yaw); assumption, floating body 0.2-0.4 Hz
HIP_LAG_RAD = 0.3  # hips reach peak roll a little after the shoulders; assumption
FORWARD_BREATHING = ("breaststroke", "butterfly")


@dataclass(frozen=True)
class Angles:
    """A segment's yaw, pitch, roll (rad) over the set, and whether the body lies supine."""

    yaw: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    supine: bool

    def matrices(self) -> np.ndarray:
        """(n, 3, 3) body-to-world rotations."""
        return rotation(self.yaw, self.pitch, self.roll, self.supine)


def rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray, supine: bool = False) -> np.ndarray:
    """Rz(yaw) Ry(-pitch) Rx(roll) [Rx(pi)] as (n, 3, 3)."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    if supine:
        cr, sr = -cr, -sr  # Rx(roll) Rx(pi) = Rx(roll + pi)
    matrix = np.empty((len(yaw), 3, 3))
    matrix[:, 0, 0] = cy * cp
    matrix[:, 0, 1] = -sy * cr - cy * sp * sr
    matrix[:, 0, 2] = sy * sr - cy * sp * cr
    matrix[:, 1, 0] = sy * cp
    matrix[:, 1, 1] = cy * cr - sy * sp * sr
    matrix[:, 1, 2] = -cy * sr - sy * sp * cr
    matrix[:, 2, 0] = sp
    matrix[:, 2, 1] = cp * sr
    matrix[:, 2, 2] = cp * cr
    return matrix


def segment_angles(timeline: Timeline, swimmer: Swimmer, params: SwimParams,
                   rng: np.random.Generator) -> dict[str, Angles]:
    """Angles of "pelvis", "trunk", "head" and "board" (draws: rest sway phases, fixed order)."""
    figures = params.stroke(swimmer.stroke)
    e, phi, swim = timeline.activity, timeline.phase_rad, timeline.swim
    roll_gain, yaw_gain, pitch_gain = timeline.gain[0], timeline.gain[1], timeline.gain[2]
    n = figures.strokes_per_cycle
    supine = swimmer.stroke == "backstroke"
    sway = [math.radians(params.walls.rest_sway_deg) * timeline.rest
            * np.sin(2.0 * math.pi * hz * timeline.time_s + float(rng.uniform(0.0, 2.0 * math.pi))) for hz in SWAY_HZ]
    yaw_b = timeline.yaw_rad + sway[2]
    pitch_b = timeline.pitch_rad + swim * math.radians(swimmer.inclination_deg) + sway[1]
    roll_b = timeline.roll_rad + sway[0]
    side_breath, forward_breath = _breaths(timeline, swimmer, n)
    rad = math.radians
    breath_roll = rad(figures.breath_roll_deg) * side_breath
    kick_cycles = figures.kick_beats_per_cycle / 2.0
    hip_roll = roll_gain * rad(swimmer.hip_roll_deg) * np.sin(phi - HIP_LAG_RAD)
    shoulder_roll = roll_gain * rad(swimmer.shoulder_roll_deg) * np.sin(phi) + breath_roll
    pelvis = Angles(
        yaw_b + e * yaw_gain * rad(swimmer.hip_yaw_deg) * np.cos(phi),
        pitch_b + e * pitch_gain * rad(figures.pelvis_pitch_deg) * np.sin(n * phi + 1.0),
        roll_b + e * (hip_roll + 0.5 * breath_roll + rad(figures.kick_roll_deg) * np.sin(kick_cycles * phi)),
        supine)
    trunk_pitch = pitch_b + e * pitch_gain * rad(figures.trunk_pitch_deg) * np.sin(n * phi + 0.5)
    trunk = Angles(yaw_b + e * yaw_gain * rad(swimmer.shoulder_yaw_deg) * np.cos(phi + 0.3), trunk_pitch,
                   roll_b + e * shoulder_roll, supine)
    follow = figures.head_follow * shoulder_roll
    breath_side = np.abs(side_breath)
    head_roll = follow + breath_side * (np.sign(side_breath) * rad(figures.head_breath_roll_deg) - follow)
    head = Angles(
        yaw_b + e * yaw_gain * rad(figures.head_yaw_deg) * np.cos(phi),
        trunk_pitch + swim * rad(swimmer.head_pitch_deg) + e * rad(figures.head_lift_deg) * forward_breath
        + timeline.sighting * rad(params.path.sighting_pitch_deg),
        roll_b + e * head_roll, supine)
    board = Angles(
        timeline.yaw_rad + e * rad(figures.board_yaw_deg) * np.sin(phi),
        swim * rad(swimmer.board_pitch_deg) + sway[1],
        e * rad(figures.board_roll_deg) * np.sin(phi + 1.0) + sway[0], False)
    return {"pelvis": pelvis, "trunk": trunk, "head": head, "board": board}


def _breaths(timeline: Timeline, swimmer: Swimmer, strokes_per_cycle: int) -> tuple[np.ndarray, np.ndarray]:
    """(side breath pulse signed by the side, forward breath pulse), each 0..1 in size."""
    size = len(timeline.time_s)
    if swimmer.breath_every <= 0:
        return np.zeros(size), np.zeros(size)
    phi = timeline.phase_rad
    if swimmer.stroke in FORWARD_BREATHING:
        cycle = np.floor(phi / (2.0 * math.pi))
        local = phi - 2.0 * math.pi * cycle
        on = (cycle + timeline.breath_offset) % swimmer.breath_every == swimmer.breath_every - 1
        u = (local - math.pi) / (BREATH_WIDTH * 2.0 * math.pi) + 0.5  # mid-cycle, inside the cycle
        return np.zeros(size), np.where(on & (u > 0) & (u < 1), np.sin(math.pi * np.clip(u, 0, 1)) ** 2, 0.0)
    stroke_angle = 2.0 * math.pi / strokes_per_cycle
    stroke = np.floor(phi / stroke_angle)
    local = phi - stroke_angle * stroke
    on = (stroke + timeline.breath_offset) % swimmer.breath_every == swimmer.breath_every - 1
    u = (local - stroke_angle / 2.0) / (BREATH_WIDTH * stroke_angle) + 0.5
    pulse = np.where(on & (u > 0) & (u < 1), np.sin(math.pi * np.clip(u, 0, 1)) ** 2, 0.0)
    side = np.where(stroke % 2 == 0, 1.0, -1.0)
    return side * pulse, np.zeros(size)

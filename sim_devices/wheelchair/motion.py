"""Chair dynamics: nonholonomic unicycles with acceleration limits, and chair-to-chair contacts.

Each chair is a unicycle: rolling speed v along its heading (negative = backward push) and a
yaw rate from differential wheel rolling, both rate-limited (`chair.*`); speeding up is limited
by push power (the limit halves at top speed), slowing down by braking; the yaw rate is capped by
grip (`chair.lateral_accel_mps2`) at speed; a push-cycle ripple rides on the speed while pushing.
Two things move a chair without turning its wheels, a real dead-reckoning error: a sideways slide
after a shove (`lateral_mps`, decelerated by tyre friction) with a short yaw skid, and the
push-apart that resolves overlapping discs (and the run-off limit).

Contacts: when two chair discs (`chair.radius_m`) overlap while closing faster than
`game.contact_min_closing_mps` (and the pair has not touched within `game.contact_refractory_s`),
a contact is recorded; an equal-mass impulse with restitution `game.restitution` changes both
chairs' velocities: the part along a chair's heading changes its rolling speed (the wheels follow),
the sideways part becomes a slide. Slower overlaps just cancel the closing velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from protocol.messages import ContactKind
from sim_devices.wheelchair.params import SimParams
from sim_devices.wheelchair.steering import CONTROL_HZ, Controller
from sim_devices.wheelchair.tactics import Tactics

FRONTAL_COS = math.cos(math.radians(45.0))  # a chair hit within 45 deg of its long axis is hit frontally
SKID_FLOOR_RPS = 1e-4  # yaw skid below this is zero (so still chairs are exactly still)
RIPPLE_GATE_PER_S = 2.0  # push ripple fades in/out over 0.5 s as pushing starts/stops
RIPPLE_MIN_MPS = 0.5  # no push ripple below this speed (command and actual)
RECORDED = ("x_m", "y_m", "heading_rad", "speed_mps", "lateral_mps", "yaw_roll_rps", "yaw_rate_rps",
            "accel_forward_mps2", "accel_left_mps2")


@dataclass(frozen=True)
class Contact:
    """A chair-to-chair contact (first < second, indices into the players)."""

    time_s: float
    first: int
    second: int
    kind: ContactKind
    closing_mps: float
    normal: tuple[float, float]  # unit vector from first to second, court frame


@dataclass
class Motion:
    """True motion at the simulation rate: arrays (steps,) and (steps, players)."""

    time_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray  # continuous (not wrapped)
    speed_mps: np.ndarray  # rolling speed along the heading: what the wheels see
    lateral_mps: np.ndarray  # sideways slide: wheels do not turn
    yaw_roll_rps: np.ndarray  # yaw from differential rolling: what the wheels see
    yaw_rate_rps: np.ndarray  # total yaw rate (rolling + skid): what the seat gyro sees
    accel_forward_mps2: np.ndarray  # chair-frame acceleration of the reference point, without impacts
    accel_left_mps2: np.ndarray
    team: np.ndarray
    top_speed_mps: np.ndarray
    contacts: list[Contact] = field(default_factory=list)
    skid_m: np.ndarray | None = None  # (players,) displacement without wheel rotation


class _Fleet:
    """State of every chair (arrays over players) and its integration over one step."""

    def __init__(self, params: SimParams, rng: np.random.Generator, position: np.ndarray, heading: np.ndarray):
        chair, players = params.chair, len(heading)
        self.params, self.rng = params, rng
        self.position, self.heading = position.astype(float), heading.astype(float)
        self.top_speed = rng.uniform(chair.top_speed_min_mps, chair.top_speed_max_mps, players)
        self.yaw_max = np.radians(chair.yaw_rate_max_dps) * rng.uniform(0.8, 1.0, players)
        self.push_phase = rng.uniform(0.0, 2.0 * math.pi, players)
        self.base_speed = np.zeros(players)  # rolling speed without the push ripple
        self.ripple_gate = np.zeros(players)
        self.speed, self.lateral = np.zeros(players), np.zeros(players)
        self.yaw_roll, self.yaw_skid = np.zeros(players), np.zeros(players)
        self.skid = np.zeros(players)
        self.last_contact = np.full((players, players), -math.inf)
        self.pairs = np.triu_indices(players, 1)
        court = params.court
        self.low = (-court.run_off_m, -court.run_off_m)
        self.high = (court.length_m + court.run_off_m, court.width_m + court.run_off_m)

    def velocity(self) -> np.ndarray:
        cos_h, sin_h = np.cos(self.heading), np.sin(self.heading)
        return np.stack([self.speed * cos_h - self.lateral * sin_h, self.speed * sin_h + self.lateral * cos_h], 1)

    def step(self, time_s: float, dt: float, speed_cmd: np.ndarray, yaw_cmd: np.ndarray) -> tuple[np.ndarray, ...]:
        """Advance one step; return the RECORDED values at `time_s` (acceleration over the step)."""
        chair, game = self.params.chair, self.params.game
        base = self.base_speed
        speeding_up = (np.abs(speed_cmd) > np.abs(base)) & (speed_cmd * base >= 0.0)
        power = chair.accel_mps2 * (1.0 - 0.5 * np.minimum(np.abs(base) / self.top_speed, 1.0))
        limit = np.where(speeding_up, power, chair.brake_mps2) * dt
        self.base_speed = base + np.maximum(np.minimum(speed_cmd - base, limit), -limit)
        pushing = (speed_cmd > RIPPLE_MIN_MPS) & (self.base_speed > RIPPLE_MIN_MPS)
        gate = self.ripple_gate + np.where(pushing, RIPPLE_GATE_PER_S, -RIPPLE_GATE_PER_S) * dt
        self.ripple_gate = np.maximum(np.minimum(gate, 1.0), 0.0)
        phase = 2.0 * math.pi * chair.push_frequency_hz * (time_s + dt) + self.push_phase
        new_speed = self.base_speed + chair.push_ripple_mps * self.ripple_gate * np.sin(phase)
        yaw_step = math.radians(chair.yaw_accel_dps2) * dt
        yaw_roll = self.yaw_roll + np.maximum(np.minimum(yaw_cmd - self.yaw_roll, yaw_step), -yaw_step)
        grip = np.minimum(self.yaw_max, chair.lateral_accel_mps2 / np.maximum(np.abs(new_speed), 0.1))
        self.yaw_roll = np.maximum(np.minimum(yaw_roll, grip), -grip)
        yaw_rate = self.yaw_roll + self.yaw_skid
        speed, lateral = self.speed, self.lateral
        new_lateral = lateral - np.sign(lateral) * np.minimum(np.abs(lateral), game.lateral_friction_mps2 * dt)
        row = (self.position[:, 0].copy(), self.position[:, 1].copy(), self.heading, speed, lateral,
               self.yaw_roll, yaw_rate, (new_speed - speed) / dt - lateral * yaw_rate,
               (new_lateral - lateral) / dt + speed * yaw_rate)
        cos_h, sin_h = np.cos(self.heading), np.sin(self.heading)
        self.position[:, 0] += (speed * cos_h - lateral * sin_h) * dt
        self.position[:, 1] += (speed * sin_h + lateral * cos_h) * dt
        self.heading = self.heading + yaw_rate * dt
        self.skid += np.abs(lateral) * dt
        self.speed, self.lateral = new_speed, new_lateral
        decay = math.exp(-dt / chair.yaw_skid_decay_s)
        self.yaw_skid = np.where(np.abs(self.yaw_skid) > SKID_FLOOR_RPS, self.yaw_skid * decay, 0.0)
        return row

    def keep_in_bounds(self) -> None:
        """Hold chairs inside the court plus run-off (a displacement without wheel rotation)."""
        clamped = np.clip(self.position, self.low, self.high)
        self.skid += np.hypot(*(clamped - self.position).T)
        self.position = clamped

    def resolve_contacts(self, time_s: float, dt: float) -> list[Contact]:
        """Resolve overlapping chair pairs; return the contacts recorded at this step."""
        reach = 2.0 * self.params.chair.radius_m
        first, second = self.pairs
        offsets = self.position[second] - self.position[first]
        overlapping = np.flatnonzero(np.einsum("ij,ij->i", offsets, offsets) < reach * reach)
        found = []
        for pair in overlapping.tolist():
            contact = self._resolve_pair(int(first[pair]), int(second[pair]), time_s, dt, reach)
            if contact is not None:
                found.append(contact)
        return found

    def _resolve_pair(self, i: int, j: int, time_s: float, dt: float, reach: float) -> Contact | None:
        game = self.params.game
        offset = self.position[j] - self.position[i]
        gap = float(np.hypot(*offset))
        normal = offset / gap if gap > 1e-9 else np.array([1.0, 0.0])
        forward = np.stack([np.cos(self.heading[[i, j]]), np.sin(self.heading[[i, j]])], 1)
        left = np.stack([-forward[:, 1], forward[:, 0]], 1)
        velocity = self.speed[[i, j], None] * forward + self.lateral[[i, j], None] * left
        closing = float((velocity[0] - velocity[1]) @ normal)
        contact = None
        if closing > 0.0:
            recorded = (closing > game.contact_min_closing_mps
                        and time_s - self.last_contact[i, j] >= game.contact_refractory_s)
            impulse = (1.0 + game.restitution) / 2.0 * closing if recorded else closing / 2.0
            for side, (chair, sign) in enumerate(((i, -1.0), (j, 1.0))):
                change = sign * impulse * normal
                along = float(change @ forward[side])
                self.speed[chair] += along
                self.base_speed[chair] += along
                self.lateral[chair] += float(change @ left[side])
                if recorded:
                    kick = math.radians(game.yaw_kick_dps_per_mps) * impulse
                    self.yaw_skid[chair] += self.rng.normal(0.0, kick)
            if recorded:
                self.last_contact[i, j] = time_s
                frontal = bool(np.all(np.abs(forward @ normal) >= FRONTAL_COS))
                contact = Contact(time_s - float(self.rng.uniform(0.0, dt)), i, j,
                                  ContactKind.FRONTAL if frontal else ContactKind.LATERAL, closing,
                                  (float(normal[0]), float(normal[1])))
        push = (reach - gap) / 2.0  # push apart along the normal: no wheel rotation
        self.position[i] -= push * normal
        self.position[j] += push * normal
        self.skid[[i, j]] += push
        return contact


def simulate_motion(players: int, duration_s: float, params: SimParams, rng: np.random.Generator,
                    progress: Callable[[float], None] | None = None) -> Motion:
    """Run the game for `duration_s` at `sensors.rate_hz`; the state is recorded at the start of each step."""
    dt = 1.0 / params.sensors.rate_hz
    steps = max(1, int(round(duration_s * params.sensors.rate_hz)))
    control_every = max(1, int(round(params.sensors.rate_hz / CONTROL_HZ)))
    tactics = Tactics(players, params, rng)
    fleet = _Fleet(params, rng, *tactics.start_positions())
    controller = Controller(players, params, fleet.top_speed, fleet.yaw_max)
    record = {name: np.zeros((steps, players)) for name in RECORDED}
    columns = list(record.values())
    contacts: list[Contact] = []
    speed_cmd = yaw_cmd = np.zeros(players)
    for k in range(steps):
        time_s = k * dt
        if k % control_every == 0:
            targets, facing, hold = tactics.update(time_s, control_every * dt, fleet.position)
            speed_cmd, yaw_cmd = controller.commands(fleet.position, fleet.heading, fleet.speed, fleet.velocity(),
                                                     targets, facing, hold, tactics.block_victim >= 0)
            if progress is not None:
                progress(k / steps)
        for column, value in zip(columns, fleet.step(time_s, dt, speed_cmd, yaw_cmd)):
            column[k] = value
        if players > 1:
            for contact in fleet.resolve_contacts(time_s + dt, dt):
                contacts.append(contact)
                tactics.on_contact(contact.first, contact.second, contact.time_s)
        fleet.keep_in_bounds()
    if progress is not None:
        progress(1.0)
    return Motion(time_s=np.arange(steps) * dt, team=tactics.team, top_speed_mps=fleet.top_speed,
                  contacts=contacts, skid_m=fleet.skid, **record)

"""Our pedestrian map matching: a particle filter over the walkable area (hub/pedestrian/walkable.py).

Each particle is a position, a heading offset (what the dead reckoning's heading is wrong by) and
a step-length scale (what its step length is wrong by). Between two dead-reckoned poses the step
is their displacement: length L and direction phi in the dead-reckoned frame. Each particle moves
L * scale along phi + offset, plus along- and cross-track noise that grows with sqrt(L) (so the
spread after a distance is the same whether poses come per step or at 50 Hz). The offset walks
with time (gyro drift) and with each heading change (gyro scale error); the scale walks with
distance. A particle whose move crosses a wall or leaves the walkable area dies (weight 0): that
is the only measurement, and through it the survivors' offsets and scales learn the drift.

Resampling is systematic, when N_eff = 1 / sum(w^2) falls below half the particles. When every
particle has died the cloud is re-seeded around the filter's own continuation (the last mean
moved by this step), not around the raw dead-reckoned pose, which has drifted away from it by
everything the filter had learned; the spread doubles per attempt until walkable cells are hit,
and the recovery is counted. No turns are needed: a junction is just where the corridors let the
cloud through. The output is the weighted mean, unless it lies in a wall or the move to it from
the last output crosses one (a cloud split by a wall): then the densest cell's most central
particle, which is walkable by construction. For phones whose heading has an absolute aid (the
hub's PHONE_PARTICLES) the offsets also revert to the dead reckoning's own (`offset_reversion_s`).
The published covariance is the cloud's plus half the dead reckoning's (`edge_covariance_share`).
Work per pose is O(particles x L / cell); memory is
the fixed particle arrays. Random numbers come from one seeded generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hub.pedestrian.lag import LagHistory
from hub.pedestrian.matching import DeadReckonedPose, MatchedPose, wrap_angle_rad
from hub.pedestrian.walkable import WalkableArea


OUTLIER_SHARE = 0.05  # of a fix's likelihood spread evenly: the chance that a gated fix is still wrong

@dataclass(frozen=True)
class ParticleSettings:
    particles: int = 300  # 200-500 is the usual range for floor-plan filters; 300 costs about 0.3 ms a step
    seed: int = 0
    along_noise_m_per_sqrt_m: float = 0.05  # 0.04 m on a 0.7 m step: 6 %, Weinberg step-length scatter
    cross_noise_m_per_sqrt_m: float = 0.08  # 0.07 m on a 0.7 m step: about 5 deg of sway per step
    offset_walk_rad_per_sqrt_s: float = math.radians(0.6)  # 4.6 deg after a minute: gyro drift and grip changes
    # None: the offsets only random-walk. A time constant: they also decay towards 0, i.e. towards
    # the dead reckoning's own heading, when that heading has an absolute aid (the magnetometer).
    offset_reversion_s: float | None = None
    turn_scale_sd: float = 0.02  # a turn of 90 deg adds 1.8 deg of offset: phone gyro scale error
    scale_walk_per_sqrt_m: float = 0.003  # the step-length scale drifts slowly (pace changes)
    scale_limits: tuple[float, float] = (0.6, 1.6)  # outside this the dead reckoning is broken, not drifted
    initial_scale_sd: float = 0.10  # a height-based step length is off by up to 10-20 %
    initial_position_sd_m: float = 0.5  # floors on the dead reckoning's own first covariance
    # A QR stand fixes the phone's heading to 2-3 deg (algorithms.md), but a hand-held phone points
    # up to about 10 deg off the walking direction: the offsets start wide and the walls narrow them
    # (3 deg here let a 12 deg offset starve the cloud and bias its scale, test_map_matching).
    initial_heading_sd_rad: float = math.radians(8.0)
    reset_position_sd_m: float = 0.3  # a QR stand fix (algorithms.md: 0.3 m)
    reset_heading_sd_rad: float = math.radians(8.0)
    recovery_position_sd_m: float = 1.5  # about a corridor's width: where the cloud most likely went wrong
    recovery_heading_sd_rad: float = math.radians(15.0)
    seed_attempts: int = 4  # spread doubles per attempt: 1.5, 3, 6, 12 m
    resample_below_fraction: float = 0.5  # N_eff < P / 2
    mode_cell_m: float = 1.0  # cell for picking the densest part of a split cloud
    gap_s: float = 5.0  # a longer silence between poses is counted as a gap
    # A refined track this many poses behind the live one (hub/pedestrian/lag.py); 0: none.
    smoothing_lag_steps: int = 0
    # The published covariance: the cloud's own plus this share of the dead reckoning's. The cloud
    # alone understates the error (its scale and heading priors are narrower than the edge's honest
    # ones, which is what makes it accurate): NEES median 13.1 at the ILC site 1 tune half's
    # waypoints; with half the edge's covariance 1.42 (an honest 2-D one: 1.39), 1.01 on the
    # report half (chosen from 0.25, 0.5, 1: docs/pdr-estimator.md).
    edge_covariance_share: float = 0.5


@dataclass
class ParticleDiagnostics:
    """Counters since construction and the last step's effective particle count (published by
    the hub so a filter that keeps recovering is seen)."""

    steps: int = 0
    resamples: int = 0
    recoveries: int = 0
    off_map_steps: int = 0  # steps where even the widest re-seed found no walkable cell
    mode_outputs: int = 0  # steps whose output was not the mean (it lay behind a wall)
    unreachable_outputs: int = 0  # ... and no particle was reachable from the last output either
    out_of_order: int = 0  # poses not later than the previous one: ignored
    gaps: int = 0
    reseeds_near: int = 0  # clouds drawn near a given point by `seed_near` (the map guard's re-acquisition)
    fixes: int = 0  # position fixes weighed in (`observe`)
    effective_particles: float = 0.0


class ParticleMatcher:
    """Particle filter over the walkable area; `update` per dead-reckoned pose, `reset` on a fix."""

    def __init__(self, area: WalkableArea, settings: ParticleSettings = ParticleSettings()) -> None:
        if settings.particles < 10:
            raise ValueError(f"particles {settings.particles} is below 10")
        self.area = area
        self.settings = settings
        self.random = np.random.default_rng(settings.seed)
        count = settings.particles
        self.x_m, self.y_m = np.zeros(count), np.zeros(count)
        self.offset_rad, self.scale = np.zeros(count), np.ones(count)
        self.weight = np.full(count, 1.0 / count)
        self.previous: DeadReckonedPose | None = None
        self.output_xy_m: tuple[float, float] | None = None
        self.output_offset_rad = 0.0
        self.diagnostics = ParticleDiagnostics()
        self.scale[:] = self._initial_scales()
        self.lag = (LagHistory(settings.smoothing_lag_steps, count, area.is_walkable)
                    if settings.smoothing_lag_steps > 0 else None)
        self.finished: list[MatchedPose] = []  # refined poses not yet taken (at most lag + 1)

    def _initial_scales(self) -> np.ndarray:
        low, high = self.settings.scale_limits
        return np.clip(self.random.normal(1.0, self.settings.initial_scale_sd, self.settings.particles), low, high)

    def reset(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        """A fix: particles around it at QR-stand accuracy; the learned step scales are kept."""
        self._seed(x_m, y_m, self.settings.reset_position_sd_m, 0.0, self.settings.reset_heading_sd_rad)
        self.previous = DeadReckonedPose(time_ns, x_m, y_m, heading_rad)
        self.output_xy_m, self.output_offset_rad = (x_m, y_m), 0.0

    def update(self, pose: DeadReckonedPose) -> MatchedPose:
        settings, previous = self.settings, self.previous
        if previous is None:
            position_sd_m, heading_sd_rad = settings.initial_position_sd_m, settings.initial_heading_sd_rad
            if pose.covariance is not None:
                position_sd_m = max(position_sd_m, math.sqrt(max(pose.covariance[0][0], pose.covariance[1][1])))
                heading_sd_rad = max(heading_sd_rad, math.sqrt(pose.covariance[2][2]))
            self._seed(pose.x_m, pose.y_m, position_sd_m, 0.0, heading_sd_rad)
            self.output_xy_m = None
        elif pose.time_ns <= previous.time_ns:
            self.diagnostics.out_of_order += 1
            return self._output(pose)
        else:
            self._propagate(previous, pose)
        self.previous = pose
        self.diagnostics.steps += 1
        live = self._output(pose)
        if self.lag is not None:
            added = (None if pose.covariance is None
                     else self.settings.edge_covariance_share * np.asarray(pose.covariance, dtype=float))
            self.finished += self.lag.record(live.time_ns, live.heading_rad, self.x_m, self.y_m, self.weight, added)
        return live

    @property
    def refined_lag_steps(self) -> int:
        return self.settings.smoothing_lag_steps

    def refined(self) -> list[MatchedPose]:
        """The refined poses finished since the last call, in time order (`smoothing_lag_steps`
        poses behind `update`; at once for those before a reset or a re-seed)."""
        out, self.finished = self.finished, []
        return out

    def flush(self) -> list[MatchedPose]:
        """End of the stream: every pose still waiting for its lag, refined now."""
        if self.lag is not None:
            self.finished += self.lag.flush(self.weight)
        return self.refined()

    def _propagate(self, previous: DeadReckonedPose, pose: DeadReckonedPose) -> None:
        settings, random, count = self.settings, self.random, self.settings.particles
        elapsed_s = (pose.time_ns - previous.time_ns) * 1e-9
        if elapsed_s > settings.gap_s:
            self.diagnostics.gaps += 1
        step_x_m, step_y_m = pose.x_m - previous.x_m, pose.y_m - previous.y_m
        length_m = math.hypot(step_x_m, step_y_m)
        direction_rad = math.atan2(step_y_m, step_x_m)
        turn_rad = wrap_angle_rad(pose.heading_rad - previous.heading_rad)
        offset_sd_rad = math.sqrt(settings.offset_walk_rad_per_sqrt_s ** 2 * elapsed_s
                                  + (settings.turn_scale_sd * turn_rad) ** 2)
        if settings.offset_reversion_s is not None:
            self.offset_rad *= math.exp(-elapsed_s / settings.offset_reversion_s)
        self.offset_rad += random.normal(0.0, offset_sd_rad, count)
        self.scale = np.clip(self.scale + random.normal(0.0, settings.scale_walk_per_sqrt_m * math.sqrt(length_m),
                                                        count), *settings.scale_limits)
        along_m = length_m * self.scale + random.normal(0.0, settings.along_noise_m_per_sqrt_m * math.sqrt(length_m),
                                                        count)
        cross_m = random.normal(0.0, settings.cross_noise_m_per_sqrt_m * math.sqrt(length_m), count)
        moved_rad = direction_rad + self.offset_rad
        cos_moved, sin_moved = np.cos(moved_rad), np.sin(moved_rad)
        end_x_m = self.x_m + along_m * cos_moved - cross_m * sin_moved
        end_y_m = self.y_m + along_m * sin_moved + cross_m * cos_moved
        alive = self.area.move_allowed(self.x_m, self.y_m, end_x_m, end_y_m)
        self.x_m, self.y_m = end_x_m, end_y_m
        self.weight *= alive
        total = float(self.weight.sum())
        if total <= 0.0:
            self._recover(length_m, direction_rad)
            return
        self.weight /= total
        self.diagnostics.effective_particles = 1.0 / float(np.sum(self.weight ** 2))
        if self.diagnostics.effective_particles < settings.resample_below_fraction * count:
            self._resample()

    def _recover(self, length_m: float, direction_rad: float) -> None:
        """Every particle died: re-seed around the last output moved by this step."""
        self.diagnostics.recoveries += 1
        mean_scale = float(np.mean(self.scale))
        start_x_m, start_y_m = self.output_xy_m if self.output_xy_m is not None else (
            float(np.mean(self.x_m)), float(np.mean(self.y_m)))
        moved_rad = direction_rad + self.output_offset_rad
        self._seed(start_x_m + length_m * mean_scale * math.cos(moved_rad),
                   start_y_m + length_m * mean_scale * math.sin(moved_rad),
                   self.settings.recovery_position_sd_m, self.output_offset_rad,
                   self.settings.recovery_heading_sd_rad)

    def observe(self, x_m: float, y_m: float, sd_m: float) -> None:
        """A position fix now (a beacon pass, carried to now along the dead reckoning): the weights
        times its likelihood, with OUTLIER_SHARE of it spread evenly (a wrong fix must not empty
        the cloud), resampled when few particles carry the weight."""
        distance2 = ((self.x_m - x_m) ** 2 + (self.y_m - y_m) ** 2) / (sd_m * sd_m)
        weight = self.weight * (OUTLIER_SHARE + np.exp(-0.5 * distance2))
        self.weight = weight / weight.sum()
        self.diagnostics.fixes += 1
        effective = 1.0 / float(np.sum(self.weight ** 2))
        self.diagnostics.effective_particles = effective
        if effective < self.settings.resample_below_fraction * self.settings.particles:
            self._resample()

    def seed_near(self, x_m: float, y_m: float, position_sd_m: float, max_distance_m: float) -> bool:
        """Re-draw the cloud on walkable cells around (x, y), none further than `max_distance_m`:
        never away from the point (a fix or a track the map does not allow stays where it is). The
        offsets restart at the dead reckoning's own heading and the scales at their first spread
        (the point is the dead reckoning's own track: what was learned against the map is not), the
        output starts at (x, y). False, and nothing changed, when no walkable cell was drawn."""
        count = self.settings.particles
        candidates_x = x_m + self.random.normal(0.0, position_sd_m, count)
        candidates_y = y_m + self.random.normal(0.0, position_sd_m, count)
        near = np.hypot(candidates_x - x_m, candidates_y - y_m) <= max_distance_m
        walkable = np.flatnonzero(near & self.area.is_walkable(candidates_x, candidates_y))
        if walkable.size == 0:
            return False
        if self.lag is not None:  # the ancestry ends here
            self.finished += self.lag.flush(self.weight)
        chosen = walkable[self.random.integers(walkable.size, size=count)]
        self.x_m, self.y_m = candidates_x[chosen], candidates_y[chosen]
        self.offset_rad = self.random.normal(0.0, self.settings.recovery_heading_sd_rad, count)
        self.scale[:] = self._initial_scales()
        self.weight = np.full(count, 1.0 / count)
        self.diagnostics.effective_particles = float(count)
        self.diagnostics.reseeds_near += 1
        self.output_xy_m, self.output_offset_rad = (x_m, y_m), 0.0
        return True

    def restart_at(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        """The dead reckoning restarted from this pose, without a cloud drawn for it (the caller
        draws one with `seed_near`, or the cloud it has goes on): the next pose continues from it."""
        self.previous = DeadReckonedPose(time_ns, x_m, y_m, heading_rad)
        self.output_xy_m, self.output_offset_rad = (x_m, y_m), 0.0

    def _seed(self, x_m: float, y_m: float, position_sd_m: float, offset_rad: float, offset_sd_rad: float) -> None:
        """Particles on walkable cells drawn around (x, y); the spread doubles per attempt while no
        draw lands on a walkable cell. With none at all, the particles wait at (x, y) off the map."""
        count = self.settings.particles
        if self.lag is not None:  # the ancestry ends: what waits is finished with the weights it has
            self.finished += self.lag.flush(self.weight)
        for attempt in range(self.settings.seed_attempts):
            spread_m = position_sd_m * 2.0 ** attempt
            candidates_x = x_m + self.random.normal(0.0, spread_m, count)
            candidates_y = y_m + self.random.normal(0.0, spread_m, count)
            walkable = np.flatnonzero(self.area.is_walkable(candidates_x, candidates_y))
            if walkable.size:
                chosen = walkable[self.random.integers(walkable.size, size=count)]  # duplicates spread on the next move
                self.x_m, self.y_m = candidates_x[chosen], candidates_y[chosen]
                break
        else:
            self.diagnostics.off_map_steps += 1
            self.x_m, self.y_m = np.full(count, x_m), np.full(count, y_m)
        self.offset_rad = offset_rad + self.random.normal(0.0, offset_sd_rad, count)
        self.weight = np.full(count, 1.0 / count)
        self.diagnostics.effective_particles = float(count)

    def _resample(self) -> None:
        """Systematic resampling: one uniform draw, P evenly spaced pointers into the weights."""
        count = self.settings.particles
        pointers = (self.random.random() + np.arange(count)) / count
        cumulative = np.cumsum(self.weight)
        cumulative[-1] = 1.0  # rounding must not leave the last pointer past the end
        chosen = np.searchsorted(cumulative, pointers)
        self.x_m, self.y_m = self.x_m[chosen], self.y_m[chosen]
        self.offset_rad, self.scale = self.offset_rad[chosen], self.scale[chosen]
        if self.lag is not None:
            self.lag.reindex(chosen)
        self.weight = np.full(count, 1.0 / count)
        self.diagnostics.resamples += 1

    def _densest_particle(self) -> int:
        """Index of the particle nearest the weighted mean of the heaviest `mode_cell_m` cell."""
        cell_m = self.settings.mode_cell_m
        columns = np.floor(self.x_m / cell_m).astype(np.int64)
        rows = np.floor(self.y_m / cell_m).astype(np.int64)
        _, cell_of = np.unique(columns * 1_000_003 + rows, return_inverse=True)  # prime stride: distinct keys
        best_cell = int(np.argmax(np.bincount(cell_of, weights=self.weight)))
        members = np.flatnonzero(cell_of == best_cell)
        member_weight = self.weight[members] / self.weight[members].sum()
        centre_x_m, centre_y_m = member_weight @ self.x_m[members], member_weight @ self.y_m[members]
        return int(members[np.argmin(np.hypot(self.x_m[members] - centre_x_m, self.y_m[members] - centre_y_m))])

    def _reachable(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Per point, True when the straight move from the last output to it stays walkable."""
        if self.output_xy_m is None:
            return self.area.is_walkable(x_m, y_m)
        return self.area.move_allowed(np.full(len(x_m), self.output_xy_m[0]), np.full(len(x_m), self.output_xy_m[1]),
                                      x_m, y_m)

    def _output_position(self, weight: np.ndarray) -> tuple[float, float]:
        """The weighted mean if the track can move there without crossing a wall; else the most
        central particle of the densest cell; else the reachable particle nearest the mean; else
        (the whole cloud is around a corner or re-seeded) the densest particle, counted."""
        mean_x_m, mean_y_m = float(weight @ self.x_m), float(weight @ self.y_m)
        if self._reachable(np.array([mean_x_m]), np.array([mean_y_m]))[0]:
            return mean_x_m, mean_y_m
        self.diagnostics.mode_outputs += 1
        densest = self._densest_particle()
        if self._reachable(self.x_m[densest:densest + 1], self.y_m[densest:densest + 1])[0]:
            return float(self.x_m[densest]), float(self.y_m[densest])
        reachable = np.flatnonzero(self._reachable(self.x_m, self.y_m))
        if reachable.size:
            nearest = reachable[np.argmin(np.hypot(self.x_m[reachable] - mean_x_m, self.y_m[reachable] - mean_y_m))]
            return float(self.x_m[nearest]), float(self.y_m[nearest])
        self.diagnostics.unreachable_outputs += 1
        return float(self.x_m[densest]), float(self.y_m[densest])

    def _output(self, pose: DeadReckonedPose) -> MatchedPose:
        weight = self.weight
        x_m, y_m = self._output_position(weight)
        offset_rad = math.atan2(float(weight @ np.sin(self.offset_rad)), float(weight @ np.cos(self.offset_rad)))
        deviations = np.stack([self.x_m - x_m, self.y_m - y_m, wrap_angle_rad(self.offset_rad - offset_rad)])
        covariance = (deviations * weight) @ deviations.T
        if pose.covariance is not None:
            covariance = covariance + self.settings.edge_covariance_share * np.asarray(pose.covariance, dtype=float)
        self.output_xy_m, self.output_offset_rad = (x_m, y_m), offset_rad
        return MatchedPose(time_ns=pose.time_ns, x_m=x_m, y_m=y_m,
                           heading_rad=wrap_angle_rad(pose.heading_rad + offset_rad), covariance=covariance)

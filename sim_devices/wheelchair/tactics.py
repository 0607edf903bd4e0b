"""Team play: where each player wants to be, updated at the control rate (no dynamics here).

Two teams; team 0 attacks the basket at large x, team 1 the one at small x. Possession
alternates every `game.possession_min_s..max_s` seconds, so every change is a transition sprint
to the other end. The offence takes spots around the attacked basket (a share
`game.post_fraction` within 2 m of it: crowding), re-drawn every few seconds (cuts). Each
defender marks one attacker (nearest, re-assigned at each possession) from the goal side at
`game.mark_distance_m`; closing in on a moving attacker produces light contacts. Independently,
each player now and then (`game.block_rate_per_min` attempts; none when no opponent is within
BLOCK_REACH_M) drives straight into the nearest opponent (a block or a screen), which produces
the harder contacts. After some possessions the ball is dead for a few seconds and
everyone holds still.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from sim_devices.wheelchair.params import SimParams

WANDER_TIME_S = 2.0  # correlation time of a target's random drift
BLOCK_REACH_M = 6.0  # a player only blocks an opponent this close
EDGE_MARGIN_M = 0.6  # targets stay this far inside the court lines
SPOT_SPACING_M = 1.5  # teammates keep their targets this far apart (chair discs touch at 0.9 m)
SPOT_TRIES = 20  # spot draws before accepting one close to a teammate
POST_RADIUS_M = (0.5, 2.0)  # post spots: this far from the basket ...
POST_ANGLE_RAD = math.radians(60.0)  # ... within this of the line to mid-court
PERIMETER_RADIUS_M = (3.0, 6.5)  # other spots: wings, top, corners
PERIMETER_ANGLE_RAD = math.radians(85.0)
ZONE_DEPTH_M = 2.5  # a defender with nobody to mark guards this far in front of the basket
START_BAND_M = (1.0, 7.0)  # start poses: this far from the centre line, in the team's own half
START_SIDE_M = 2.0  # and this far from the side lines


class Tactics:
    """Targets (x, y), facing and hold flags for every player; `update` once per control tick."""

    def __init__(self, players: int, params: SimParams, rng: np.random.Generator):
        self.params = params
        self.rng = rng
        game, court = params.game, params.court
        self.players = players
        self.team = np.array([0] * ((players + 1) // 2) + [1] * (players // 2))
        inset = court.basket_inset_m
        self.baskets = np.array([[inset, court.width_m / 2], [court.length_m - inset, court.width_m / 2]])
        self.possession = int(rng.integers(2))
        tip_off = self._stoppage_length()  # drawn either way, so the other draws do not depend on parked_start
        self.play_from_s = tip_off if game.parked_start else 0.0
        self.possession_until_s = self.play_from_s + self._possession_length()
        self.marks = np.full(players, -1)
        self.spots = np.zeros((players, 2))
        self.spot_until_s = np.zeros(players)
        self.wander = np.zeros((players, 2))
        self.block_victim = np.full(players, -1)
        self.block_until_s = np.zeros(players)
        rate = game.block_rate_per_min / 60.0
        self.next_block_s = np.array([self._next_event(0.0, rate) for _ in range(players)])
        self._assign_marks(None)

    # -- public ---------------------------------------------------------------------------------

    def start_positions(self) -> tuple[np.ndarray, np.ndarray]:
        """Start poses: each team spread over its own half, facing the attacked end; no overlaps."""
        court, chair = self.params.court, self.params.chair
        positions = np.zeros((self.players, 2))
        headings = np.zeros(self.players)
        for i in range(self.players):
            for _ in range(1000):
                x = court.length_m / 2 - self.rng.uniform(*START_BAND_M)
                y = self.rng.uniform(START_SIDE_M, court.width_m - START_SIDE_M)
                if self.team[i] == 1:
                    x = court.length_m - x
                x = min(max(x, EDGE_MARGIN_M), court.length_m - EDGE_MARGIN_M)  # small courts
                if i == 0 or np.min(np.hypot(positions[:i, 0] - x, positions[:i, 1] - y)) > 2.5 * chair.radius_m:
                    break
            positions[i] = (x, y)
            headings[i] = (0.0 if self.team[i] == 0 else math.pi) + self.rng.normal(0.0, 0.3)
        return positions, headings

    def update(self, time_s: float, dt_s: float, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Targets (N, 2) m, facing (N,) rad and hold-still flags (N,) at `time_s`."""
        if time_s >= self.possession_until_s:
            self._change_possession(time_s, positions)
        if time_s < self.play_from_s:  # dead ball: everyone holds still where they are
            return positions.copy(), np.zeros(self.players), np.ones(self.players, dtype=bool)
        self._drift_wander(dt_s)
        targets = np.zeros((self.players, 2))
        facing = np.zeros(self.players)
        attacked = self.baskets[self._attacked(self.possession)]
        for i in range(self.players):
            if self.team[i] == self.possession:
                targets[i], facing[i] = self._attacker_target(i, time_s, attacked)
                targets[i] += self.wander[i]
            else:  # defenders follow their attacker, no wander of their own
                targets[i], facing[i] = self._defender_target(i, positions, attacked)
        self._separate_teammates(targets)
        self._blocks(time_s, positions, targets, facing)
        margin = EDGE_MARGIN_M
        targets[:, 0] = np.clip(targets[:, 0], margin, self.params.court.length_m - margin)
        targets[:, 1] = np.clip(targets[:, 1], margin, self.params.court.width_m - margin)
        return targets, facing, np.zeros(self.players, dtype=bool)

    def on_contact(self, first: int, second: int, time_s: float) -> None:
        """A contact between two players ends a block one of them was making on the other."""
        for blocker, victim in ((first, second), (second, first)):
            if self.block_victim[blocker] == victim:
                self._end_block(blocker, time_s)

    # -- possession -----------------------------------------------------------------------------

    def _attacked(self, team: int) -> int:
        return 1 if team == 0 else 0

    def _possession_length(self) -> float:
        game = self.params.game
        return float(self.rng.uniform(game.possession_min_s, game.possession_max_s))

    def _stoppage_length(self) -> float:
        game = self.params.game
        return float(self.rng.uniform(game.stoppage_min_s, game.stoppage_max_s))

    def _change_possession(self, time_s: float, positions: np.ndarray) -> None:
        self.possession = 1 - self.possession
        self.play_from_s = time_s
        if self.rng.random() < self.params.game.stoppage_probability:
            self.play_from_s = time_s + self._stoppage_length()
        self.possession_until_s = self.play_from_s + self._possession_length()
        self.spot_until_s[:] = 0.0
        for player in np.flatnonzero(self.block_victim >= 0).tolist():
            self._end_block(player, time_s)
        self.next_block_s = np.maximum(self.next_block_s, self.play_from_s)  # no blocks in a dead ball
        self._assign_marks(positions)

    def _assign_marks(self, positions: np.ndarray | None) -> None:
        """Each defender marks one attacker: nearest overall (Hungarian), by index at the start."""
        self.marks[:] = -1
        defenders = np.flatnonzero(self.team != self.possession)
        attackers = np.flatnonzero(self.team == self.possession)
        if len(defenders) == 0 or len(attackers) == 0:
            return
        if positions is None:
            rows = cols = np.arange(min(len(defenders), len(attackers)))
        else:
            cost = np.linalg.norm(positions[defenders, None, :] - positions[None, attackers, :], axis=2)
            rows, cols = linear_sum_assignment(cost)
        self.marks[defenders[rows]] = attackers[cols]

    # -- targets --------------------------------------------------------------------------------

    def _attacker_target(self, i: int, time_s: float, basket: np.ndarray) -> tuple[np.ndarray, float]:
        game = self.params.game
        if time_s >= self.spot_until_s[i]:
            self.spots[i] = self._draw_spot(i, basket)
            self.spot_until_s[i] = time_s + self.rng.uniform(game.spot_change_min_s, game.spot_change_max_s)
        to_basket = basket - self.spots[i]
        return self.spots[i].copy(), math.atan2(to_basket[1], to_basket[0])

    def _draw_spot(self, i: int, basket: np.ndarray) -> np.ndarray:
        """A spot around `basket`, away from the teammates' spots: posts within 2 m, perimeter 3-6.5 m."""
        inward = 1.0 if basket[0] < self.params.court.length_m / 2 else -1.0
        mates = [j for j in range(self.players) if j != i and self.team[j] == self.team[i]]
        spot = basket
        for _ in range(SPOT_TRIES):
            if self.rng.random() < self.params.game.post_fraction:
                radius, angle = self.rng.uniform(*POST_RADIUS_M), self.rng.uniform(-POST_ANGLE_RAD, POST_ANGLE_RAD)
            else:
                radius = self.rng.uniform(*PERIMETER_RADIUS_M)
                angle = self.rng.uniform(-PERIMETER_ANGLE_RAD, PERIMETER_ANGLE_RAD)
            spot = basket + radius * np.array([inward * math.cos(angle), math.sin(angle)])
            if not mates or np.min(np.hypot(*(self.spots[mates] - spot).T)) >= SPOT_SPACING_M:
                break
        return spot

    def _separate_teammates(self, targets: np.ndarray) -> None:
        """Move teammates' targets apart to SPOT_SPACING_M (players avoid crowding their own side)."""
        for i in range(self.players):
            for j in range(i + 1, self.players):
                if self.team[i] != self.team[j]:
                    continue
                offset = targets[j] - targets[i]
                gap = float(np.hypot(*offset))
                if gap < SPOT_SPACING_M:
                    direction = offset / gap if gap > 1e-6 else np.array([0.0, 1.0])
                    shift = (SPOT_SPACING_M - gap) / 2.0 * direction
                    targets[i] -= shift
                    targets[j] += shift

    def _defender_target(self, i: int, positions: np.ndarray, basket: np.ndarray) -> tuple[np.ndarray, float]:
        attacker = self.marks[i]
        if attacker < 0:  # nobody to mark: guard the area in front of the basket
            inward = 1.0 if basket[0] < self.params.court.length_m / 2 else -1.0
            target = basket + np.array([ZONE_DEPTH_M * inward, 0.0])
            return target, (0.0 if inward > 0 else math.pi)
        to_basket = basket - positions[attacker]
        distance = float(np.hypot(*to_basket))
        unit = to_basket / distance if distance > 1e-6 else np.array([1.0, 0.0])
        target = positions[attacker] + unit * self.params.game.mark_distance_m
        return target, math.atan2(-unit[1], -unit[0])  # face the attacker

    def _drift_wander(self, dt_s: float) -> None:
        """Ornstein-Uhlenbeck drift of each target, SD `game.target_wander_m`."""
        decay = math.exp(-dt_s / WANDER_TIME_S)
        sigma = self.params.game.target_wander_m * math.sqrt(1.0 - decay**2)
        self.wander = self.wander * decay + self.rng.normal(0.0, sigma, self.wander.shape)

    # -- blocks ---------------------------------------------------------------------------------

    def _blocks(self, time_s: float, positions: np.ndarray, targets: np.ndarray, facing: np.ndarray) -> None:
        """Start due blocks on the nearest opponent in reach; aim blocking players at their victim."""
        for i in range(self.players):
            if self.block_victim[i] < 0 and time_s >= self.next_block_s[i]:
                opponents = np.flatnonzero(self.team != self.team[i])
                if len(opponents):
                    gaps = np.hypot(*(positions[opponents] - positions[i]).T)
                    if gaps.min() < BLOCK_REACH_M:
                        self.block_victim[i] = opponents[int(np.argmin(gaps))]
                        self.block_until_s[i] = time_s + self.params.game.block_timeout_s
                if self.block_victim[i] < 0:
                    self._end_block(i, time_s)
            if self.block_victim[i] >= 0:
                if time_s >= self.block_until_s[i]:
                    self._end_block(i, time_s)
                    continue
                victim = positions[self.block_victim[i]]
                targets[i] = victim  # drive at the victim itself
                facing[i] = math.atan2(victim[1] - positions[i, 1], victim[0] - positions[i, 0])

    def _end_block(self, i: int, time_s: float) -> None:
        self.block_victim[i] = -1
        self.next_block_s[i] = self._next_event(time_s, self.params.game.block_rate_per_min / 60.0)

    def _next_event(self, time_s: float, rate_per_s: float) -> float:
        return time_s + (float(self.rng.exponential(1.0 / rate_per_s)) if rate_per_s > 0 else math.inf)

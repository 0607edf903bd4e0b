"""The paper's whole method offline: dead reckoning plus its corrections, frame by frame (10 Hz).

Corrections (names used in `reckon eval`):
- `beacon`: reception decided from the BLE sightings in the log (RSSI above the level the
  path-loss model gives at the zone edge); the paper's centroid shift when reception ends.
- `beacon_zone`: reception when the *true* position is within the beacon radius, exactly the
  paper's own simulation (sec. 4.4.1); an upper bound no real radio gives.
- `collision`: impacts > 8 g paired within 0.5 s, reliability-weighted pull (eq. 8-9).
- `collision_midpoint`: the same pairs pulled to their midpoint.
- `video`: each 10 fps frame, with probability 1/200, one random chair is reset to its true
  position (sec. 4.4.2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.chair.paper.dr import PaperDrState, dead_reckon
from hub.chair.paper import (Collision, centroid_shift, decay_reliability, midpoint_collision,
                             weighted_collision)
from protocol.session import Beacon, Venue
from protocol.session_log import Sightings
from reckon.evaluation.inputs import FRAME_HZ, EvalInputs

CORRECTIONS = ("beacon", "beacon_zone", "collision", "collision_midpoint", "video")
VIDEO_FIX_PROBABILITY = 1.0 / 200.0  # per frame (sec. 4.4.2): about one fix every 20 s
VIDEO_RUNS = 10  # the paper averages 10 runs of its random fixes (Fig. 10)

# Turning RSSI into the paper's "within 1 m of the goal": the level a free-space path loss
# (exponent 2) gives at the zone edge, seen from a seat receiver 0.5 m above the floor.
PATH_LOSS_EXPONENT = 2.0
RECEIVER_HEIGHT_M = 0.5
RECEPTION_HOLD_S = 1.0  # reception lasts while an in-zone sighting arrived in the last second


@dataclass
class Estimate:
    x_m: np.ndarray  # (agents, frames)
    y_m: np.ndarray
    corrections_applied: int


def zone_threshold_dbm(beacon: Beacon) -> float:
    slant_m = math.hypot(beacon.radius_m, beacon.height_m - RECEIVER_HEIGHT_M)
    return beacon.tx_power_dbm - 10.0 * PATH_LOSS_EXPONENT * math.log10(max(slant_m, 0.1))


def reception_from_sightings(frame_ns: np.ndarray, sightings: Sightings | None, venue: Venue) -> np.ndarray:
    """Per frame, the index of the beacon whose zone the chair is in (by RSSI), or -1."""
    zone = np.full(len(frame_ns), -1, dtype=np.int64)
    if sightings is None or len(sightings.time_ns) == 0:
        return zone
    best = np.full(len(frame_ns), -np.inf)
    hold_ns = int(RECEPTION_HOLD_S * 1e9)
    for index, beacon in enumerate(venue.beacons):
        strong = (sightings.beacon_id == beacon.id) & (sightings.rssi_dbm >= zone_threshold_dbm(beacon))
        times, rssi = sightings.time_ns[strong], sightings.rssi_dbm[strong]
        if len(times) == 0:
            continue
        # the latest strong sighting at or before each frame, if recent enough
        last = np.searchsorted(times, frame_ns, side="right") - 1
        valid = (last >= 0) & (frame_ns - times[np.clip(last, 0, None)] <= hold_ns)
        level = np.where(valid, rssi[np.clip(last, 0, None)], -np.inf)
        better = level > best
        zone[better] = index
        best[better] = level[better]
    return zone


def reception_from_truth(x_m: np.ndarray, y_m: np.ndarray, venue: Venue) -> np.ndarray:
    zone = np.full(len(x_m), -1, dtype=np.int64)
    for index, beacon in enumerate(venue.beacons):
        zone[np.hypot(x_m - beacon.x_m, y_m - beacon.y_m) <= beacon.radius_m] = index
    return zone


def run_paper(inputs: EvalInputs, heading: list[np.ndarray], corrections: frozenset[str], venue: Venue | None,
              zones: dict[str, np.ndarray], collisions: list[Collision], rng: np.random.Generator) -> Estimate:
    """Dead reckoning with the given heading, then the paper's corrections frame by frame.

    `zones[kind]` is (agents, frames) beacon indices for kind "beacon" or "beacon_zone".
    """
    frames = inputs.frame_index
    n_agents, n_frames = len(inputs.agents), len(frames)
    dr = np.zeros((n_agents, n_frames, 2))
    truth = np.full((n_agents, n_frames, 2), np.nan)
    for a, agent in enumerate(inputs.agents):
        x0, y0, _ = agent.start_pose()
        x, y = dead_reckon(PaperDrState(x0, y0, float(heading[a][0])), agent.travel_m, heading[a][1:])
        dr[a, :, 0], dr[a, :, 1] = x[frames], y[frames]
        if agent.truth_x_m is not None:
            truth[a, :, 0], truth[a, :, 1] = agent.truth_x_m[frames], agent.truth_y_m[frames]
    beacon_kind = next((k for k in ("beacon", "beacon_zone") if k in corrections), None)
    collision_kind = next((k for k in ("collision", "collision_midpoint") if k in corrections), None)
    zone = zones[beacon_kind] if beacon_kind else None
    goals = np.array([[b.x_m, b.y_m] for b in venue.beacons] if venue else []).reshape(-1, 2)
    index = {agent.agent.id: a for a, agent in enumerate(inputs.agents)}
    at_frame: dict[int, list[Collision]] = {}
    if collision_kind:
        for c in collisions:
            k = int(math.ceil((c.time_ns - inputs.grid_ns[0]) * 1e-9 * FRAME_HZ - 1e-9))
            if 0 <= k < n_frames and c.agent_a in index and c.agent_b in index:
                at_frame.setdefault(k, []).append(c)

    estimate = np.zeros_like(dr)
    offset = np.zeros((n_agents, 2))
    reliability = np.ones(n_agents)
    heard = np.full(n_agents, -1)
    heard_from = np.zeros(n_agents, dtype=np.int64)
    heard_sum = np.zeros((n_agents, 2))
    applied = 0
    for k in range(n_frames):
        position = dr[:, k] + offset
        if zone is not None:
            for a in range(n_agents):
                b = zone[a, k]
                if heard[a] >= 0 and b != heard[a]:  # reception ended: eq. 6 over frames heard_from..k-1
                    shift = centroid_shift(heard_sum[a], k - heard_from[a], goals[heard[a]])
                    estimate[a, heard_from[a]:k] += shift  # the stretch heard is moved as a whole
                    offset[a] += shift
                    position[a] += shift
                    reliability[a] = 1.0
                    heard[a] = -1
                    applied += 1
                if b >= 0:
                    if heard[a] < 0:
                        heard[a], heard_from[a], heard_sum[a] = b, k, 0.0
                    heard_sum[a] += position[a]
        for c in at_frame.get(k, ()):
            i, j = index[c.agent_a], index[c.agent_b]
            if collision_kind == "collision":
                point, shared = weighted_collision(position[i], position[j], reliability[i], reliability[j])
                reliability[i] = reliability[j] = shared
                target_i = target_j = point
            else:
                target_i = target_j = midpoint_collision(position[i], position[j])
            offset[i] += target_i - position[i]
            offset[j] += target_j - position[j]
            position[i], position[j] = target_i, target_j
            applied += 1
        if "video" in corrections and rng.random() < VIDEO_FIX_PROBABILITY:
            a = int(rng.integers(n_agents))
            if not np.isnan(truth[a, k, 0]):
                offset[a] = truth[a, k] - dr[a, k]
                position[a] = truth[a, k]
                reliability[a] = 1.0
                applied += 1
        estimate[:, k] = position
        reliability = np.array([decay_reliability(r) for r in reliability])
    return Estimate(estimate[:, :, 0], estimate[:, :, 1], applied)

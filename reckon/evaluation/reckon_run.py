"""Our method offline: the per-chair filter (edge/chair_estimator.py) and the hub's corrections.

All chairs advance together frame by frame (10 Hz, the hub's correction rate); between frames
each filter steps through its own seat samples. `live` is what the hub would publish at each
frame; `refined` is a Rauch-Tung-Striebel pass over the frames (the whole session here: the
offline limit of the hub's fixed-lag smoother).

Corrections: `beacon` (closest approach of each pass near a goal, hub/chair_corrections.py) and
`collision` (impacts grouped within 0.5 s; in a group of two or more chairs, the pair whose
estimates best fit a contact is pulled to contact distance, chi-square gated).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from edge.chair_estimator import (BIAS, GYRO_SCALE, HEADING, NORTH, SCALE, N, X, Y, ChairSample, ChairSettings, ChairState,
                                  position_update, start, step)
from edge.chair_merger import ChairMerger
from hub.chair_corrections import CONTACT_DISTANCE_M, CONTACT_SD_M, beacon_fix, contact_update
from hub.paper_rules import group_impacts
from protocol.session import Venue
from protocol.session_log import Sightings
from reckon.evaluation.inputs import FRAME_HZ, AgentInputs, EvalInputs, agent_impacts

RECKON_CORRECTIONS = ("beacon", "collision")
IMPACT_THRESHOLD_G = 6.0  # lower than the paper's 8 g: the gate, not the threshold, rejects false pairs
PASS_FLOOR_DBM = -72.0  # sightings weaker than this (about 4 m from a goal) do not start or extend a pass
PASS_END_S = 1.5  # a pass ends after this long without a sighting above the floor


@dataclass
class ReckonEstimate:
    x_m: np.ndarray  # (agents, frames)
    y_m: np.ndarray
    corrections_applied: int


@dataclass(frozen=True)
class PassFix:
    frame: int  # when the pass ended: the fix is applied then
    peak_frame: int  # where the chair was at the peak
    xy: np.ndarray
    covariance: np.ndarray


class AgentTrack:
    """One chair's filter, stepped up to each frame time; keeps what the smoother needs."""

    def __init__(self, agent: AgentInputs, samples: list[ChairSample], n_frames: int):
        self.agent = agent
        self.settings = ChairSettings(wheel_diameter_m=agent.agent.wheel_diameter_m, camber_deg=agent.agent.camber_deg)
        self.samples = samples
        x0, y0, h0 = agent.start_pose()
        self.state: ChairState = start(self.settings, self.samples[0], x0, y0, h0)
        self.next = 1
        self.prior_mean = np.zeros((n_frames, N))
        self.prior_cov = np.zeros((n_frames, N, N))
        self.post_mean = np.zeros((n_frames, N))
        self.post_cov = np.zeros((n_frames, N, N))
        self.transition = np.zeros((n_frames, N, N))

    def advance(self, until_ns: int, frame: int) -> None:
        """Step through every sample up to `until_ns`; record the prior for frame `frame`."""
        start_mean = self.state.mean
        while self.next < len(self.samples) and self.samples[self.next].time_ns <= until_ns:
            self.state = step(self.settings, self.state, self.samples[self.next])
            self.next += 1
        self.prior_mean[frame] = self.state.mean
        self.prior_cov[frame] = self.state.cov
        self.transition[frame] = _frame_jacobian(start_mean, self.state.mean)

    def settle(self, frame: int) -> None:
        self.post_mean[frame] = self.state.mean
        self.post_cov[frame] = self.state.cov


def merged_samples(agent: AgentInputs) -> list[ChairSample]:
    """The agent's logged samples pushed through the live path's merger, in arrival (time) order."""
    merger = ChairMerger(agent.agent)
    streams = [(sensor_id, series) for sensor_id, series in agent.raw.items()]
    times = np.concatenate([series.time_ns for _, series in streams])
    which = np.concatenate([np.full(len(series.time_ns), i) for i, (_, series) in enumerate(streams)])
    index = np.concatenate([np.arange(len(series.time_ns)) for _, series in streams])
    samples: list[ChairSample] = []
    for k in np.argsort(times, kind="stable"):
        sensor_id, series = streams[which[k]]
        i = index[k]
        mag = None if series.mag_gauss is None else tuple(series.mag_gauss[i].tolist())
        samples += merger.push(sensor_id, int(series.time_ns[i]), tuple(series.accel_g[i].tolist()),
                               tuple(series.gyro_dps[i].tolist()), mag)
    return samples + merger.flush()


def _frame_jacobian(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Jacobian of one frame's motion (state after vs state before), linearised over the frame.

    A heading error rotates the frame's displacement; the gyro bias and scale errors act through
    the heading, on average over the frame; the wheel scale stretches the displacement.
    """
    jacobian = np.eye(N)
    dx, dy = after[X] - before[X], after[Y] - before[Y]
    jacobian[X, HEADING], jacobian[Y, HEADING] = -dy, dx
    if before[SCALE] != 0.0:
        jacobian[X, SCALE], jacobian[Y, SCALE] = dx / before[SCALE], dy / before[SCALE]
    turn = after[HEADING] - before[HEADING]
    jacobian[HEADING, BIAS] = -1.0 / FRAME_HZ
    jacobian[HEADING, GYRO_SCALE] = turn / (1.0 + before[GYRO_SCALE])
    for column in (BIAS, GYRO_SCALE):
        jacobian[X, column] = -dy * 0.5 * jacobian[HEADING, column]
        jacobian[Y, column] = dx * 0.5 * jacobian[HEADING, column]
    return jacobian


def rts_smooth(track: AgentTrack) -> np.ndarray:
    """Smoothed means over frames (Rauch-Tung-Striebel, frame-level linearisation).

    North is left out: it is (re)initialised from the magnetometer fit, a jump no transition
    explains, and positions do not depend on it.
    """
    kept = slice(0, NORTH)
    smoothed = track.post_mean.copy()
    for k in range(len(smoothed) - 2, -1, -1):
        transition = track.transition[k + 1][kept, kept]
        gain = track.post_cov[k][kept, kept] @ transition.T @ np.linalg.pinv(track.prior_cov[k + 1][kept, kept])
        smoothed[k, kept] = track.post_mean[k, kept] + gain @ (smoothed[k + 1, kept] - track.prior_mean[k + 1, kept])
    return smoothed


def beacon_passes(frame_ns: np.ndarray, sightings: Sightings | None, venue: Venue) -> list[PassFix]:
    """Each pass near a goal (sightings above the floor, gaps < PASS_END_S) -> one fix at its peak."""
    fixes: list[PassFix] = []
    if sightings is None:
        return fixes
    for beacon in venue.beacons:
        strong = (sightings.beacon_id == beacon.id) & (sightings.rssi_dbm >= PASS_FLOOR_DBM)
        times, rssi = sightings.time_ns[strong], sightings.rssi_dbm[strong]
        if len(times) == 0:
            continue
        breaks = np.flatnonzero(np.diff(times) > PASS_END_S * 1e9) + 1
        for pass_times, pass_rssi in zip(np.split(times, breaks), np.split(rssi, breaks)):
            peak = int(np.argmax(pass_rssi))
            fix = beacon_fix(beacon, float(pass_rssi[peak]))
            if fix is None:
                continue
            end = int(np.searchsorted(frame_ns, pass_times[-1] + PASS_END_S * 1e9))
            peak_frame = min(int(np.searchsorted(frame_ns, pass_times[peak])), len(frame_ns) - 1)
            if end < len(frame_ns):
                fixes.append(PassFix(end, peak_frame, fix.xy, fix.covariance))
    return fixes


def impact_groups(inputs: EvalInputs, frame_ns: np.ndarray) -> dict[int, list[list[str]]]:
    groups: dict[int, list[list[str]]] = {}
    for time_ns, agents in group_impacts(agent_impacts(inputs, IMPACT_THRESHOLD_G)):
        k = int(np.searchsorted(frame_ns, time_ns))
        if len(agents) >= 2 and k < len(frame_ns):
            groups.setdefault(k, []).append(agents)
    return groups


def _best_pair(tracks: dict[str, AgentTrack], agents: list[str]) -> tuple[str, str] | None:
    """The pair whose estimated separation best fits a contact (smallest normalised residual)."""
    best, best_score = None, np.inf
    for a, b in itertools.combinations(agents, 2):
        sa, sb = tracks[a].state, tracks[b].state
        distance = float(np.hypot(*(sa.mean[:2] - sb.mean[:2])))
        spread = np.trace(sa.cov[:2, :2]) / 2 + np.trace(sb.cov[:2, :2]) / 2 + CONTACT_SD_M**2
        score = (distance - CONTACT_DISTANCE_M) ** 2 / spread
        if score < best_score:
            best, best_score = (a, b), score
    return best


def run_reckon(inputs: EvalInputs, corrections: frozenset[str], venue: Venue, sightings: dict[str, Sightings],
               samples: dict[str, list[ChairSample]] | None = None) -> tuple[ReckonEstimate, ReckonEstimate]:
    """(live, refined) estimates of every chair at every frame.

    `samples`: each agent's `merged_samples`, when the caller runs several correction sets.
    """
    frame_ns = inputs.frame_ns
    samples = samples or {agent.agent.id: merged_samples(agent) for agent in inputs.agents}
    tracks = {agent.agent.id: AgentTrack(agent, samples[agent.agent.id], len(frame_ns)) for agent in inputs.agents}
    fixes_at: dict[int, list[tuple[str, PassFix]]] = {}
    if "beacon" in corrections:
        for agent_id in tracks:
            for fix in beacon_passes(frame_ns, sightings.get(agent_id), venue):
                fixes_at.setdefault(fix.frame, []).append((agent_id, fix))
    groups = impact_groups(inputs, frame_ns) if "collision" in corrections else {}
    applied = 0
    for k, now_ns in enumerate(frame_ns):
        for track in tracks.values():
            track.advance(int(now_ns), k)
        for agent_id, fix in fixes_at.get(k, ()):
            track = tracks[agent_id]
            # delayed fix: the chair was at fix.xy when the peak came; carry that offset to now
            shift = fix.xy - track.post_mean[fix.peak_frame, :2]
            track.state, used = position_update(track.state, track.state.mean[:2] + shift, fix.covariance)
            applied += used
        for agents in groups.get(k, ()):
            pair = _best_pair(tracks, agents)
            if pair:
                a, b = pair
                tracks[a].state, tracks[b].state, used = contact_update(tracks[a].state, tracks[b].state)
                applied += used
        for track in tracks.values():
            track.settle(k)
    ordered = [tracks[agent.agent.id] for agent in inputs.agents]
    live = ReckonEstimate(np.array([t.post_mean[:, X] for t in ordered]), np.array([t.post_mean[:, Y] for t in ordered]), applied)
    smoothed = [rts_smooth(t) for t in ordered]
    refined = ReckonEstimate(np.array([s[:, X] for s in smoothed]), np.array([s[:, Y] for s in smoothed]), applied)
    return live, refined



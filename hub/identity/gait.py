"""Gait phase: a walker's steps as the camera sees them (the head's bob) against the waist IMU's.

A walking body rises and falls once per step, the head with the pelvis (the inverted pendulum: a few
centimetres). A camera that reports head heights sees that bob under its noise; the waist IMU feels
the same motion as vertical acceleration, in antiphase with the height at the step frequency. Two
people walking side by side at one speed have the same speed, turn rate and activity, but not the
same step timing: over a few seconds the right pair's signals are phase-locked and a wrong pair's
drift past each other. So per hop, for every track and pedestrian agent, the correlation of the
track's head height with minus the agent's vertical acceleration, both band-passed to the step band
(`BAND_HZ`), over the last `WINDOW_BINS` bins:
- compared only while the agent walks (its activity above WALKING_G over the window); NaN otherwise,
  so still or seated people are judged by the other cues alone. A track seen for less than the
  window is compared over what it has, from 1.2 s on (a new fragment is when naming happens);
- at a lag learned without labels: the pairs the engine holds with clear evidence and a full window
  add their correlation at each candidate lag (`LAGS` bins, camera height against the IMU) to
  forgetting sums, and the cue votes only once they hold LAG_MIN_WEIGHT comparisons (at a wrong lag
  a right pair looks out of step); the same pairs learn the correlation a right pair shows
  (`reference`, from PRIOR_REFERENCE);
- the cost per bin of the hop is weight x (reference - correlation) x the share of a full window
  compared: about 0 for the right pair, weight x reference for a wrong one (its correlation
  scatters around 0).
State: two small arrays and three numbers; work per hop O(tracks x agents x lags x window).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt

from hub.identity.cues import BIN_S, WALKING_G

BAND_HZ = (1.0, 3.0)  # walking cadence 1.2-2.4 steps/s (the room simulator's gait bounds, docs/simulator-room.md)
WINDOW_BINS = 24  # 2.4 s, 4 steps at 1.8 Hz: 4 s windows were seldom whole (the room's tracks break every few seconds)
LAGS = np.arange(-2, 4)  # bins of camera height against the IMU, -0.2 .. +0.3 s: one step, so a step off cannot alias
LAG_MIN_WEIGHT = 10.0
LAG_FORGET = 0.995  # per comparison: the lag is what the last few hundred held pairs said
LOCKED_CORRELATION = 0.15  # the held pairs' mean correlation at the best lag, at least
PRIOR_REFERENCE = 0.3  # a right pair's correlation while walking (simulated room, seed 1: median 0.37)
REFERENCE_PRIOR_WEIGHT = 20.0
# A track seen for less than the window is compared over the longest of these it has (a few sizes, so a
# hop's tracks fall into a few groups computed at once); under the first (1.2 s, two steps) not at all.
WINDOW_SIZES = (12, 16, 20, WINDOW_BINS)
PAD_BINS = 4  # read before the window, so the band-pass has settled where the window starts
FILTER_PAD = 8  # filtfilt's own padding (odd extension) at both ends


class GaitPhase:
    def __init__(self, weight: float):
        self.weight = weight
        self.sos = butter(2, BAND_HZ, btype="band", fs=1.0 / BIN_S, output="sos")
        self.operators: dict[int, np.ndarray] = {}  # series length -> its band-pass as a matrix
        self.lag_sums = np.zeros(len(LAGS))
        self.lag_weight = 0.0
        self.reference_sum = PRIOR_REFERENCE * REFERENCE_PRIOR_WEIGHT
        self.reference_weight = REFERENCE_PRIOR_WEIGHT
        self.bins = np.zeros(0, dtype=np.int64)  # the last hop's window per track (0: not compared)

    @property
    def calibrated(self) -> bool:
        """Enough held pairs, and they step together at the best lag: pairs held wrongly (a crowd the other
        cues cannot sort) correlate around 0 at every lag and must not teach the cue anything."""
        return (self.lag_weight >= LAG_MIN_WEIGHT
                and float(self.lag_sums.max()) >= LOCKED_CORRELATION * self.lag_weight)

    @property
    def lag(self) -> int:
        """The lag (bins) the held pairs step together at (meaningful once calibrated)."""
        return int(LAGS[int(np.argmax(self.lag_sums))])

    @property
    def reference(self) -> float:
        return self.reference_sum / self.reference_weight

    def correlations(self, heights: np.ndarray, vertical: np.ndarray, activity: np.ndarray) -> np.ndarray:
        """(tracks, agents, lags) correlations over the window; NaN where a side is incomplete or still.
        heights (tracks, WINDOW_BINS + PAD_BINS): the tracks' head heights up to the window's end; a track
        seen for less is compared over the longest of WINDOW_SIZES it has (`bins` says which, per track);
        vertical and activity (agents, WINDOW_BINS + PAD_BINS + span of LAGS): the agents' vertical
        acceleration and activity, ending LAGS.min() bins after the window's end."""
        n_tracks, n_agents = len(heights), len(vertical)
        out = np.full((n_tracks, n_agents, len(LAGS)), np.nan)
        self.bins = np.zeros(n_tracks, dtype=np.int64)
        agent_ok = np.isfinite(vertical).all(axis=1)
        if not agent_ok.any():
            return out
        v = np.where(agent_ok[:, None], -(np.nan_to_num(vertical) @ self._operator(vertical.shape[1]).T), 0.0)
        finite = np.isfinite(heights)
        last_gap = np.where(finite.all(axis=1), -1, heights.shape[1] - 1 - np.argmax(~finite[:, ::-1], axis=1))
        seen = heights.shape[1] - 1 - last_gap  # each track's trailing run of heights
        stops = v.shape[1] - (LAGS - LAGS.min())  # per lag, where the agent's bins `lag` before the track's end
        sizes = np.array(WINDOW_SIZES)
        window = np.where(seen >= sizes[0], sizes[np.clip(np.searchsorted(sizes, seen, side="right") - 1, 0, None)], 0)
        for count in np.unique(window[window > 0]).tolist():
            rows = np.flatnonzero(window == count)
            length = min(count + PAD_BINS, int(seen[rows].min()))  # filtered over what every track of the group has
            h = (heights[rows, -length:] @ self._operator(length).T)[:, -count:]
            h = h - h.mean(axis=1, keepdims=True)
            h_norm = np.sqrt((h * h).sum(axis=1))
            a = np.stack([v[:, stop - count:stop] for stop in stops])  # (lags, agents, count)
            a = a - a.mean(axis=2, keepdims=True)
            a_norm = np.sqrt((a * a).sum(axis=2))
            moving = np.stack([activity[:, stop - count:stop] for stop in stops])
            known = np.isfinite(moving)
            power = np.where(known, moving * moving, 0.0).sum(axis=2) / np.maximum(known.sum(axis=2), 1)
            walking = np.sqrt(power) > WALKING_G
            with np.errstate(invalid="ignore", divide="ignore"):
                corr = np.einsum("nc,lac->nal", h, a) / (h_norm[:, None, None] * a_norm.T[None])
            ok = (agent_ok[:, None] & walking.T & (a_norm.T > 0))[None] & (h_norm > 0)[:, None, None]
            out[rows] = np.where(ok, corr, np.nan)
            self.bins[rows] = np.where(h_norm > 0, count, 0)
        return out

    def _operator(self, length: int) -> np.ndarray:
        """The zero-phase band-pass (filtfilt, odd padding) of a series of this length, as a matrix: it is
        linear, so it is made once per length (a few) and each hop's filtering is one product."""
        if length not in self.operators:
            self.operators[length] = sosfiltfilt(self.sos, np.eye(length), axis=0, padlen=min(FILTER_PAD, length - 1))
        return self.operators[length]

    def cost(self, correlations: np.ndarray) -> np.ndarray:
        """(tracks, agents): weight x (reference - correlation at the learned lag) x the share of a full
        window the track was compared over (a short one says less); NaN where not compared, and
        everywhere until the lag is learned (at a wrong lag a right pair's steps look out of phase)."""
        if not self.calibrated:
            return np.full(correlations.shape[:2], np.nan)
        at = correlations[:, :, int(np.flatnonzero(LAGS == self.lag)[0])]
        return self.weight * (self.reference - at) * (self.bins / WINDOW_BINS)[:, None]

    def learn(self, correlations: np.ndarray, held: list[tuple[int, int]]) -> None:
        """Pairs (track row, agent) the engine holds with clear evidence: their correlations teach the lag
        and the right pair's reference correlation."""
        for row, agent in held:
            values = correlations[row, agent]
            if not (np.isfinite(values).all() and self.bins[row] == WINDOW_BINS):
                continue
            if self.calibrated:  # at the lag it votes at
                self.reference_sum += float(values[int(np.flatnonzero(LAGS == self.lag)[0])])
                self.reference_weight += 1.0
            self.lag_sums = self.lag_sums * LAG_FORGET + values
            self.lag_weight = self.lag_weight * LAG_FORGET + 1.0

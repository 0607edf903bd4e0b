"""Who is which camera track: streaming association of anonymous tracks with the agents' sensors.

The camera-identity paper (hub/identity/paper/search.py) scores whole fragments offline and tries every
order of people. Here every hop (hop_s of camera time) the newest bins of motion cues
(hub/identity/cues.py) of every live track are compared with every agent's:
- speed: a chair's dead-reckoned speed, a pedestrian's from its waist activity (the paper's cue);
- turn rate: gyro about the vertical against the rotation of the track's velocity;
- moving or still;
- direction (chairs): a moving track's course against the dead-reckoned one, less the pair's usual angle;
- position: the track against where the agent was last seen or, for a chair, the hub's pose;
- stature (trackers that report head heights): how much worse the agent's motion has matched tracks
  of this head height than of its best-matching one, over the session (StatureProfile);
- gait phase (pedestrians, trackers that report head heights): whether the track's head bobs in step
  with the agent's waist over the last seconds (hub/identity/gait.py).
Each bin gives a normalised squared error per cue (about 1 for the right pair). A pair's evidence
is the forgetting mean of its bins' costs (factor forget_per_s per second, after a prior that
makes a new track earn its identity). The assignment is the Hungarian method (scipy) over tracks
and agents with "nobody" on both sides at nobody_cost, the current pairs favoured by
switch_margin so identities do not flicker. Work per hop is tracks x agents x new bins.

An identified track gives its agent a PositionFix (kind VIDEO) every fix_every_s while the pair's
evidence is clear; the hub turns it into a correction like any fix. An agent without a track is
carried by its own dead reckoning (the hub's pose) until a track matches again.
The camera's clock offset is searched on the identified chairs every lag_every_s, within max_lag_s
of lag_prior_s in total (pedestrians' turn rates do not separate pairs: docs/identity.md).

Four rules follow the tracker's own errors (docs/identity.md): continuation of a broken-off track,
births, encounters and shares; they are hub/identity/rules.py (`TrackRules`, a part of the engine that
works on its track records, hub/identity/book.py). The settings and counters are hub/identity/settings.py.
This module is the engine: inputs, the hop's scoring, the assignment (solved in independent parts),
fixes and the camera's clock offset.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, Callable

import numpy as np
from scipy.optimize import linear_sum_assignment

from hub.clocks import ClockOffsets
from hub.identity.assign import BIG, components, exclusion_margin, padded, swap_bound
from hub.identity.book import Lost, Track, identity_message
from hub.identity.cues import (BIN_NS, BIN_S, MOVING_MPS, TRACK_DELAY_BINS, TURN_BINS, AgentCues, StatureProfile,
                               SpeedModel, TrackCues, agent_hop_blocks, track_hop_cues)
from hub.identity.gait import LAGS, PAD_BINS, WINDOW_BINS, GaitPhase
from hub.identity.rules import TrackRules
from hub.identity.settings import IdentityCounters, IdentitySettings
from hub.identity.window import LiveWindow
from protocol import messages
from protocol.messages import CorrectionKind
from protocol.session import AgentKind, Mount, Session

# how far a seated head is below the stature: seat + sitting height ~0.52 x stature (docs/simulator-room.md)
SEATED_DROP_M = (0.33, 0.38, 0.43)


class IdentityEngine:
    """`on_message(message)` -> outputs (TrackIdentity, PositionFix); `assignment()`: who holds which track.

    `pose_of(agent_id, time_ns)`: the hub's (xy, sd) of an agent, or None. `clock`: a wall clock in seconds
    (the caller's `time.perf_counter`) that times each hop into `update_s`; None: hops are not timed. The
    engine reads no clock of its own, so its outputs depend on its inputs only."""

    def __init__(self, session: Session, settings: IdentitySettings = IdentitySettings(),
                 pose_of: Callable[[str, int], tuple[np.ndarray, float] | None] | None = None,
                 clock: Callable[[], float] | None = None):
        self.settings = settings
        self.clock = clock
        self.venue = session.venue.name
        self.pose_of = pose_of  # the hub's (xy, sd) of an agent at a venue time, when it has one
        self.clocks = ClockOffsets()
        self.agents: list[AgentCues] = []
        self.kinds: list[AgentKind] = []
        for agent in session.agents:
            sensor = agent.sensor(Mount.SEAT) or agent.sensor(Mount.WAIST) or next(
                (s for s in agent.sensors if not s.mount.on_wheel), None)
            if sensor is None or agent.kind is AgentKind.SWIMMER:
                continue
            self.agents.append(AgentCues(agent.id, sensor.id, sensor.rate_hz))
            self.kinds.append(agent.kind)
        self.index = {cues.agent_id: i for i, cues in enumerate(self.agents)}
        # where each agent's edge starts its filter (the session's start; 0.1 m sd, edge/chair/estimator.py):
        # the hub's pose of a chair before its first edge pose has arrived
        self.start_xy = {self.index[a.id]: np.array([a.start_x_m, a.start_y_m]) for a in session.agents
                         if a.id in self.index}
        self.is_chair = np.array([kind is AgentKind.WHEELCHAIR for kind in self.kinds], dtype=bool)
        self.is_pedestrian = np.array([kind is AgentKind.PEDESTRIAN for kind in self.kinds], dtype=bool)
        self.by_sensor = {cues.sensor_id: i for i, cues in enumerate(self.agents)}
        count = len(self.agents)
        self.seen_xy = np.full((count, 2), np.nan)  # where each agent's track last was
        self.seen_ns = np.zeros(count, dtype=np.int64)
        self.speed_model = SpeedModel()
        self.statures = StatureProfile(count)
        self.gait = GaitPhase(settings.gait_weight)
        self.gait_correlations: np.ndarray | None = None  # the last hop's (tracks, agents, lags), for learning
        self.tracks: dict[tuple[str, int], Track] = {}
        self.lost: dict[int, Lost] = {}  # agent -> where its last track broke off (until it holds another)
        self.scored_until: dict[str, int] = {}  # camera -> first bin not yet scored
        self.next_lag_bin: dict[str, int] = {}
        self.lag_bins: dict[str, int] = {}
        self.counters = IdentityCounters()
        self.update_s: deque[float] = deque(maxlen=4096)  # wall time of the latest hops (reports, not control)
        self.delays_s: deque[float] = deque(maxlen=4096)  # ... and how far behind the camera each scored
        self.walkers = [i for i in range(count) if self.is_pedestrian[i]]
        self.windows: dict[str, LiveWindow] = {}  # camera -> its walkers' window (settings.window_s > 0)
        self.rules = TrackRules(settings, self.agents, self.is_chair, self.start_xy, self.tracks, self.lost,
                                self.counters, pose_of)

    # -- inputs ------------------------------------------------------------------------------

    def on_message(self, message: Any) -> list[Any]:
        name = messages.type_name(message)
        if name == "CameraFrame":
            return self.on_frame(message)
        if name == "ImuBatch":
            self.on_imu(message)
        elif name == "ClockSample":
            self.clocks.observe(message.sensor_id, message.timestamp_ns, message.received_ns)
        elif name == "EstimatedPose":  # the hub passes only its edges' poses (pose/edge), never its own
            self.on_edge_pose(message)
        return []

    def on_imu(self, batch: Any) -> None:
        i = self.by_sensor.get(batch.sensor_id)
        if i is None or not len(batch.sample_offset_ns):
            return
        if batch.received_ns:
            self.clocks.observe(batch.sensor_id, batch.timestamp_ns + batch.sample_offset_ns[-1], batch.received_ns)
        times = batch.timestamp_ns + np.asarray(batch.sample_offset_ns, dtype=np.int64) + self.clocks.offset_ns(batch.sensor_id)
        self.agents[i].push_imu(times, np.asarray(batch.accel_g, dtype=float).reshape(-1, 3),
                                np.asarray(batch.gyro_dps, dtype=float).reshape(-1, 3))

    def on_edge_pose(self, pose: Any) -> None:
        i = self.index.get(pose.agent_id)
        if i is None:
            return
        cues = self.agents[i]
        cues.push_pose(self.clocks.to_venue(cues.sensor_id, pose.timestamp_ns), pose.x_m, pose.y_m, pose.heading_rad,
                       pose.correction_sequence)

    def on_frame(self, frame: Any) -> list[Any]:
        camera = frame.camera_id
        lag_ns = self.lag_bins.setdefault(camera, int(round(self.settings.lag_prior_s / BIN_S))) * BIN_NS
        time_ns = frame.timestamp_ns - lag_ns
        new = []
        count = len(frame.track_id)
        if len(frame.x_m) != count or len(frame.y_m) != count:  # zip would pair rows with other tracks' positions
            raise ValueError(f"CameraFrame {camera} frame {frame.frame}: track_id has {count} entries, x_m "
                             f"{len(frame.x_m)}, y_m {len(frame.y_m)}: they must be the same")
        self.counters.frames += 1
        heights = frame.height_m if len(frame.height_m) == count else [float("nan")] * count  # none: no height cue
        for track_id, x, y, height in zip(frame.track_id, frame.x_m, frame.y_m, heights):
            if not math.isfinite(x + y):  # a tracker's bad row: the rest of the frame stands
                self.counters.rows_not_numbers += 1
                continue
            key = (camera, int(track_id))
            track = self.tracks.get(key)
            if track is None:
                track = self.tracks[key] = Track(TrackCues(int(track_id)), np.zeros((2, len(self.agents))),
                                                  np.zeros((2, len(self.agents))), born_ns=time_ns)
                self.counters.tracks += 1
                new.append(key)
            track.cues.push(time_ns, float(x), float(y), float(height))
        out = self.rules.continue_tracks(camera, new, time_ns) if new else []
        bin_now = time_ns // BIN_NS
        first = self.scored_until.setdefault(camera, bin_now)
        end = self._scored_end(bin_now)
        if end - first < int(round(self.settings.hop_s / BIN_S)):
            return out
        self.scored_until[camera] = end
        self.delays_s.append((bin_now - end) * BIN_S)
        started = self.clock() if self.clock is not None else None
        out += self._update(camera, first, end, frame.position_sd_m, time_ns)
        if started is not None:
            self.update_s.append(self.clock() - started)
        return out

    def _scored_end(self, bin_now: int) -> int:
        """The first bin not to score yet: at least delay_s back, and no further than every live agent's data has
        reached (its cues are compared TRACK_DELAY_BINS earlier), but at most max_delay_s back. A bin scored
        before an agent's data is in would count nothing for it, for good."""
        s = self.settings
        earliest, latest = bin_now - int(round(s.max_delay_s / BIN_S)), bin_now - int(round(s.delay_s / BIN_S))
        ready = [a.complete_bin() + 1 + TRACK_DELAY_BINS for a in self.agents]
        live = [bin_ for bin_ in ready if bin_ > earliest]
        return max(earliest, min([latest] + live))

    # -- one hop -----------------------------------------------------------------------------

    def _update(self, camera: str, first: int, end: int, camera_sd_m: float, now_ns: int) -> list[Any]:
        s = self.settings
        timeout = int(s.track_timeout_s * 1e9)
        gone = [k for k, t in self.tracks.items() if k[0] == camera and now_ns - t.cues.last_ns > timeout]
        keys = [k for k in self.tracks if k[0] == camera and k not in set(gone)]
        shares = self.rules.encounters(gone, keys, first, now_ns)
        out = [message for k in gone for message in self._drop(k, now_ns)]
        out += self.rules.share(camera, shares, now_ns)
        if not keys or not self.agents:
            return out
        tracks = [self.tracks[k] for k in keys]
        count = end - first
        agent_cues = self._agent_windows(first, count)
        track_cues = track_hop_cues([t.cues for t in tracks], first, count)
        window = self._window(camera)
        if window is not None:
            window.add(keys, track_cues["speed"], agent_cues["activity"], first)
            if window.due(end):
                window.solve(end)
                self.counters.window_solves += 1
        costs = self._bin_costs(tracks, track_cues, agent_cues, first, count, camera_sd_m)  # (T, A, bins), NaN = not comparable
        forget = np.stack([np.where(self.is_pedestrian, s.pedestrian_forget_per_s, s.forget_per_s),
                           np.full(len(self.agents), s.fast_forget_per_s)]) ** (count * BIN_S)
        bins = np.arange(first, end)
        for row, track in enumerate(tracks):
            valid = np.isfinite(costs[row])
            if track.since_bin is not None:
                valid &= bins[None, :] >= track.since_bin[:, None]
            track.cost_sum = track.cost_sum * forget + np.where(valid, costs[row], 0.0).sum(axis=1)[None]
            track.cost_count = track.cost_count * forget + valid.sum(axis=1)[None]
        self.counters.updates += 1
        work = len(tracks) * len(self.agents) * count
        self.counters.pair_bins += work
        self.counters.max_pair_bins = max(self.counters.max_pair_bins, work)
        evidence = np.array([self._evidence(t) for t in tracks])
        if window is not None:
            evidence = window.steer(keys, evidence, s.window_weight)
        out += self._assign(camera, keys, tracks, evidence, now_ns)
        out += self._fixes(camera, tracks, evidence, now_ns, camera_sd_m, end * BIN_NS)
        self._learn_speed(tracks, evidence, first, count)
        if self.gait_correlations is not None:  # pedestrians held with clear evidence teach the gait cue
            self.gait.learn(self.gait_correlations, [(row, t.agent) for row, t in enumerate(tracks) if t.agent >= 0
                                                     and self.is_pedestrian[t.agent]
                                                     and evidence[row, t.agent] <= s.fix_cost])
        if end >= self.next_lag_bin.get(camera, end):
            self.next_lag_bin[camera] = end + int(s.lag_every_s / BIN_S)
            self._search_lag(camera, tracks, end)
        return out

    def _window(self, camera: str) -> LiveWindow | None:
        s = self.settings
        if s.window_s <= 0 or not 0 < len(self.walkers) <= s.window_max_walkers:
            return None
        window = self.windows.get(camera)
        if window is None:
            window = self.windows[camera] = LiveWindow(self.walkers, s.window_s, s.window_every_s, s.window_iterations)
        return window

    def _evidence(self, track: Track) -> np.ndarray:
        """Per agent: the slow mean of its bins' costs on this track (after the prior) or, where recent bins
        disagree with it, the fast one's: a holder whose recent bins are bad loses the track sooner, and
        an agent whose recent bins are good is not held back by bad ones from before (a merge, a crowd)."""
        s = self.settings
        means = (track.cost_sum + s.prior_cost * s.prior_bins) / (track.cost_count + s.prior_bins)
        if s.fast_forget_per_s <= 0:
            return means[0]
        slow, fast = means
        return np.minimum(slow, fast + s.fast_margin)


    def _agent_windows(self, first: int, count: int) -> dict[str, np.ndarray]:
        """Every agent's cues for the track bins first..first+count-1 (an agent's are TRACK_DELAY_BINS older)."""
        b = agent_hop_blocks(self.agents, first, count, TRACK_DELAY_BINS)
        chair = self.is_chair & np.isfinite(b["speed_dr"]).any(axis=1)
        # a pedestrian's speed from its activity, already as slow as a fit (no delay)
        speed = np.where(chair[:, None], b["speed_dr"], self.speed_model.predict(b["activity"]))
        yaw = np.where(chair[:, None], b["yaw_dr"], b["yaw"])
        with np.errstate(invalid="ignore"):
            moving = np.where(np.isfinite(speed), speed > MOVING_MPS, np.nan)
        return {"speed": speed, "yaw": yaw, "moving": moving, "tilt": b["tilt"], "activity": b["activity"],
                "vx": np.where(chair[:, None], b["vx_dr"], np.nan), "vy": np.where(chair[:, None], b["vy_dr"], np.nan)}

    def _bin_costs(self, tracks: list[Track], cues: dict[str, np.ndarray], agent: dict[str, np.ndarray], first: int,
                   count: int, camera_sd_m: float) -> np.ndarray:
        s = self.settings
        t_speed, t_yaw, t_x, t_y = cues["speed"], cues["yaw"], cues["x"], cues["y"]
        with np.errstate(invalid="ignore"):
            t_moving = np.where(np.isfinite(t_speed), t_speed > MOVING_MPS, np.nan)

        def normalised(track_values: np.ndarray, agent_values: np.ndarray, sd: float) -> np.ndarray:
            return np.minimum(((track_values[:, None, :] - agent_values[None, :, :]) / sd) ** 2, s.clip)

        parts = [normalised(t_speed, agent["speed"], s.speed_sd_mps),
                 normalised(t_moving, agent["moving"], s.moving_sd),
                 normalised(t_yaw, agent["yaw"], s.yaw_sd_dps)]
        if s.course_sd_deg > 0 and np.isfinite(agent["vx"]).any():  # only agents with dead reckoning (chairs) have one
            parts.append(self._course_cost(tracks, cues["vx"], cues["vy"], agent["vx"], agent["vy"], count))
        position = self._position_cost(tracks, t_x, t_y, first, count, camera_sd_m)
        if position is not None:
            parts.append(position)
        stack = np.stack(parts)
        present = np.isfinite(stack)
        # each cue adds its excess over what the right pair would show on average (1, a normalised
        # squared error); a bin counts once its speed (both sides) is known
        excess = np.where(present, stack - 1.0, 0.0).sum(axis=0)
        if s.stature_weight > 0 and np.isfinite(cues["height"]).any():
            motion = np.where(present[0], np.where(present[:3], stack[:3] - 1.0, 0.0).sum(axis=0), np.nan)
            stature = self._stature_cost(cues["height"], agent["tilt"])  # from the bins before these
            with np.errstate(invalid="ignore"):
                self.statures.learn(cues["height"], motion, t_speed > MOVING_MPS)
            excess = excess + np.where(np.isfinite(stature), s.stature_weight * stature, 0.0)
        self.gait_correlations = None
        if s.gait_weight > 0 and self.is_pedestrian.any() and np.isfinite(cues["height"]).any():
            phase = self._gait_cost(tracks, first + count)
            excess = excess + np.where(np.isfinite(phase), phase, 0.0)[:, :, None]
        return np.where(present[0], excess, np.nan)

    def _gait_cost(self, tracks: list[Track], end: int) -> np.ndarray:
        """(tracks, agents) gait-phase cost over the window ending at bin `end` (exclusive); NaN for
        chairs and where not compared."""
        read = WINDOW_BINS + PAD_BINS
        heights = np.stack([t.cues.ring.window("height", end - read, read) for t in tracks])
        span = int(LAGS.max() - LAGS.min())
        start = end - read - int(LAGS.max())
        blocks = np.stack([a.ring.block(start, read + span) for a in self.agents])
        rows = self.agents[0].ring.row
        vertical, activity = blocks[:, rows["vertical"]], blocks[:, rows["activity"]]
        correlations = self.gait.correlations(heights, vertical, activity)
        correlations[:, ~self.is_pedestrian] = np.nan
        self.gait_correlations = correlations
        return self.gait.cost(correlations)

    def _stature_cost(self, height_m: np.ndarray, tilt_deg: np.ndarray) -> np.ndarray:
        """(tracks, agents, bins) from the stature profile; for an agent whose waist says it sits (tilted
        seated_tilt_deg from walking upright), the profile is read SEATED_DROP_M above the track's head."""
        stature = self.statures.cost(height_m)
        with np.errstate(invalid="ignore"):
            seated = tilt_deg > self.settings.seated_tilt_deg
        if seated.any():
            risen = np.fmin.reduce([self.statures.cost(height_m + drop) for drop in SEATED_DROP_M])
            stature = np.where(seated[None], risen, stature)
        return stature

    def _course_cost(self, tracks: list[Track], t_vx: np.ndarray, t_vy: np.ndarray, a_vx: np.ndarray,
                     a_vy: np.ndarray, count: int) -> np.ndarray:
        """The angle between a track's velocity and an agent's dead-reckoned one, less the pair's usual angle,
        (tracks, agents, bins); NaN unless both move. A chair's heading mostly stays within a few degrees of
        the truth (docs/identity.md), so its direction of travel is nearly absolute: after a crossing the
        chairs leave in different directions. But a knock can turn it by 20 deg for a minute, and then its
        own track would look wrong and never be claimed back (a 317 s game: its pose 2-6 m off for 60 s).
        So each pair learns its usual angle (a forgetting circular mean, shrunk towards 0 by
        course_prior_bins): steady for the right pair, wandering for a wrong one. Scored against the
        angle learnt from the bins before these (a bin never judges itself)."""
        s = self.settings
        tvx, tvy = t_vx[:, None, :], t_vy[:, None, :]
        avx, avy = a_vx[None], a_vy[None]
        angle = np.arctan2(tvx * avy - tvy * avx, tvx * avx + tvy * avy)  # rad, (T, A, bins)
        with np.errstate(invalid="ignore"):
            moving = (np.hypot(tvx, tvy) > s.course_min_mps) & (np.hypot(avx, avy) > s.course_min_mps)
        forget = s.course_forget_per_s ** (count * BIN_S)
        usual = np.empty((len(tracks), angle.shape[1]))
        for row, track in enumerate(tracks):
            if track.course is None:
                track.course = np.zeros((2, angle.shape[1]))
            usual[row] = np.arctan2(track.course[1], s.course_prior_bins + track.course[0])
            ok = moving[row]
            track.course = track.course * forget + np.stack([np.where(ok, np.cos(angle[row]), 0.0).sum(axis=1),
                                                             np.where(ok, np.sin(angle[row]), 0.0).sum(axis=1)])
        residual = np.degrees((angle - usual[:, :, None] + np.pi) % (2 * np.pi) - np.pi)
        return np.where(moving, np.minimum((residual / s.course_sd_deg) ** 2, s.clip), np.nan)

    def _position_cost(self, tracks: list[Track], t_x: np.ndarray, t_y: np.ndarray, first: int, count: int,
                       camera_sd_m: float) -> np.ndarray | None:
        """Where each agent is expected: a chair where the hub has it; an agent without a track where
        its last track ended, less certain as time passes. An agent's current track is not compared
        with where that same track was: that would only confirm whatever identity it has."""
        s = self.settings
        times = (np.arange(first, first + count) + 0.5) * BIN_NS
        expected = np.full((len(self.agents), count, 2), np.nan)
        sd = np.full((len(self.agents), count), np.nan)
        clip = np.full((len(self.agents), 1), s.clip)
        holding = {t.agent for t in self.tracks.values() if t.agent >= 0}
        for i, cues in enumerate(self.agents):
            pose = self.pose_of(cues.agent_id, int(times[-1])) if self.pose_of else None
            if pose is not None:
                expected[i] = pose[0]
                sd[i] = np.hypot(pose[1], s.position_sd_m)
                clip[i] = s.position_clip
            elif i not in holding and np.isfinite(self.seen_xy[i, 0]):
                expected[i] = self.seen_xy[i]
                age_s = np.maximum(times - self.seen_ns[i], 0) * 1e-9
                sd[i] = np.hypot(s.position_sd_m + s.walk_mps * age_s, camera_sd_m)
        if not np.isfinite(sd).any():
            return None
        dx = t_x[:, None, :] - expected[None, :, :, 0]
        dy = t_y[:, None, :] - expected[None, :, :, 1]
        return np.minimum((dx * dx + dy * dy) / (2 * sd[None] ** 2), clip[None])

    def _assign(self, camera: str, keys: list[tuple[str, int]], tracks: list[Track], evidence: np.ndarray,
                now_ns: int) -> list[Any]:
        s = self.settings
        n_tracks, n_agents = evidence.shape
        cost = evidence.copy()
        for row, track in enumerate(tracks):
            if track.agent >= 0:
                cost[row, track.agent] -= s.switch_margin
        held = {t.agent for k, t in self.tracks.items() if k[0] != camera and t.agent >= 0}
        for i in held:  # an agent another camera holds is not available here
            cost[:, i] = BIG
        parts = components(cost, s.nobody_cost)
        self.counters.solves += 1
        chosen: dict[int, int] = {}
        where: dict[int, tuple] = {}  # row -> its part's (matrix, best cost, row in it, agent -> column, solution)
        for rows_in, cols_in in parts:
            matrix = padded(cost[np.ix_(rows_in, cols_in)], s.nobody_cost)
            self.counters.max_assignment_size = max(self.counters.max_assignment_size, len(matrix))
            rows, cols = linear_sum_assignment(matrix)
            best = float(matrix[rows, cols].sum())
            column_of = {int(c): k for k, c in enumerate(cols_in)}
            for r, c in zip(rows, cols):
                if r < len(rows_in) and c < len(cols_in):
                    chosen[int(rows_in[r])] = int(cols_in[c])
            for k, r in enumerate(rows_in):
                where[int(r)] = (matrix, best, k, column_of, cols)
        final: dict[int, int] = {}
        solves = 0
        for row, track in enumerate(tracks):
            agent = chosen.get(row, -1)
            if agent >= 0 and agent != track.agent:
                # a new identity must beat every assignment without it by claim_margin: two people
                # standing still look alike, and no identity is better than a guess
                matrix, best, k, column_of, solution = where[row]
                if swap_bound(matrix, solution, k, column_of[agent]) < s.claim_margin:
                    agent = -1  # one exchange with another pair already costs less than the margin: no solve
                    self.counters.screened += 1
                else:
                    solves += 1
                    if solves > s.max_claims or exclusion_margin(matrix, best, k, column_of[agent]) < s.claim_margin:
                        agent = -1
                    self.counters.solves += solves <= s.max_claims
            final[row] = agent
        # an agent that moves to another track says so once; "no track" only for one left without any
        taken = set(final.values())
        out = [self._identity(track.agent, camera, 0, 0.0, now_ns) for row, track in enumerate(tracks)
               if track.agent >= 0 and final[row] != track.agent and track.agent not in taken]
        for row, (key, track) in enumerate(zip(keys, tracks)):
            agent = final[row]
            if agent == track.agent:
                continue
            track.agent = agent
            track.held_since_ns = now_ns
            self.lost.pop(agent, None)
            self.rules.unshare(agent)
            self.counters.identity_changes += 1
            if agent >= 0:
                out.append(self._identity(agent, camera, key[1], self._margin(evidence, row, agent), now_ns))
        return out

    def _margin(self, evidence: np.ndarray, row: int, agent: int) -> float:
        others = np.concatenate([np.delete(evidence[:, agent], row), np.delete(evidence[row], agent),
                                 [2 * self.settings.nobody_cost]])
        return float(max(others.min() - evidence[row, agent], 0.0))

    def _fixes(self, camera: str, tracks: list[Track], evidence: np.ndarray, now_ns: int,
               camera_sd_m: float, scored_ns: int) -> list[Any]:
        """A fix is the track's position at the end of the bins its evidence has scored (`scored_ns`), not its
        newest: a tracker's swap in the last delay_s would otherwise send a fix from someone else."""
        s = self.settings
        out = []
        for row, track in enumerate(tracks):
            i = track.agent
            if i < 0:
                continue
            self.seen_xy[i], self.seen_ns[i] = track.cues.latest_xy, track.cues.last_ns
            if evidence[row, i] > s.fix_cost or now_ns - track.held_since_ns < s.fix_after_s * 1e9:
                continue
            at = track.cues.at(scored_ns)
            if at is None or at[0] - track.last_fix_ns < s.fix_every_s * 1e9:
                continue
            fix_ns, xy = at
            track.last_fix_ns = fix_ns
            variance = max(camera_sd_m, 0.05) ** 2
            out.append(messages.new("PositionFix", timestamp_ns=int(fix_ns), agent_id=self.agents[i].agent_id,
                                    kind=CorrectionKind.VIDEO, x_m=float(xy[0]), y_m=float(xy[1]),
                                    covariance=[variance, 0.0, 0.0, variance], source_id=f"{camera}:{track.cues.track_id}"))
            self.counters.fixes += 1
        return out

    def _learn_speed(self, tracks: list[Track], evidence: np.ndarray, first: int, count: int) -> None:
        """Refit the activity-to-speed line on pedestrians whose identity is clear (never on a doubtful pair)."""
        for row, track in enumerate(tracks):
            i = track.agent
            if i < 0 or self.kinds[i] is not AgentKind.PEDESTRIAN:
                continue
            if evidence[row, i] > self.settings.fix_cost:
                continue
            self.speed_model.learn(self.agents[i].ring.window("activity", first, count), track.cues.speed(first, count))

    def _search_lag(self, camera: str, tracks: list[Track], end: int) -> None:
        """Shift the camera's bins against the agents' to where the identified pairs' turn rates agree best,
        within max_lag_s of the configured lag_prior_s (an absolute bound: successive moves never add up
        beyond it)."""
        s = self.settings
        # chairs only: pedestrians' turn rates do not separate pairs (docs/identity.md, the room)
        pairs = [(t, t.agent) for t in tracks if t.agent >= 0 and not self.is_pedestrian[t.agent]]
        if not pairs:
            return
        span = int(4.0 / BIN_S)
        prior = int(round(s.lag_prior_s / BIN_S))
        max_lag = int(round(s.max_lag_s / BIN_S))
        current = self.lag_bins.get(camera, prior)
        lags = np.arange(prior - max_lag, prior + max_lag + 1) - current  # moves that stay within the bound
        reach = int(np.abs(lags).max())
        scores = np.zeros(len(lags))
        counts = np.zeros(len(lags))
        # an agent's bins end - span - TRACK_DELAY_BINS - lag ...: one read covers every lag and the turn
        lo = end - span - TRACK_DELAY_BINS - reach - TURN_BINS
        width = span + 2 * reach + TURN_BINS
        take = (reach - lags)[:, None] + np.arange(span)[None, :] + TURN_BINS  # (lags, span) into the read
        for track, i in pairs:
            t_yaw = track.cues.turn_rate(end - span, span)
            ring = self.agents[i].ring
            name = "heading_dr" if np.isfinite(ring.window("heading_dr", end - span, span)).any() else "heading"
            heading = ring.window(name, lo, width)
            a_yaw = (heading[take] - heading[take - TURN_BINS]) / (TURN_BINS * BIN_S)  # as turn_rate, per lag
            d = (t_yaw[None, :] - a_yaw) / s.yaw_sd_dps
            ok = np.isfinite(d)
            scores += np.where(ok, np.minimum(d * d, s.clip), 0.0).sum(axis=1)
            counts += ok.sum(axis=1)
        if counts.min() < 20:
            return
        mean = scores / counts
        k = int(np.argmin(mean))
        stay = int(np.flatnonzero(lags == 0)[0])
        if mean[k] < mean[stay] - 0.2:  # move only when clearly better than no change
            self.lag_bins[camera] = current + int(lags[k])
            self.counters.lag_bins = self.lag_bins[camera]

    def _drop(self, key: tuple[str, int], now_ns: int) -> list[Any]:
        """Forget a track the camera lost; its agent, if any, now has no track."""
        track = self.tracks.pop(key)
        if track.agent >= 0:
            self.lost[track.agent] = Lost.of(key[0], track)
        out = [self._identity(i, key[0], 0, 0.0, now_ns) for i in track.sharers]
        if track.agent >= 0:
            out.append(self._identity(track.agent, key[0], 0, 0.0, now_ns))
        return out

    def _identity(self, agent: int, camera: str, track_id: int, score: float, now_ns: int) -> Any:
        return identity_message(self.agents[agent].agent_id, camera, track_id, score, now_ns)

    def assignment(self) -> dict[str, tuple[str, int]]:
        """agent id -> (camera, track id) for every agent that has a track now."""
        return {self.agents[t.agent].agent_id: key for key, t in self.tracks.items() if t.agent >= 0}

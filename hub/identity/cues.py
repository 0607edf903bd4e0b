"""Motion cues of agents (from their IMU and dead reckoning) and of camera tracks, on one time grid.

Both sides are reduced to the same few signals every BIN_S of venue time, so a track and an agent
can be compared bin by bin:
- `speed` (m/s): a track's from its positions; a chair's from its edge's dead-reckoned poses; a
  pedestrian's predicted from the vertical activity of the waist (the camera-identity paper's
  regression of vertical acceleration on speed, inverted) by `SpeedModel`.
- `yaw` (deg/s): turn rate about the vertical over TURN_BINS: the gyro projected on the gravity
  direction, integrated to a heading; a track's from the rotation of its velocity between fits
  (only meaningful while it moves). A track's cues describe its last TRACK_FIT_S, so an agent's
  instantaneous cues are compared TRACK_DELAY_BINS earlier.
- `moving` (0/1): speed above MOVING_MPS; for a pedestrian, activity above its threshold.
- `height` (m): a track's reported head height, where the tracker gives one; `StatureProfile`
  learns which heights each agent's motion matches.
- `vertical` (g): an agent's mean vertical acceleration (gravity removed) over the bin; against a
  track's heights it shows whether they step together (hub/identity/gait.py).

Everything is stored in fixed rings of CAPACITY bins (the comparison window plus margin), so
memory is constant per agent and per live track.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.signal import lfilter

BIN_S = 0.1
BIN_NS = int(BIN_S * 1e9)
CAPACITY = 128  # bins kept: 12.8 s, more than the window plus the lag search
MOVING_MPS = 0.3
GRAVITY_TAU_S = 1.0  # low-pass that tracks the gravity direction through turns and tilts
ACTIVITY_TAU_S = 0.5  # RMS of the vertical acceleration over about one stride
TRACK_FIT_S = 0.5  # a track's velocity: line fit over its last half second of positions
TRACK_DELAY_BINS = 2  # ... so it describes the motion about a quarter second ago
TURN_BINS = 5  # turn rates over half a second: the pelvis' rotation at the step frequency averages out
NO_BIN = -(2**62)
WALKING_G = 0.08  # the waist's vertical activity (RMS) above this is walking: upright
UPRIGHT_S = 1.0  # walking needed before the upright direction is known
UPRIGHT_FORGET = 0.9999  # per sample: the upright direction is remembered for a few minutes


class Ring:
    """Per-bin values of several named signals; the bin number is the key, old bins are overwritten."""

    def __init__(self, names: tuple[str, ...], capacity: int = CAPACITY):
        self.capacity = capacity
        self.bins = np.full(capacity, NO_BIN, dtype=np.int64)
        self.row = {name: k for k, name in enumerate(names)}
        self.data = np.full((len(names), capacity), np.nan)  # one row per name

    def put(self, bin_number: int, **values: float) -> None:
        slot = bin_number % self.capacity
        if self.bins[slot] != bin_number:
            self.bins[slot] = bin_number
            self.data[:, slot] = np.nan  # what an older bin left there is not this bin's
        for name, value in values.items():
            self.data[self.row[name], slot] = value

    def block(self, first_bin: int, count: int) -> np.ndarray:
        """Every signal at bins first_bin .. first_bin + count - 1, (names, count); NaN where a bin is missing."""
        wanted = np.arange(first_bin, first_bin + count)
        slots = wanted % self.capacity
        return np.where(self.bins[slots] == wanted, self.data[:, slots], np.nan)

    def window(self, name: str, first_bin: int, count: int) -> np.ndarray:
        """Values of bins first_bin .. first_bin + count - 1; NaN where a bin is missing."""
        wanted = np.arange(first_bin, first_bin + count)
        slots = wanted % self.capacity
        return np.where(self.bins[slots] == wanted, self.data[self.row[name], slots], np.nan)


def _alpha(tau_s: float, dt_s: float) -> float:
    return float(min(1.0, dt_s / tau_s))


@dataclass
class SpeedModel:
    """Walking speed from the waist's vertical activity (RMS, g): speed = slope * (activity - floor).

    The paper fits vertical acceleration on speed beforehand on labelled data (r = 0.91); here the
    line starts from a prior and is refitted online from the pairs the hub has identified, so a
    venue's people and sensors calibrate it without labels. The prior is deliberately loose.
    """

    slope_mps_per_g: float = 6.0
    floor_g: float = 0.03
    prior_weight: float = 50.0  # the prior counts as this many bins of evidence
    forget_per_bin: float = 0.999
    _sums: np.ndarray = field(init=False)  # n, sa, ss, saa, sas: the prior, then forgetting sums

    def __post_init__(self) -> None:
        self._sums = self._prior()

    def _prior(self) -> np.ndarray:
        activity = np.array([self.floor_g, self.floor_g + 0.1])
        speed = self.slope_mps_per_g * (activity - self.floor_g)
        w = self.prior_weight / 2
        return np.array([2 * w, w * activity.sum(), w * speed.sum(), w * (activity**2).sum(), w * (activity * speed).sum()])

    def predict(self, activity_g: np.ndarray) -> np.ndarray:
        n, sa, ss, saa, sas = self._sums
        var = saa - sa * sa / n
        slope = (sas - sa * ss / n) / var if var > 1e-12 else self.slope_mps_per_g
        slope = max(slope, 0.5)  # activity must not predict less speed as it grows
        intercept = (ss - slope * sa) / n
        return np.clip(intercept + slope * activity_g, 0.0, None)

    def learn(self, activity_g: np.ndarray, speed_mps: np.ndarray) -> None:
        ok = np.isfinite(activity_g) & np.isfinite(speed_mps)
        if not ok.any():
            return
        a, s = activity_g[ok], speed_mps[ok]
        keep = self.forget_per_bin ** len(a)
        self._sums = self._sums * keep + np.array([len(a), a.sum(), s.sum(), (a * a).sum(), (a * s).sum()])


class StatureProfile:
    """How well each agent's motion has matched tracks of each reported head height, over the session.

    A camera that reports the head top's height sees each person at their own stature on every track
    of theirs while they walk (seated, the head is ~0.4 m lower). Every scored bin of every live track
    that moves (held or not: no feedback from the assignment) adds the agent's motion cost (speed,
    moving, turn rate) to the cell of the track's height; over
    minutes the agent's own stature collects the lowest mean cost, a bystander's or another wearer's
    a higher one. The cue is that mean cost, smoothed over heights, above its lowest value: ~0 for
    tracks at the agent's stature. Unsupervised and never from truth."""

    LOW_M, STEP_M, CELLS = 0.5, 0.01, 200  # head heights 0.5-2.5 m in 1 cm cells

    def __init__(self, agents: int, smooth_m: float = 0.02, prior_bins: float = 200.0):
        self.sums = np.zeros((agents, self.CELLS))
        self.counts = np.zeros((agents, self.CELLS))
        half = int(3 * smooth_m / self.STEP_M)
        kernel = np.exp(-0.5 * (np.arange(-half, half + 1) * self.STEP_M / smooth_m) ** 2)
        self.kernel = kernel / kernel.sum()
        self.prior_bins = prior_bins  # each cell starts as this many bins at the agent's mean over all heights
        self._profile: np.ndarray | None = None

    def cells(self, height_m: np.ndarray) -> np.ndarray:
        return np.clip(np.round((height_m - self.LOW_M) / self.STEP_M), 0, self.CELLS - 1).astype(np.int64)

    def learn(self, height_m: np.ndarray, motion: np.ndarray, upright: np.ndarray) -> None:
        """height_m (tracks, bins); motion (tracks, agents, bins) excess cost, NaN where not compared; upright
        (tracks, bins): the track walks, so its head is at the person's stature (seated, it is ~0.4 m lower)."""
        ok = (np.isfinite(height_m) & upright)[:, None, :] & np.isfinite(motion)
        if not ok.any():
            return
        t, a, k = np.nonzero(ok)
        cell = self.cells(height_m[t, k])
        np.add.at(self.sums, (a, cell), motion[t, a, k])
        np.add.at(self.counts, (a, cell), 1.0)
        self._profile = None

    def profile(self) -> np.ndarray:
        """(agents, cells): smoothed mean motion cost above the agent's lowest; NaN where too little is known."""
        if self._profile is None:
            smooth = lambda m: np.apply_along_axis(lambda r: np.convolve(r, self.kernel, mode="same"), 1, m)
            total = self.counts.sum(axis=1, keepdims=True)
            overall = self.sums.sum(axis=1, keepdims=True) / np.maximum(total, 1.0)
            sums, counts = smooth(self.sums), smooth(self.counts)
            mean = (sums + overall * self.prior_bins) / (counts + self.prior_bins)  # thin cells stay near the mean
            lowest = mean.min(axis=1, keepdims=True)
            self._profile = np.where(total >= self.prior_bins, mean - lowest, np.nan)
        return self._profile

    def cost(self, height_m: np.ndarray) -> np.ndarray:
        """(tracks, agents, bins) for track heights (tracks, bins); NaN where the height or the profile is unknown."""
        profile = self.profile()
        cell = self.cells(np.nan_to_num(height_m, nan=0.0))
        out = profile[:, cell].transpose(1, 0, 2)
        return np.where(np.isfinite(height_m)[:, None, :], out, np.nan)


class AgentCues:
    """One agent's cues from its body IMU (pedestrian waist, chair seat) and, for chairs, its edge poses."""

    NAMES = ("activity", "heading", "speed_dr", "heading_dr", "vx_dr", "vy_dr", "tilt", "vertical")

    def __init__(self, agent_id: str, sensor_id: str, rate_hz: float):
        self.agent_id = agent_id
        self.sensor_id = sensor_id
        dt = 1.0 / rate_hz
        self.filters = {name: (np.array([a]), np.array([1.0, a - 1.0])) for name, a in
                        (("gravity", _alpha(GRAVITY_TAU_S, dt)), ("activity", _alpha(ACTIVITY_TAU_S, dt)))}
        self.dt_s = dt
        self.heading_deg = 0.0
        self.state: dict[str, np.ndarray] | None = None
        self.ring = Ring(self.NAMES)
        self.last_pose: tuple[int, float, float, float] | None = None
        self.correction_sequence = 0
        self.upright = np.zeros(3)  # forgetting sum of the gravity direction (sensor frame) while walking
        self.newest_imu_bin = NO_BIN  # the newest bins its data has reached (a bin is complete once a later one is)
        self.newest_pose_bin = NO_BIN
        self.vertical_carry = (NO_BIN, 0.0, 0)  # the last bin's (number, sum, samples) so far: a batch may end inside it

    def complete_bin(self) -> int:
        """The newest bin whose cues are all in: both its IMU and, once poses come, its poses have passed it."""
        newest = self.newest_imu_bin if self.newest_pose_bin == NO_BIN else min(self.newest_imu_bin, self.newest_pose_bin)
        return newest - 1

    def push_imu(self, time_ns: np.ndarray, accel_g: np.ndarray, gyro_dps: np.ndarray) -> None:
        """Samples in venue time, in order; bins that end inside the batch get their values."""
        if len(time_ns) == 0:
            return
        if self.state is None:
            settled = np.asarray(accel_g[0]) * (1.0 - self.filters["gravity"][0][0])  # as if it had always read this
            self.state = {"gravity": settled.reshape(1, 3), "activity": np.zeros(1)}
        b, a = self.filters["gravity"]
        gravity, zi = lfilter(b, a, accel_g, axis=0, zi=self.state["gravity"])
        self.state["gravity"] = zi
        norm = np.linalg.norm(gravity, axis=1)
        unit = gravity / np.maximum(norm, 1e-6)[:, None]
        vertical = np.einsum("ij,ij->i", accel_g, unit) - norm
        b, a = self.filters["activity"]
        power, self.state["activity"] = lfilter(b, a, vertical * vertical, zi=self.state["activity"])
        heading = self.heading_deg + np.cumsum(np.einsum("ij,ij->i", gyro_dps, unit)) * self.dt_s
        self.heading_deg = float(heading[-1])
        tilt = self._tilt(unit, np.sqrt(np.maximum(power, 0.0)))
        bins = time_ns // BIN_NS
        self.newest_imu_bin = max(self.newest_imu_bin, int(bins[-1]))
        ends = np.flatnonzero(np.diff(np.append(bins, bins[-1] + 1)) != 0)  # last sample of each bin
        starts = np.concatenate([[0], ends[:-1] + 1])
        sums, counts = np.add.reduceat(vertical, starts), np.diff(np.append(starts, len(bins)))
        carry_bin, carry_sum, carry_count = self.vertical_carry
        if int(bins[0]) == carry_bin:
            sums[0] += carry_sum
            counts[0] += carry_count
        self.vertical_carry = (int(bins[-1]), float(sums[-1]), int(counts[-1]))
        for k, i in enumerate(ends):
            self.ring.put(int(bins[i]), activity=float(np.sqrt(max(power[i], 0.0))), heading=float(heading[i]),
                          tilt=float(tilt[i]), vertical=float(sums[k] / counts[k]))

    def _tilt(self, unit: np.ndarray, activity_g: np.ndarray) -> np.ndarray:
        """Degrees between each sample's gravity direction and the one while walking (learnt here, NaN until
        UPRIGHT_S of walking): seated, the pelvis tilts back ~10-20 deg and the belt sensor with it."""
        walking = activity_g > WALKING_G
        keep = UPRIGHT_FORGET ** len(unit)
        self.upright = self.upright * keep + unit[walking].sum(axis=0)
        norm = float(np.linalg.norm(self.upright))
        if norm < UPRIGHT_S / self.dt_s:  # the sum of unit vectors: about the walking samples seen
            return np.full(len(unit), np.nan)
        return np.degrees(np.arccos(np.clip(unit @ (self.upright / norm), -1.0, 1.0)))

    def push_pose(self, time_ns: int, x_m: float, y_m: float, heading_rad: float, correction_sequence: int = 0) -> None:
        """A dead-reckoned pose (venue time): speed since the previous one, and the heading (unwrapped).

        A pose that holds a new hub correction jumped there: it starts afresh rather than read the
        jump as speed."""
        self.newest_pose_bin = max(self.newest_pose_bin, int(time_ns // BIN_NS))
        if correction_sequence != self.correction_sequence:
            self.correction_sequence = correction_sequence
            self.last_pose = None
        if self.last_pose is not None:
            t0, x0, y0, h0 = self.last_pose
            dt = (time_ns - t0) * 1e-9
            if dt <= 0:
                return
            heading_rad = h0 + (heading_rad - h0 + np.pi) % (2 * np.pi) - np.pi
            if dt < 1.0:
                vx, vy = (x_m - x0) / dt, (y_m - y0) / dt
                self.ring.put(time_ns // BIN_NS, speed_dr=float(np.hypot(vx, vy)), heading_dr=float(np.degrees(heading_rad)),
                              vx_dr=float(vx), vy_dr=float(vy))
        self.last_pose = (time_ns, x_m, y_m, heading_rad)


def turn_rate(heading_deg_window: Callable[[int, int], np.ndarray], first_bin: int, count: int) -> np.ndarray:
    """Turn rate (deg/s) at bins first..first+count-1 from a heading series, over TURN_BINS."""
    now = heading_deg_window(first_bin, count)
    before = heading_deg_window(first_bin - TURN_BINS, count)
    return (now - before) / (TURN_BINS * BIN_S)


class TrackCues:
    """One camera track: its latest positions and, per bin, position and velocity (line fit)."""

    NAMES = ("x", "y", "vx", "vy", "height")

    def __init__(self, track_id: int, fps_hint: float = 25.0):
        self.track_id = track_id
        size = int(TRACK_FIT_S * fps_hint * 2) + 4
        self.times = np.zeros(size)
        self.xy = np.zeros((size, 2))
        self.count = 0
        self.ring = Ring(self.NAMES)
        self.last_ns = 0
        self.latest_height = float("nan")

    @property
    def latest_xy(self) -> np.ndarray:
        return self.xy[(self.count - 1) % len(self.times)]

    def push(self, time_ns: int, x_m: float, y_m: float, height_m: float = float("nan")) -> None:
        if self.count and time_ns <= self.last_ns:
            return  # a repeated or out-of-order frame
        self.last_ns = time_ns
        self.latest_height = height_m
        slot = self.count % len(self.times)
        self.times[slot], self.xy[slot] = time_ns * 1e-9, (x_m, y_m)
        self.count += 1
        n = min(self.count, len(self.times))
        t, xy = self.times[:n], self.xy[:n]
        recent = t >= time_ns * 1e-9 - TRACK_FIT_S
        velocity = (np.nan, np.nan)
        if recent.sum() >= 3:
            tc = t[recent] - t[recent].mean()
            denominator = float(tc @ tc)
            if denominator > 0:
                velocity = tc @ (xy[recent] - xy[recent].mean(axis=0)) / denominator
        self.ring.put(int(time_ns // BIN_NS), x=x_m, y=y_m, vx=float(velocity[0]), vy=float(velocity[1]),
                      height=height_m)

    def at(self, time_ns: int) -> tuple[int, np.ndarray] | None:
        """(time, position) of the newest frame not after `time_ns` among those kept (about 1 s), or None."""
        n = min(self.count, len(self.times))
        if n == 0:
            return None
        stamps = np.round(self.times[:n] * 1e9).astype(np.int64)
        kept = np.flatnonzero(stamps <= time_ns)
        if not len(kept):
            return None
        k = kept[np.argmax(stamps[kept])]
        return int(stamps[k]), self.xy[k].copy()

    def height(self, seconds: float = 1.0) -> float:
        """Mean reported head height over the last `seconds` (NaN without heights)."""
        bins = max(int(round(seconds / BIN_S)), 1)
        values = self.ring.window("height", int(self.last_ns // BIN_NS) - bins + 1, bins)
        return float(np.mean(values[np.isfinite(values)])) if np.isfinite(values).any() else float("nan")

    def speed(self, first_bin: int, count: int) -> np.ndarray:
        return np.hypot(self.ring.window("vx", first_bin, count), self.ring.window("vy", first_bin, count))

    def turn_rate(self, first_bin: int, count: int) -> np.ndarray:
        """deg/s over TURN_BINS; NaN unless the track moves at both ends (a still track's heading is noise)."""
        vx, vy = self.ring.window("vx", first_bin, count), self.ring.window("vy", first_bin, count)
        px, py = self.ring.window("vx", first_bin - TURN_BINS, count), self.ring.window("vy", first_bin - TURN_BINS, count)
        angle = np.degrees(np.arctan2(px * vy - py * vx, px * vx + py * vy))
        moving = (np.hypot(vx, vy) > MOVING_MPS) & (np.hypot(px, py) > MOVING_MPS)
        return np.where(moving, angle / (TURN_BINS * BIN_S), np.nan)


def track_hop_cues(tracks: list[TrackCues], first_bin: int, count: int) -> dict[str, np.ndarray]:
    """speed, yaw (as TrackCues.speed / .turn_rate), x and y of several tracks at once, each (tracks, count):
    one block read per track instead of one per signal and shift."""
    blocks = np.stack([t.ring.block(first_bin - TURN_BINS, TURN_BINS + count) for t in tracks])
    now, before = blocks[:, :, TURN_BINS:], blocks[:, :, :count]
    vx, vy, px, py = now[:, 2], now[:, 3], before[:, 2], before[:, 3]
    speed = np.hypot(vx, vy)
    angle = np.degrees(np.arctan2(px * vy - py * vx, px * vx + py * vy))
    with np.errstate(invalid="ignore"):
        moving = (speed > MOVING_MPS) & (np.hypot(px, py) > MOVING_MPS)
    return {"speed": speed, "yaw": np.where(moving, angle / (TURN_BINS * BIN_S), np.nan), "x": now[:, 0], "y": now[:, 1],
            "height": now[:, 4], "vx": vx, "vy": vy}


def agent_hop_blocks(agents: list[AgentCues], first_bin: int, count: int, delay_bins: int) -> dict[str, np.ndarray]:
    """The agents' signals for track bins first..first+count-1, each (agents, count): `activity` at those
    bins, and `tilt` (deg from upright, the waist); `speed_dr`, `vx_dr`, `vy_dr` (DR velocity), `yaw_dr` (DR heading) and `yaw` (gyro heading)
    delay_bins earlier (turn rates over TURN_BINS, as turn_rate)."""
    start = first_bin - delay_bins
    blocks = np.stack([a.ring.block(start - TURN_BINS, TURN_BINS + delay_bins + count) for a in agents])
    now = blocks[:, :, TURN_BINS:TURN_BINS + count]
    before = blocks[:, :, :count]
    rate = 1.0 / (TURN_BINS * BIN_S)
    return {"activity": blocks[:, 0, TURN_BINS + delay_bins:], "tilt": blocks[:, 6, TURN_BINS + delay_bins:],
            "speed_dr": now[:, 2], "vx_dr": now[:, 4],
            "vy_dr": now[:, 5], "yaw_dr": (now[:, 3] - before[:, 3]) * rate, "yaw": (now[:, 1] - before[:, 1]) * rate}

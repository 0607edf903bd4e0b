"""What the chairs' hub keeps of one agent: its recent live poses, its smoother, its pending
corrections and beacon passes (hub/chair/hub.py uses it; the identity engine asks it where a chair was)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from hub.chair.history import PoseHistory
from hub.chair.smoother import FixedLagSmoother

CORRECTIONS = ("beacon", "collision", "fix", "camera")  # fix: an operator's; camera: identified tracks
HISTORY = 1024  # poses kept per agent for looking back to a measured time (20 s at 50 Hz)
GAP_S = 0.2  # poses further apart than this are a gap (the edge publishes at 50 Hz)
STALE_MPS = 2.0  # a chair's typical speed (a 10-chair game: 150-200 m in 120 s): how a pose's doubt grows with its age


@dataclass
class Pass:
    peak_rssi: float
    peak_ns: int
    last_ns: int


@dataclass
class AgentView:
    """What the hub knows of one agent."""

    agent_id: str
    seat_id: str
    smoother: FixedLagSmoother
    history: PoseHistory = field(default_factory=lambda: PoseHistory(HISTORY))  # live poses
    latest_ns: int | None = None  # venue time of the newest pose
    arrival_ns: int = 0  # hub clock when its last message came
    # The newest edge pose's 3 x 3 covariance, row-major, as the message held it: a correction reads
    # it (as an array), every pose replaces it (a list: an array made per pose cost a microsecond).
    edge_covariance: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0])
    pending: list[tuple[int, np.ndarray]] = field(default_factory=list)  # (sequence, expected shift)
    sequence: int = 0  # last Correction sent
    acknowledged: int = 0
    passes: dict[str, Pass] = field(default_factory=dict)  # open, per beacon
    # No open pass has a last sighting before this (0: none checked yet): while the newest pose is
    # within the pass end of it, none can have ended, and the passes are not looked through per pose.
    passes_last_ns: int = 0
    ended: deque = field(default_factory=lambda: deque(maxlen=16))  # (beacon, pass) awaiting poses past the peak
    fixes: deque = field(default_factory=lambda: deque(maxlen=16))  # PositionFix awaiting poses past its time
    applied: dict[str, int] = field(default_factory=lambda: {name: 0 for name in CORRECTIONS})
    poses: int = 0
    # The position covariance the edge is missing (hub/chair/hub.py), 2 x 2 row-major: floats, as it
    # grows with every pose; `extra` is it as an array.
    extra_m2: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])
    last_edge: tuple[int, float, float, int] | None = None  # (venue time, x, y, correction sequence) as sent
    refused_source: str = ""  # the video source whose fixes were refused in a row, most recent last
    refused: list = field(default_factory=list)  # ... as [(time, offset)]
    live_key: str = ""  # where its live and refined poses go (ChairHub.key_for)
    refined_key: str = ""
    pose_fields: dict = field(default_factory=dict)  # per track, an EstimatedPose holding what every one of its poses shares

    @property
    def extra(self) -> np.ndarray:
        return np.array(self.extra_m2).reshape(2, 2)

    @extra.setter
    def extra(self, matrix: np.ndarray) -> None:
        self.extra_m2 = np.asarray(matrix, dtype=float).ravel().tolist()

    def pose_at(self, time_ns: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Live position and its covariance at `time_ns` (the last pose not after it; the first if none)."""
        if not self.history:
            return None
        return self.history.position(self.history.last_at(time_ns) or 0)

    def heading_at(self, time_ns: int) -> float | None:
        """Live heading (rad) at `time_ns`, as pose_at picks the pose."""
        return self.history.heading(self.history.last_at(time_ns) or 0) if self.history else None

    def pose_bridged(self, time_ns: int) -> tuple[np.ndarray, np.ndarray] | None:
        """As pose_at, but inside a gap of more than GAP_S between two poses (the link stalled) the position
        is interpolated between them and its covariance grows with the gap (the chair may have turned):
        a fix that falls in the gap is not compared with where the chair was before it."""
        after = self.history.last_at(time_ns)
        if after is None or after + 1 >= len(self.history):
            return self.pose_at(time_ns)
        t0, t1 = self.history.time_at(after), self.history.time_at(after + 1)
        (xy0, cov0), (xy1, cov1) = self.history.position(after), self.history.position(after + 1)
        if (t1 - t0) * 1e-9 <= GAP_S:
            return xy0, cov0
        w = (time_ns - t0) / (t1 - t0)
        spread = STALE_MPS * min(time_ns - t0, t1 - time_ns) * 1e-9
        return (1 - w) * xy0 + w * xy1, np.maximum(cov0, cov1) + spread**2 * np.eye(2)

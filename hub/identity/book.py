"""The identity engine's records (hub/identity/engine.py, hub/identity/rules.py): a camera track it follows
(`Track`), where an agent's track broke off (`Lost`), and the TrackIdentity message it sends about them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hub.identity.cues import BIN_NS, TrackCues
from protocol import messages

METHOD = "reckon"  # TrackIdentity.method of the engine's messages (the paper's baseline is another method)


@dataclass
class Track:
    """One live camera track: its cues, every agent's evidence on it, and who holds it."""
    cues: TrackCues
    cost_sum: np.ndarray  # (2, agents): forgetting sums of bin costs, slow (forget_per_s) and fast (fast_forget_per_s)
    cost_count: np.ndarray
    agent: int = -1
    held_since_ns: int = 0  # since when its identity is undisputed: held, and no encounter since
    last_fix_ns: int = 0
    encounter: set[int] = field(default_factory=set)  # agents this track may show since it met other tracks
    close_bin: int = -(2**62)  # the last bin in which it was within encounter_m of another track
    since_bin: np.ndarray | None = None  # per agent, the first bin that counts (bins before it showed someone else)
    sharers: set[int] = field(default_factory=set)  # agents whose track merged into this one (it shows them too)
    born_ns: int = 0
    course: np.ndarray | None = None  # (cos, sin) x agents: forgetting sums of the angle track - agent direction


@dataclass
class Lost:
    """Where an agent's track broke off, and its evidence then: what a continuation inherits."""
    camera: str
    last_ns: int
    xy: np.ndarray
    velocity: np.ndarray  # m/s, NaN if the track was not moving fast enough to have one
    cost_sum: np.ndarray
    cost_count: np.ndarray
    height_m: float = float("nan")  # the old track's reported head height (NaN: the tracker reports none)
    course: np.ndarray | None = None

    @classmethod
    def of(cls, camera: str, track: Track) -> Lost:
        last_bin = track.cues.last_ns // BIN_NS
        velocity = np.array([track.cues.ring.window(name, last_bin, 1)[0] for name in ("vx", "vy")])
        return cls(camera, track.cues.last_ns, track.cues.latest_xy.copy(), velocity, track.cost_sum.copy(),
                   track.cost_count.copy(), track.cues.height(), None if track.course is None else track.course.copy())


def identity_message(agent_id: str, camera: str, track_id: int, score: float, now_ns: int) -> Any:
    """TrackIdentity: `agent_id` is on `camera`'s track `track_id` from `now_ns` (track id 0: on none)."""
    return messages.new("TrackIdentity", timestamp_ns=int(now_ns), agent_id=agent_id,
                        camera_id=camera, track_id=int(track_id), method=METHOD, score=float(score))

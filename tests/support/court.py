"""The court view's scene (tests/reckon/test_court_view.py, test_foxglove.py): three chairs with a
seat sensor on a court with one beacon and one stand, and their edge poses at 50 Hz."""

from __future__ import annotations

from protocol import messages
from protocol.session import Session, session_from_dict

CHAIRS = ("c1", "c2", "c3")
T0_NS = 1_000_000_000_000
STEP_NS = 20_000_000  # 50 Hz edge poses


def session() -> Session:
    chairs = [{"id": agent, "sensors": [{"id": f"{agent}-seat", "mount": "seat"}]} for agent in CHAIRS]
    return session_from_dict({"venue": {"name": "court", "beacons": [{"id": "goal-a", "x_m": 1.2, "y_m": 7.5}],
                                        "stands": [{"id": "bench", "x_m": 14.0, "y_m": 0.5}]}, "agents": chairs})


def pose(agent: str, time_ns: int, x: float, y: float, track: int = messages.Track.LIVE, covariance=None):
    return messages.new("EstimatedPose", timestamp_ns=time_ns, agent_id=agent, x_m=x, y_m=y, heading_rad=0.0,
                        covariance=covariance or [0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.01], method="reckon", track=track)


def chair_xy(agent: str, step: int) -> tuple[float, float]:
    """The scene: c1 rolls past the goal-a beacon along y = 7.5, c2 and c3 cross the court."""
    t = step * STEP_NS / 1e9
    return {"c1": (1.6 + 1.0 * t, 7.5), "c2": (8.0 + 1.5 * t, 3.0 + 0.5 * t), "c3": (20.0 - 1.0 * t, 11.0)}[agent]

"""The wheelchair paper's correction rules (Hasegawa et al., sec. 3.3), as pure functions.

Reliability L (sec. 3.3.2): starts at 1, loses 0.001 every 0.1 s, never below 0.01, back to 1 at
every beacon or manual fix. Collisions pull both chairs onto one point (eq. 8) and share one
reliability (eq. 9). Beacon reception moves the stretch heard so its centroid sits under the goal
(eq. 6). Impacts of two chairs within 0.5 s are a collision; three or more chairs at once, none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FRAME_S = 0.1
RELIABILITY_DECAY_PER_FRAME = 0.001
RELIABILITY_FLOOR = 0.01
PAIRING_WINDOW_S = 0.5


def decay_reliability(reliability: float) -> float:
    """One 0.1 s step of reliability decay, floored at 0.01."""
    return max(reliability - RELIABILITY_DECAY_PER_FRAME, RELIABILITY_FLOOR)


def weighted_collision(p1: np.ndarray, p2: np.ndarray, l1: float, l2: float) -> tuple[np.ndarray, float]:
    """Both chairs move to P = P1 + (P2 - P1) L2 / (L1 + L2) (eq. 8); both get L of eq. 9."""
    weight = l2 / (l1 + l2)
    point = p1 + (p2 - p1) * weight  # eq. 8
    reliability = l1 + (l2 - l1) * weight  # eq. 9, as printed
    return point, reliability


def midpoint_collision(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """The paper's first variant: both chairs move to the midpoint."""
    return 0.5 * (p1 + p2)


def centroid_shift(position_sum: np.ndarray, count: int, goal: np.ndarray) -> np.ndarray:
    """Translation that puts the centroid of the reception stretch under the goal (eq. 6).

    Erratum: eq. 6 divides the sum of F+1 positions (indices 0..F) by F; the centroid divides
    by the number of positions, F+1 (`count` here).
    """
    return goal - position_sum / count


@dataclass(frozen=True)
class Collision:
    time_ns: int
    agent_a: str
    agent_b: str


def group_impacts(impacts: list[tuple[int, str]], window_s: float = PAIRING_WINDOW_S) -> list[tuple[int, list[str]]]:
    """Impacts grouped from the earliest one forward over `window_s`: (first time, sorted chairs)."""
    ordered = sorted(impacts)
    window_ns = int(window_s * 1e9)
    groups = []
    start = 0
    while start < len(ordered):
        end = start
        while end + 1 < len(ordered) and ordered[end + 1][0] - ordered[start][0] <= window_ns:
            end += 1
        groups.append((ordered[start][0], sorted({agent for _, agent in ordered[start:end + 1]})))
        start = end + 1
    return groups


def pair_impacts(impacts: list[tuple[int, str]], window_s: float = PAIRING_WINDOW_S) -> list[Collision]:
    """Collisions from (time_ns, agent) impacts of all chairs.

    A group (`group_impacts`) of exactly two chairs is a collision (at the first impact); a group
    of three or more chairs is ambiguous and skipped, as the paper does; a lone chair is none.
    """
    return [Collision(time_ns, agents[0], agents[1]) for time_ns, agents in group_impacts(impacts, window_s)
            if len(agents) == 2]

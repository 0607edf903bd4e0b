"""Scores: position error statistics and collision-detection precision/recall."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hub.chair.paper import PAIRING_WINDOW_S, Collision
from protocol.session_log import Contact


@dataclass(frozen=True)
class ErrorSummary:
    mean_error_m: float  # over time and agents
    max_team_mean_error_m: float  # the paper's figure: max over time of the team-mean error
    worst_agent_mean_error_m: float
    final_team_mean_error_m: float
    team_mean_error_at_120s_m: float  # the paper's "growth over 2 minutes"


def error_summary(error_m: np.ndarray, frame_s: np.ndarray) -> ErrorSummary:
    """`error_m` (agents, frames) distances to truth; `frame_s` seconds since the start."""
    team = np.nanmean(error_m, axis=0)
    at_120 = int(np.searchsorted(frame_s, 120.0)) if frame_s[-1] >= 120.0 else len(frame_s) - 1
    return ErrorSummary(
        mean_error_m=float(np.nanmean(error_m)),
        max_team_mean_error_m=float(np.nanmax(team)),
        worst_agent_mean_error_m=float(np.nanmax(np.nanmean(error_m, axis=1))),
        final_team_mean_error_m=float(team[-1]),
        team_mean_error_at_120s_m=float(team[min(at_120, len(team) - 1)]),
    )


def average_summaries(summaries: list[ErrorSummary]) -> ErrorSummary:
    fields = ErrorSummary.__dataclass_fields__
    return ErrorSummary(**{name: float(np.mean([getattr(s, name) for s in summaries])) for name in fields})


@dataclass(frozen=True)
class DetectionScore:
    threshold_g: float
    detected: int
    true_contacts: int
    matched: int

    @property
    def precision(self) -> float | None:
        return self.matched / self.detected if self.detected else None

    @property
    def recall(self) -> float | None:
        return self.matched / self.true_contacts if self.true_contacts else None


def score_collisions(threshold_g: float, detected: list[Collision], contacts: list[Contact],
                     window_s: float = PAIRING_WINDOW_S) -> DetectionScore:
    """A detected pair is right when the same two chairs truly touched within `window_s`."""
    unused = list(contacts)
    matched = 0
    window_ns = window_s * 1e9
    for collision in detected:
        pair = {collision.agent_a, collision.agent_b}
        for i, contact in enumerate(unused):
            if {contact.agent_id, contact.other_agent_id} == pair and abs(contact.time_ns - collision.time_ns) <= window_ns:
                matched += 1
                del unused[i]
                break
    return DetectionScore(threshold_g, len(detected), len(contacts), matched)

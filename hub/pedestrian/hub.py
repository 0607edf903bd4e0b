"""The hub's part for pedestrians: each one's dead-reckoned steps through a map matcher.

Per pedestrian agent with a map (the venue's floor plan, or corridors between its map points:
hub/pedestrian/walkable.py), every edge pose (EstimatedPose on `pose/edge`, per step) goes through the
matcher and leaves as the corrected `pose/live`. Without a map the edge pose is passed on as it is.

A stand reset is read from the pose itself: the edge counts its stand resets in
`correction_sequence`, so the first pose with a higher count restarts the matcher at that pose
(within a step of the stand, at the stand's accuracy) even if the StandScan message, which comes
on its own key, arrives later. A pose not later than the agent's last one is dropped and counted.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from hub.pedestrian.guard import GuardSettings, MapGuard
from hub.pedestrian.matching import DeadReckonedPose, MapMatcher
from hub.pedestrian.particles import ParticleMatcher, ParticleSettings
from hub.pedestrian.walkable import WalkableArea
from protocol import keys, messages
from protocol.session import AgentKind, Session, Venue

METHOD = "reckon"
REFINED_LAG_STEPS = 20  # pose/refined: about 10 s behind, long enough to have met the next wall or corner
SNAPS_KEPT = 1024  # a 4-minute walk over the paper's map makes about 20 snap decisions
# The filter's settings for phones (chosen on ILC site 1 F1 walks 1-5, checked on walks 6-10 and
# on simulated walks over the paper's corridors and an office floor: docs/pdr-estimator.md).
# Against ParticleSettings' defaults (which the synthetic tests pin):
# - the edge's heading is magnetometer-aided, so its offset is trusted more: narrower at a stand
#   (4 deg), a slower walk (0.15 deg/sqrt s), half the gyro-scale term, and an offset that decays
#   back to the edge's heading over 10 s (Ornstein-Uhlenbeck: what the walls taught is forgotten
#   as the magnetometer re-corrects the edge);
# - K is learned per user between stands, so the scale starts at 5 %, not 10 %;
# - walls stay hard: soft ones (a crossing costing a factor 0.3) did as well (p75 in m, ILC 10 walks
#   / simulated corridors / simulated office: hard 3.58 / 3.27 / 1.06, soft 3.60 / 2.57 / 1.27),
#   but a cloud that crosses a wall together keeps its weight, and the track must never be
#   matched through a wall.
PHONE_PARTICLES = ParticleSettings(
    reset_heading_sd_rad=math.radians(4.0), offset_walk_rad_per_sqrt_s=math.radians(0.15), turn_scale_sd=0.01,
    offset_reversion_s=10.0, initial_scale_sd=0.05, smoothing_lag_steps=REFINED_LAG_STEPS)
# The check that falls back to the edge's own track where the map contradicts it (hub/pedestrian/guard.py).
PHONE_GUARD = GuardSettings()


@dataclass
class PedestrianView:
    agent_id: str
    matcher: MapMatcher | None
    resets: int = 0
    last_time_ns: int = -1
    poses: int = 0
    out_of_order: int = 0
    matched: int = 0  # poses that went through the matcher
    fallback_poses: int = 0  # live poses that are the edge's own track: the map contradicted it
    snaps: deque = field(default_factory=lambda: deque(maxlen=SNAPS_KEPT))  # the paper's snap decisions, newest
    last: tuple[float, float] | None = None  # the last pose out (x m, y m)

    def describe(self) -> str:
        where = "none" if self.last is None else f"x {self.last[0]:.2f} m, y {self.last[1]:.2f} m"
        fallback = f", {self.fallback_poses} on the edge's track (map contradicted)" if self.fallback_poses else ""
        return (f"{self.poses} poses, {self.resets} stand resets, {self.out_of_order} out of order{fallback}; "
                f"last {where}")


def particle_matcher_factory(venue: Venue, area: WalkableArea | None = None) -> Callable[[str], MapMatcher] | None:
    """Our matcher for each pedestrian, or None when the venue has no map: the particle filter
    behind the map guard. The walkable area (`area`, else built from the venue) is shared; each
    agent's filter has its own seed (agent order)."""
    if not venue.floor_plan and not venue.map_points:
        return None
    if area is None:
        area = WalkableArea.from_venue(venue)
    seeds: dict[str, int] = {}

    def make(agent_id: str) -> MapMatcher:
        seed = seeds.setdefault(agent_id, len(seeds))
        return MapGuard(ParticleMatcher(area, replace(PHONE_PARTICLES, seed=seed)), PHONE_GUARD)

    return make


class PedestrianHub:
    """`on_message(message) -> outputs` (EstimatedPose, track LIVE), `key_for(output)`."""

    def __init__(self, session: Session, matcher_factory: Callable[[str], MapMatcher] | None = None,
                 method: str = METHOD):
        """`matcher_factory(agent_id)`: each pedestrian's matcher; None: ours over the venue's map
        (particle_matcher_factory), and none where the venue has no map."""
        self.venue = session.venue.name
        factory = matcher_factory if matcher_factory is not None else particle_matcher_factory(session.venue)
        self.method = method
        self.agents = {agent.id: PedestrianView(agent.id, factory(agent.id) if factory is not None else None)
                       for agent in session.agents if agent.kind is AgentKind.PEDESTRIAN}

    def on_message(self, message: Any) -> list[Any]:
        """Outputs for one input: a live pose, and the refined poses the matcher finished."""
        if messages.type_name(message) != "EstimatedPose":
            return []
        view = self.agents.get(message.agent_id)
        if view is None:
            return []
        if message.timestamp_ns <= view.last_time_ns:
            view.out_of_order += 1
            return []
        view.last_time_ns = message.timestamp_ns
        view.poses += 1
        covariance = np.asarray(message.covariance, dtype=float).reshape(3, 3) if len(message.covariance) == 9 else None
        previous_sequence, sequence = view.resets, message.correction_sequence
        restarted = sequence != previous_sequence
        view.resets = sequence
        if view.matcher is None:
            return [self._pose(view, message.timestamp_ns, message.x_m, message.y_m, message.heading_rad, covariance,
                               sequence)]
        if restarted:  # what waited for its lag ends with the old stand's track
            view.matcher.reset(message.timestamp_ns, message.x_m, message.y_m, message.heading_rad)
            out = self._refined(view, previous_sequence)
            here = (message.timestamp_ns, message.x_m, message.y_m, message.heading_rad, covariance, sequence)
            refined_too = view.matcher.refined_lag_steps > 0
            off_map = bool(getattr(view.matcher, "fallback", False))  # a stand the map does not allow
            return out + [self._pose(view, *here, fallback=off_map)] + (
                [self._pose(view, *here, track=messages.Track.REFINED, fallback=off_map)] if refined_too else [])
        matched = view.matcher.update(DeadReckonedPose(message.timestamp_ns, message.x_m, message.y_m,
                                                       message.heading_rad, covariance))
        view.matched += 1
        if matched.snap is not None:
            view.snaps.append(matched.snap)
        if matched.fallback:
            view.fallback_poses += 1
        return [self._pose(view, matched.time_ns, matched.x_m, matched.y_m, matched.heading_rad, matched.covariance,
                           sequence, fallback=matched.fallback)] + self._refined(view, sequence)

    def flush(self) -> list[Any]:
        """End of the streams: every refined pose still waiting for its lag."""
        out = []
        for view in self.agents.values():
            if view.matcher is not None:
                out += [self._pose(view, p.time_ns, p.x_m, p.y_m, p.heading_rad, p.covariance, view.resets,
                                   track=messages.Track.REFINED, fallback=p.fallback) for p in view.matcher.flush()]
        return out

    def _refined(self, view: PedestrianView, sequence: int) -> list[Any]:
        return [self._pose(view, p.time_ns, p.x_m, p.y_m, p.heading_rad, p.covariance, sequence,
                           track=messages.Track.REFINED, fallback=p.fallback)
                for p in view.matcher.refined()] if view.matcher else []

    def _pose(self, view: PedestrianView, time_ns: int, x_m: float, y_m: float, heading_rad: float,
              covariance: np.ndarray | None, sequence: int, track: messages.Track = messages.Track.LIVE,
              fallback: bool = False) -> Any:
        if track is messages.Track.LIVE:
            view.last = (x_m, y_m)
        values = [] if covariance is None else np.asarray(covariance, dtype=float).ravel().tolist()
        return messages.new("EstimatedPose", timestamp_ns=time_ns, agent_id=view.agent_id, x_m=x_m, y_m=y_m,
                            heading_rad=math.remainder(heading_rad, 2.0 * math.pi), covariance=values,
                            method=self.method, track=track, correction_sequence=sequence, map_fallback=fallback)

    def key_for(self, message: Any) -> str:
        track = "refined" if message.track == messages.Track.REFINED else "live"
        return keys.pose(self.venue, message.agent_id, track)

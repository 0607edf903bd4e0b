"""The hub's part for pedestrians: each one's dead-reckoned steps through a map matcher.

Per pedestrian agent with a map (the venue's floor plan, or corridors between its map points:
hub/pedestrian/walkable.py), every edge pose (EstimatedPose on `pose/edge`, per step) goes through the
matcher and leaves as the corrected `pose/live`. Without a map the edge pose is passed on as it is.

Each pose names its floor (the edge counts floor changes from the phone's barometer:
edge/pedestrian/floors.py). A building with a plan per floor (`Venue.floor_plans`) has a matcher per
floor and agent; when the floor changes, the new floor's matcher starts where the old one left the
agent (the edge pose shifted by the last matched offset: a stair is in both floors' plans) and the
old one's refined poses are flushed.

Beacon sightings (BeaconSighting, the phone's scan of the venue's beacons) become proximity fixes
at the moment of closest approach (hub/pedestrian/beacons.py: a per-beacon learned level, a pass
peak), only from beacons on the agent's floor, each gated against the hub's own track at that
moment and, when taken, carried to now along the edge's track and weighed into the matcher: the
particle filter's weights, or where a floor has no map the offset of the edge's track
(hub/pedestrian/offset.py).

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

from hub.dedup import RESET_NS
from hub.inputs import check_pose
from hub.pedestrian.beacons import BeaconPasses, ProximityFix, gate
from hub.pedestrian.guard import GuardSettings, MapGuard
from hub.pedestrian.matching import DeadReckonedPose, MapMatcher
from hub.pedestrian.offset import OffsetMatcher
from hub.pedestrian.particles import ParticleMatcher, ParticleSettings
from hub.pedestrian.walkable import WalkableArea
from protocol import keys, messages
from protocol.session import AgentKind, Session, Venue

METHOD = "reckon"
REFINED_LAG_STEPS = 20  # pose/refined: about 10 s behind, long enough to have met the next wall or corner
HISTORY_POSES = 64  # about 30 s of steps: a beacon pass is placed on the track up to this far back
FIX_PLACE_S = 1.0  # ... on the pose nearest its time, when one is this close
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


# (agent id, floor) -> that agent's matcher there; None: that floor has no map (the edge's track goes on)
MatcherFactory = Callable[[str, int], MapMatcher | None]


@dataclass
class PedestrianView:
    agent_id: str
    matcher: MapMatcher | None
    floor: int = 0
    floor_changes: int = 0
    resets: int = 0
    last_time_ns: int = -1
    poses: int = 0
    out_of_order: int = 0
    clock_restarts: int = 0  # poses further back than the dedup's reset: the track starts again from them
    matched: int = 0  # poses that went through the matcher
    fallback_poses: int = 0  # live poses that are the edge's own track: the map contradicted it
    snaps: deque = field(default_factory=lambda: deque(maxlen=SNAPS_KEPT))  # the paper's snap decisions, newest
    last: tuple[float, float] | None = None  # the last pose out (x m, y m)
    last_edge: tuple[float, float] | None = None  # the edge pose it came from
    passes: BeaconPasses | None = None  # its phone's passes of the venue's beacons
    # (time ns, x m, y m, 2x2 covariance, edge x m, edge y m) of the last live poses out, oldest first
    history: deque = field(default_factory=lambda: deque(maxlen=HISTORY_POSES))
    fixes_taken: int = 0
    fixes_refused: int = 0  # outside the gate
    fixes_elsewhere: int = 0  # of a beacon on another floor, or with no pose near its time

    def describe(self) -> str:
        where = "none" if self.last is None else f"x {self.last[0]:.2f} m, y {self.last[1]:.2f} m"
        fallback = f", {self.fallback_poses} on the edge's track (map contradicted)" if self.fallback_poses else ""
        floors = f", {self.floor_changes} floor changes (on floor {self.floor})" if self.floor_changes else ""
        beacons = (f", beacon fixes {self.fixes_taken} taken, {self.fixes_refused} refused by the gate, "
                   f"{self.fixes_elsewhere} elsewhere" if self.passes is not None else "")
        restarts = f", {self.clock_restarts} clock restarts" if self.clock_restarts else ""
        return (f"{self.poses} poses, {self.resets} stand resets, {self.out_of_order} out of order{restarts}{fallback}{floors}"
                f"{beacons}; last {where}")


class OurMatchers:
    """Our matcher for each pedestrian and floor (a MatcherFactory the hub's checkpoint can pickle):
    the particle filter behind the map guard; on a floor without a map, the edge's track shifted by
    beacon fixes when the venue has beacons (and `beacons`), else none. Each floor's walkable area
    is built once and shared; each agent's filter has its own seed (agent order)."""

    def __init__(self, venue: Venue, area: WalkableArea | None = None, beacons: bool = True) -> None:
        self.venue = venue
        self.with_beacons = beacons and bool(venue.beacons)
        self.areas: dict[int, WalkableArea | None] = {} if area is None else {0: area}
        self.seeds: dict[str, int] = {}

    def __call__(self, agent_id: str, floor: int) -> MapMatcher | None:
        if floor not in self.areas:
            try:
                self.areas[floor] = WalkableArea.from_venue(self.venue, floor=floor)
            except ValueError:  # no plan, and map points on other floors only (or none)
                self.areas[floor] = None
        area = self.areas[floor]
        if area is None:
            return OffsetMatcher() if self.with_beacons else None
        seed = self.seeds.setdefault(agent_id, len(self.seeds))
        return MapGuard(ParticleMatcher(area, replace(PHONE_PARTICLES, seed=seed)), PHONE_GUARD)


def our_matcher_factory(venue: Venue, area: WalkableArea | None = None, beacons: bool = True) -> OurMatchers | None:
    """OurMatchers for the venue (`area`: floor 0's walkable area, when already built), or None when
    no floor could have a matcher (no map and no beacons to use)."""
    if not venue.floor_plan and not venue.floor_plans and not venue.map_points and not (beacons and venue.beacons):
        return None
    return OurMatchers(venue, area, beacons)


class PedestrianHub:
    """`on_message(message) -> outputs` (EstimatedPose, track LIVE), `key_for(output)`."""

    def __init__(self, session: Session, matcher_factory: MatcherFactory | None = None, method: str = METHOD,
                 beacons: bool = True):
        """`matcher_factory(agent_id, floor)`: each pedestrian's matcher on a floor; None: ours
        (our_matcher_factory). `beacons`: the venue's beacons give fixes (to a matcher that takes them)."""
        self.venue = session.venue.name
        self.factory = (matcher_factory if matcher_factory is not None
                        else our_matcher_factory(session.venue, beacons=beacons))
        self.method = method
        self.beacons = {beacon.id: beacon for beacon in session.venue.beacons} if beacons else {}
        self.agents = {agent.id: PedestrianView(agent.id, self.factory(agent.id, 0) if self.factory else None,
                                                passes=BeaconPasses(tuple(self.beacons.values())) if self.beacons
                                                else None)
                       for agent in session.agents if agent.kind is AgentKind.PEDESTRIAN}

    def on_message(self, message: Any) -> list[Any]:
        """Outputs for one input: a live pose, and the refined poses the matcher finished."""
        name = messages.type_name(message)
        view = self.agents.get(getattr(message, "agent_id", ""))
        if view is None:
            return []
        if name == "BeaconSighting":
            if view.passes is not None:
                for fix in view.passes.sight(message.timestamp_ns, message.beacon_id, message.rssi_dbm):
                    self._fix(view, fix)
            return []
        if name != "EstimatedPose":
            return []
        values = check_pose(message)
        clock_restart = False
        if message.timestamp_ns <= view.last_time_ns:
            if view.last_time_ns - message.timestamp_ns <= RESET_NS:
                view.out_of_order += 1
                return []
            # further back than the dedup's reset: the phone's clock restarted, or the pose before was a
            # jump ahead; refusing every later pose as older than that one would end the walker's track
            view.clock_restarts += 1
            clock_restart = True
        view.last_time_ns = message.timestamp_ns
        view.poses += 1
        if view.passes is not None:
            for fix in view.passes.tick(message.timestamp_ns):
                self._fix(view, fix)
        covariance = np.asarray(values, dtype=float).reshape(3, 3) if len(values) == 9 else None
        previous_sequence, sequence = view.resets, message.correction_sequence
        restarted = sequence != previous_sequence or clock_restart
        view.resets = sequence
        out: list[Any] = []
        if message.floor != view.floor:
            out = self._change_floor(view, message, restarted)
        if view.matcher is None:
            view.last_edge = (message.x_m, message.y_m)
            return out + [self._pose(view, message.timestamp_ns, message.x_m, message.y_m, message.heading_rad,
                                     covariance, sequence)]
        if restarted:  # what waited for its lag ends with the old stand's track
            view.matcher.reset(message.timestamp_ns, message.x_m, message.y_m, message.heading_rad)
            out += self._refined(view, previous_sequence)
            here = (message.timestamp_ns, message.x_m, message.y_m, message.heading_rad, covariance, sequence)
            refined_too = view.matcher.refined_lag_steps > 0
            off_map = bool(getattr(view.matcher, "fallback", False))  # a stand the map does not allow
            view.last_edge = (message.x_m, message.y_m)
            view.history.clear()  # the edge restarted: its track before the stand is another one
            return out + [self._pose(view, *here, fallback=off_map, edge_xy=view.last_edge)] + (
                [self._pose(view, *here, track=messages.Track.REFINED, fallback=off_map)] if refined_too else [])
        matched = view.matcher.update(DeadReckonedPose(message.timestamp_ns, message.x_m, message.y_m,
                                                       message.heading_rad, covariance))
        view.matched += 1
        if matched.snap is not None:
            view.snaps.append(matched.snap)
        if matched.fallback:
            view.fallback_poses += 1
        view.last_edge = (message.x_m, message.y_m)
        return out + [self._pose(view, matched.time_ns, matched.x_m, matched.y_m, matched.heading_rad,
                                 matched.covariance, sequence, fallback=matched.fallback, edge_xy=view.last_edge)
                      ] + self._refined(view, sequence)

    def _fix(self, view: PedestrianView, fix: ProximityFix) -> None:
        """A beacon's close pass: placed on the track at its time, gated, carried to now, weighed in."""
        observe = getattr(view.matcher, "observe", None)
        beacon = self.beacons[fix.beacon_id]
        if observe is None or not view.history:
            return
        nearest = min(view.history, key=lambda row: abs(row[0] - fix.time_ns))
        if beacon.floor != view.floor or abs(nearest[0] - fix.time_ns) > FIX_PLACE_S * 1e9:
            view.fixes_elsewhere += 1
            return
        taken = gate(fix, nearest[1], nearest[2], nearest[3])
        view.passes.judged(fix, taken)
        if not taken:
            view.fixes_refused += 1
            return
        view.fixes_taken += 1
        last = view.history[-1]
        observe(fix.x_m + last[4] - nearest[4], fix.y_m + last[5] - nearest[5], fix.sd_m, last[3])

    def _change_floor(self, view: PedestrianView, message: Any, restarted: bool) -> list[Any]:
        """The agent is on another floor: the old floor's refined poses, and its new floor's matcher
        started where the matched track would go on (a stand reset that came with it starts it anyway)."""
        out = [] if view.matcher is None else [
            self._pose(view, p.time_ns, p.x_m, p.y_m, p.heading_rad, p.covariance, view.resets,
                       track=messages.Track.REFINED, fallback=p.fallback) for p in view.matcher.flush()]
        view.matcher = self.factory(view.agent_id, message.floor) if self.factory is not None else None
        view.floor = message.floor
        view.floor_changes += 1
        if view.matcher is not None and not restarted:
            x_m, y_m = message.x_m, message.y_m
            if view.last is not None and view.last_edge is not None:
                x_m += view.last[0] - view.last_edge[0]
                y_m += view.last[1] - view.last_edge[1]
            view.matcher.reset(message.timestamp_ns, x_m, y_m, message.heading_rad)
        return out

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
              fallback: bool = False, edge_xy: tuple[float, float] | None = None) -> Any:
        if track is messages.Track.LIVE:
            view.last = (x_m, y_m)
            if view.passes is not None and covariance is not None and edge_xy is not None:
                view.history.append((time_ns, x_m, y_m, np.asarray(covariance, dtype=float)[:2, :2], *edge_xy))
        values = [] if covariance is None else np.asarray(covariance, dtype=float).ravel().tolist()
        return messages.new("EstimatedPose", timestamp_ns=time_ns, agent_id=view.agent_id, x_m=x_m, y_m=y_m,
                            heading_rad=math.remainder(heading_rad, 2.0 * math.pi), covariance=values,
                            method=self.method, track=track, correction_sequence=sequence, map_fallback=fallback,
                            floor=view.floor)

    def key_for(self, message: Any) -> str:
        track = "refined" if message.track == messages.Track.REFINED else "live"
        return keys.pose(self.venue, message.agent_id, track)

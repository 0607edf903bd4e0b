"""The hub's computation for a venue of chairs, without I/O: messages in, messages out.

In: every agent's ClockSample (or raw ImuBatch, from a recording: only for clock offsets),
EstimatedPose and FieldReading from its edge, ImpactEvent, BeaconSighting, and PositionFix from an
operator or a video tracker.
Out: a live corrected pose per agent as each edge pose arrives, a refined pose once it is `lag_s`
old (hub/chair/smoother.py), and Correction and FieldMap messages for the edges.

Why corrections go back to the edges: the edge holds the whole state (heading, gyro bias, wheel
scale), so a position measurement applied there also corrects the heading error that caused the
drift, which an offset kept at the hub could not. Until an edge's pose says it has taken a
correction (`correction_sequence`), the hub adds the shift it expects the edge to make.

All times here are venue time: device timestamps plus each device's clock offset (hub/clocks.py).
- Collisions: impacts above `impact_g` seen by two chairs within `pairing_window_s`, paired into
  contacts once every live agent's poses have passed them (hub/chair/pairing.py); each chair of a
  contact gets the other's side as a measurement.
- Beacons: one fix per candidate pass, at its strongest sighting: close or far, each where and as widely as its
  beacon's passes of that kind have shown (hub/chair/corrections.py).
- Fixes: an operator's or video position at a time, gated like a beacon fix.
- The hall's magnetic field: every edge's FieldReading goes into one map of the hall
  (hub/chair/field_map.py); every `period_s` each reading edge gets it back without its own.

Honest covariance. An edge's covariance is its filter's, and after a run of video fixes it states
a few centimetres while the chair's true error grows faster than the edge's process noise says
(slips, shoves, a wrong fix taken): measured on a 120 s game with camera fixes, the live pose's
squared error is 4.9 times the edge's stated covariance at the median (NEES; 2 if honest), 12 on
average, so a gate on that covariance alone refuses correct fixes from well-identified tracks for
seconds at a time. The hub therefore keeps, per agent, the covariance the edge is missing (`AgentView.extra`): it grows
with the chair's travel and with time, and shrinks with each correction as the honest update
(the edge's gain, applied to the edge's covariance + extra) says. The gate of fixes (video and
an operator's), the published live poses and the identity engine's position cue use the honest
covariance (edge's + extra). Beacons, contacts and the smoother keep the edge's: without camera
fixes it is already conservative (NEES median 1.2), and with the honest one there beacon +
collision got up to 0.01 m worse.
A video track that the gate keeps refusing with the same offset (`relock_after` fixes in a row
from one source, agreeing with each other) says the hub's pose is wrong, not the track: its
offset is added to `extra` and the fix is taken.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from hub.chair.corrections import FIX_GATE_CHI2, BeaconLevels, mahalanobis2
from hub.chair.field_map import FieldMap, FieldMapSettings
from hub.chair.pairing import ImpactPairing
from hub.clocks import ClockOffsets
from hub.dedup import RESET_NS
from hub.inputs import check_pose
from hub.chair.smoother import FixedLagSmoother
from hub.chair.view import CORRECTIONS, AgentView, Pass
from protocol import keys, messages
from protocol.session import AgentKind, Mount, Session

Kind = messages.CorrectionKind
# Corrections sent and not yet acknowledged by the edge's poses, per agent, beyond which the oldest two
# are held as one (taken back together, when the second is acknowledged): an edge that never takes
# them (a replay, an edge deaf to the hub) would otherwise grow the list, and every pose sums it.
PENDING_MAX = 16
_EstimatedPose = messages.EstimatedPose
_IDENTITY = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]  # a pose's covariance when it came without one


@dataclass(frozen=True)
class HubSettings:
    lag_s: float = 30.0  # refined poses leave this late (a pass near a goal every 10-30 s)
    pose_rate_hz: float = 50.0  # of the edges; sizes the smoother's ring
    corrections: Collection[str] = CORRECTIONS  # kept as a tuple in CORRECTIONS' order (below)
    impact_g: float = 6.0  # lower than the paper's 8 g: the gate, not the threshold, rejects false pairs
    # both impacts of a contact are one instant on the clocks the hub aligns (hub/clocks.py): the
    # paper's 0.5 s also pairs two bumps that merely happen close together. The window is also the
    # impacts' timing prior until the venue's contacts have shown theirs (pairing.ContactTiming).
    pairing_window_s: float = 0.15
    lateness_s: float = 1.0  # how long a group waits for the other chairs' impacts to arrive
    stale_s: float = 5.0  # an agent silent this long (hub clock) no longer holds the others back
    pass_end_s: float = 1.5  # a pass ends after this long without a sighting above its beacon's floor
    extra_m2_per_m: float = 0.003  # covariance the edge is missing, per metre travelled (per axis)
    extra_m2_per_s: float = 0.0005  # ... and per second (shoves and slips without wheel travel)
    extra_max_m2: float = 0.09  # ... up to this: what it stands for (slips, shoves, a fix's timing) is bounded
    relock_after: int = 2  # video fixes in a row from one source refused with one offset: the pose is wrong
    relock_agree_m: float = 0.4  # ... their offsets this close to their mean
    relock_within_s: float = 6.0  # ... all within this long
    field_map: FieldMapSettings = FieldMapSettings()  # the hall's magnetic field, learnt from every chair

    def __post_init__(self) -> None:
        unknown = set(self.corrections) - set(CORRECTIONS)
        if unknown:
            raise ValueError(f"corrections {sorted(unknown)}: not among {', '.join(CORRECTIONS)}")
        # A tuple in a fixed order, not a set: a set's order depends on how it was built, so a hub
        # restored from a snapshot would pickle differently from the same hub that never stopped.
        object.__setattr__(self, "corrections", tuple(c for c in CORRECTIONS if c in set(self.corrections)))
        if not (0 <= self.lag_s < math.inf and 0 < self.pose_rate_hz < math.inf):  # refuses NaN too
            raise ValueError(f"lag_s {self.lag_s} must be finite and >= 0, pose_rate_hz {self.pose_rate_hz} finite and > 0")


@dataclass
class HubCounters:
    impacts: int = 0
    groups: int = 0
    pairs: int = 0
    gated_out: int = 0  # candidate corrections the gate rejected
    pushes_not_opposed: int = 0  # impact pairs whose pushes did not point opposite ways: no contact
    not_simultaneous: int = 0  # impact pairs further apart in time than the contacts taken (pairing.ContactTiming)
    relocks: int = 0  # video fixes taken after a run of consistent refusals
    late_impacts: int = 0  # arrived after their window had closed: paired with later ones only
    clock_restarts: int = 0  # an agent's poses went back in time by more than the dedup's reset (`_restart`)
    pending_folded: int = 0  # corrections held together with the one after them (PENDING_MAX)
    refined_unbuilt: int = 0  # refined poses not made into messages: nobody wanted the track (`refined_wanted`)


class ChairHub:
    def __init__(self, session: Session, settings: HubSettings = HubSettings()):
        self.session = session
        self.settings = settings
        self.venue = session.venue.name
        self.clocks = ClockOffsets()
        self.beacons = {beacon.id: beacon for beacon in session.venue.beacons}
        self.beacon_levels = BeaconLevels(session.venue.beacons,
                                          session.venue.court_length_m * session.venue.court_width_m)
        chairs = [agent.id for agent in session.agents if agent.kind is AgentKind.WHEELCHAIR]
        self.field = FieldMap(session.venue, chairs, settings.field_map)
        ring = int(settings.lag_s * settings.pose_rate_hz) + 2
        self.agents: dict[str, AgentView] = {}
        for agent in session.agents:
            if agent.kind is not AgentKind.WHEELCHAIR:
                continue  # a swimmer's lengths need no venue-level correction (reckon/processes/hub.py shows them)
            seat = agent.sensor(Mount.SEAT)
            self.agents[agent.id] = AgentView(
                agent.id, seat.id if seat else "", FixedLagSmoother(settings.lag_s, ring),
                live_key=keys.pose(self.venue, agent.id, "live"), refined_key=keys.pose(self.venue, agent.id, "refined"),
                pose_fields={track: _EstimatedPose(schema_version=messages.SCHEMA_VERSION, agent_id=agent.id,
                                                   method="reckon", track=track)
                             for track in (messages.Track.LIVE, messages.Track.REFINED)})
        self.newest_arrival_ns = 0
        self.counters = HubCounters()
        self.pairing = ImpactPairing(settings.pairing_window_s, settings.lateness_s, settings.stale_s, self.counters)
        # Whether anyone takes the refined track (a subscriber, a recording: the hub process says, as it
        # learns): when nobody does, its poses still pass through the smoothers, never into messages.
        self.refined_wanted = True
        self._pass_end_ns = settings.pass_end_s * 1e9

    # -- inputs ------------------------------------------------------------------------------

    def on_message(self, message: Any, arrival_ns: int) -> list[Any]:
        """Any input message and when it arrived (hub clock); returns the messages to publish (`key_for`).

        Arrival times only tell a silent agent from a slow one: an agent whose last message came
        `stale_s` before the newest arrival no longer holds the collision pairing back.
        """
        view = self.agents.get(message.agent_id)
        if view is None:
            return []
        view.arrival_ns = arrival_ns
        if arrival_ns > self.newest_arrival_ns:
            self.newest_arrival_ns = arrival_ns
        if type(message) is _EstimatedPose:  # most inputs
            return self.on_pose(message)
        name = messages.type_name(message)
        if name == "ClockSample":
            self.clocks.observe(message.sensor_id, message.timestamp_ns, message.received_ns)
            return []
        if name == "ImuBatch":  # a recording's or a replay's raw batches (a live edge sends ClockSample)
            if message.received_ns and len(message.sample_offset_ns):
                self.clocks.observe(message.sensor_id, message.timestamp_ns + message.sample_offset_ns[-1],
                                    message.received_ns)
            return []
        if name == "ImpactEvent":
            self.on_impact(message)
        elif name == "BeaconSighting":
            return self.on_sighting(message)
        elif name == "PositionFix":
            return self.on_fix(message)
        elif name == "FieldReading":
            self.field.add(message)
        return []

    def on_pose(self, pose: Any) -> list[Any]:
        view = self.agents[pose.agent_id]
        time_ns = self.clocks.to_venue(view.seat_id, pose.timestamp_ns)
        sequence, edge_x, edge_y, heading = pose.correction_sequence, pose.x_m, pose.y_m, pose.heading_rad
        values = check_pose(pose)  # the 3 x 3 as floats; not numbers would reach the smoother, the history, the fixes
        out: list[Any] = []
        if view.latest_ns is not None and view.latest_ns - time_ns > RESET_NS:
            out = self._restart(view)
        if sequence < view.acknowledged:  # the edge restarted: it holds none of ours
            view.pending.clear()
        # The edge holds corrections this hub never made (sent by it before a restart, after its last
        # checkpoint): number on from them, so the edge does not drop ours as repeats.
        if sequence > view.sequence:
            view.sequence = sequence
        view.acknowledged = sequence
        if view.pending:
            view.pending = [(seq, shift) for seq, shift in view.pending if seq > sequence]
        if view.pending:
            xy = np.array([edge_x, edge_y]) + sum((shift for _, shift in view.pending), np.zeros(2))
            x, y = float(xy[0]), float(xy[1])
        else:  # the usual case; + 0.0 as the sum above adds (it turns -0.0 into 0.0)
            x, y = edge_x + 0.0, edge_y + 0.0
        if len(values) != 9:
            values = _IDENTITY
        view.edge_covariance = values
        self._grow_extra(view, time_ns, edge_x, edge_y, sequence)
        if view.latest_ns is None or time_ns > view.latest_ns:
            view.latest_ns = time_ns
        honest = list(values)  # + extra on the position block, in floats: one small array op less
        e00, e01, e10, e11 = view.extra_m2
        honest[0] += e00
        honest[1] += e01
        honest[3] += e10
        honest[4] += e11
        view.history.append(time_ns, x, y, values, heading)
        view.poses += 1
        out.append(self._pose_message(view, time_ns, x, y, heading, honest, messages.Track.LIVE))
        refined = view.smoother.add(time_ns, x, y, heading, values, self.refined_wanted)
        if refined:
            out += self._refined(view, refined)
        if view.passes or view.ended or view.fixes:
            out += self._end_passes(view)
        if self.pairing.impacts:
            out += [self._send(self.agents[fix.agent], fix.time_ns, fix.measured, fix.covariance, Kind.COLLISION,
                               other=fix.other) for fix in self.pairing.close(view, self.agents, self.newest_arrival_ns)]
        if self.field.due(time_ns):
            out += self.field.maps(time_ns)
        return out

    def _restart(self, view: AgentView) -> list[Any]:
        """The agent's time went back by more than the dedup's reset (its device's clock restarted, or the
        pose before was a jump ahead): what is held on its old timeline (the smoother's poses, which leave
        now as refined, the history, open passes and fixes waiting for poses) is closed, so that its poses
        from here on are not all older than that one and refused. (A device whose own clock restarted reaches
        the hub re-anchored by its edge, docs/device-faults.md; were its venue time to stay far behind the
        others', it would hold the collision pairing back like any agent short of an impact, until the
        clock offsets follow it.)"""
        self.counters.clock_restarts += 1
        refined = self._refined(view, view.smoother.flush())
        view.history.clear()
        view.passes.clear()
        view.ended.clear()
        view.fixes.clear()
        view.latest_ns = view.last_edge = None
        view.passes_last_ns = 0
        self.pairing.agents_changed()  # the agents short of the oldest impact are found again
        return refined

    def _grow_extra(self, view: AgentView, time_ns: int, x: float, y: float, sequence: int) -> None:
        """The covariance the edge is missing grows with travel and time since the previous pose (the
        edge's, at `x`, `y` holding corrections up to `sequence`). A pose holding a new correction
        jumped: its step is not travel."""
        last = view.last_edge
        view.last_edge = (time_ns, x, y, sequence)
        if last is None or time_ns <= last[0]:
            return
        travel = math.hypot(x - last[1], y - last[2]) if sequence == last[3] else 0.0
        grow = self.settings.extra_m2_per_m * travel + self.settings.extra_m2_per_s * (time_ns - last[0]) * 1e-9
        extra = view.extra_m2  # grown in place (as extra + grow x identity: + 0.0 off the diagonal)
        if grow > 0 and extra[0] + extra[3] < 2 * self.settings.extra_max_m2:
            extra[0] += grow
            extra[1] += 0.0
            extra[2] += 0.0
            extra[3] += grow

    def on_impact(self, event: Any) -> None:
        if not math.isfinite(event.peak_g + event.forward_g + event.left_g):
            raise ValueError(f"ImpactEvent of {event.agent_id} at {event.timestamp_ns}: peak_g {event.peak_g}, "
                             f"forward_g {event.forward_g}, left_g {event.left_g}: every value must be finite")
        if event.peak_g < self.settings.impact_g or "collision" not in self.settings.corrections:
            return
        view = self.agents[event.agent_id]
        time_ns = self.clocks.to_venue(event.sensor_id or view.seat_id, event.timestamp_ns)
        self.pairing.add(time_ns, event.agent_id, event.forward_g, event.left_g)

    def on_sighting(self, sighting: Any) -> list[Any]:
        if not math.isfinite(sighting.rssi_dbm):  # NaN passes every comparison below and would join the level's peaks
            raise ValueError(f"BeaconSighting of {sighting.agent_id} at {sighting.timestamp_ns}: rssi_dbm "
                             f"{sighting.rssi_dbm} must be finite")
        if "beacon" not in self.settings.corrections or sighting.beacon_id not in self.beacons:
            return []
        if sighting.rssi_dbm < self.beacon_levels.pass_floor_dbm(sighting.beacon_id):
            return []
        view = self.agents[sighting.agent_id]
        time_ns = self.clocks.to_venue(sighting.sensor_id or view.seat_id, sighting.timestamp_ns)
        current = view.passes.get(sighting.beacon_id)
        if current is not None and time_ns - current.last_ns > self._pass_end_ns:
            view.ended.append((sighting.beacon_id, view.passes.pop(sighting.beacon_id)))
            current = None
        if current is None:
            view.passes[sighting.beacon_id] = Pass(sighting.rssi_dbm, time_ns, time_ns)
            view.passes_last_ns = min(view.passes_last_ns, time_ns)
        else:
            current.last_ns = max(current.last_ns, time_ns)
            if sighting.rssi_dbm > current.peak_rssi:
                current.peak_rssi, current.peak_ns = sighting.rssi_dbm, time_ns
        return self._end_passes(view)

    def on_fix(self, fix: Any) -> list[Any]:
        if not math.isfinite(fix.x_m + fix.y_m):
            raise ValueError(f"PositionFix for {fix.agent_id} at {fix.timestamp_ns}: x_m {fix.x_m}, y_m {fix.y_m} "
                             "must be finite")
        wanted = "camera" if fix.kind == Kind.VIDEO else "fix"
        if wanted not in self.settings.corrections:
            return []
        view = self.agents[fix.agent_id]
        covariance = np.array(fix.covariance, dtype=float).reshape(2, 2) if len(fix.covariance) == 4 else None
        if covariance is None or not np.all(np.isfinite(covariance)) or np.linalg.det(covariance) <= 0:
            raise ValueError(f"PositionFix for {fix.agent_id}: covariance {list(fix.covariance)} is not a 2 x 2 "
                             "positive-definite matrix")
        kind = Kind(fix.kind) if fix.kind in (Kind.VIDEO, Kind.MANUAL) else Kind.MANUAL
        view.fixes.append((fix.timestamp_ns, np.array([fix.x_m, fix.y_m]), covariance, kind, fix.source_id))
        return self._end_passes(view)

    def without_clocks(self, min_poses: int) -> list[str]:
        """Agents with at least `min_poses` poses whose seat has given no clock offset yet (no
        ClockSample, no raw batch with its arrival time): their venue time is their device time."""
        return [view.agent_id for view in self.agents.values()
                if view.poses >= min_poses and view.seat_id not in self.clocks.envelopes]

    def flush(self) -> list[Any]:
        """End of session: refined poses still inside the lag."""
        return [message for part in self.flush_by_agent() for message in part]

    def flush_by_agent(self) -> Iterator[list[Any]]:
        """`flush`, one agent at a time: a whole venue's tracks at once are gigabytes (500 chairs x 30 s)."""
        for view in self.agents.values():
            yield self._refined(view, view.smoother.flush())

    # -- corrections ---------------------------------------------------------------------------

    def _end_passes(self, view: AgentView) -> list[Any]:
        """Fixes of passes that are over, once the agent's poses have reached their peaks.

        Pose time, not sighting time, decides: the bus does not keep an agent's sightings and
        poses in order, and a fix needs the pose the chair had at the peak.
        """
        if view.latest_ns is None:
            return []
        latest_ns, end_ns = view.latest_ns, self._pass_end_ns
        if view.passes and latest_ns - view.passes_last_ns > end_ns:  # one may have ended (sightings move last_ns on)
            for beacon_id, current in list(view.passes.items()):
                if latest_ns - current.last_ns > end_ns:
                    view.ended.append((beacon_id, view.passes.pop(beacon_id)))
            view.passes_last_ns = min((current.last_ns for current in view.passes.values()), default=latest_ns)
        out = []
        while view.ended and view.ended[0][1].peak_ns <= view.latest_ns:
            beacon_id, ended = view.ended.popleft()
            covariance = self.beacon_levels.close(beacon_id, ended.peak_rssi)
            then = view.pose_bridged(ended.peak_ns) if covariance is not None else None
            fix = self.beacon_levels.fix(beacon_id, then[0], then[1], covariance) if then is not None else None
            if fix is not None:
                out += self._absolute(view, ended.peak_ns, fix[0], fix[1], Kind.BEACON, beacon_id, then)
        while view.fixes and view.fixes[0][0] <= view.latest_ns:
            out += self._absolute(view, *view.fixes.popleft())
        return out

    def _absolute(self, view: AgentView, time_ns: int, xy: np.ndarray, covariance: np.ndarray, kind: Kind,
                  source: str, then: tuple[np.ndarray, np.ndarray] | None = None) -> list[Any]:
        """A fix at `time_ns` gated against the pose then (`then`, if the caller has it already)."""
        then = view.pose_bridged(time_ns) if then is None else then
        if then is None:
            return []
        shift = xy - then[0]
        spread = then[1] + covariance + (view.extra if kind in (Kind.VIDEO, Kind.MANUAL) else 0.0)
        taken = mahalanobis2(shift, spread) <= FIX_GATE_CHI2
        if not taken:
            if kind != Kind.VIDEO or not self._relock(view, time_ns, shift, covariance, source):
                self.counters.gated_out += 1
                return []
        if source == view.refused_source:
            view.refused.clear()
        return [self._send(view, time_ns, shift, covariance, kind, source=source)]

    def _relock(self, view: AgentView, time_ns: int, shift: np.ndarray, covariance: np.ndarray, source: str) -> bool:
        """Whether a refused video fix is taken after all: when its source's last `relock_after` fixes were
        all refused with offsets that agree, the hub's pose is what is wrong (a track does not follow a
        chair at a fixed offset unless the pose is off). Then `extra` takes the offset and the fix passes."""
        s = self.settings
        if s.relock_after <= 0:
            return False
        if source != view.refused_source:  # "in a row": another source's refusals are another story
            view.refused_source, view.refused = source, []
        runs = view.refused
        runs.append((time_ns, shift))
        del runs[:-s.relock_after]
        if len(runs) < s.relock_after or time_ns - runs[0][0] > s.relock_within_s * 1e9:
            return False
        offsets = np.array([offset for _, offset in runs])
        mean = offsets.mean(axis=0)
        if np.hypot(*(offsets - mean).T).max() > s.relock_agree_m:
            return False
        view.extra = view.extra + np.outer(shift, shift)
        self.counters.relocks += 1
        return True

    def _send(self, view: AgentView, time_ns: int, measured: np.ndarray, covariance: np.ndarray, kind: Kind,
              other: str = "", source: str = "") -> Any:
        """Record a correction, expect its effect on the live pose, and build the message.

        The edge applies its own gain (from its covariance P); `extra` becomes what the honest posterior
        of that update (Joseph form, prior P + extra) holds beyond the edge's. Sending a smaller
        measurement covariance instead, so that the edge would apply the honest gain, also scales the
        edge's heading update and diverges (a 120 s game without camera: 9.6 m against 0.70 m)."""
        edge_covariance = np.array(view.edge_covariance, dtype=float).reshape(3, 3)
        prior = edge_covariance[:2, :2]
        honest = prior + view.extra
        gain = prior @ np.linalg.inv(prior + covariance)
        expected = gain @ measured
        view.sequence += 1
        view.pending.append((view.sequence, expected))
        if len(view.pending) > PENDING_MAX:  # an edge not taking corrections: its two oldest become one
            (_, first), (second_sequence, second) = view.pending[0], view.pending[1]
            view.pending[0:2] = [(second_sequence, first + second)]
            self.counters.pending_folded += 1
        keep = np.eye(2) - gain
        after = keep @ prior
        honest_after = keep @ honest @ keep.T + gain @ covariance @ gain.T
        view.extra = _psd(honest_after - after)
        edge_covariance[:2, :2] = after
        view.edge_covariance = edge_covariance.ravel().tolist()
        view.smoother.correct(time_ns, expected, 0.5 * float(after[0, 0] + after[1, 1]))
        view.applied[{Kind.VIDEO: "camera", Kind.MANUAL: "fix"}.get(kind, kind.name.lower())] += 1
        return messages.new("Correction", timestamp_ns=int(time_ns), agent_id=view.agent_id, kind=kind,
                            dx_m=float(measured[0]), dy_m=float(measured[1]), other_agent_id=other, source_id=source,
                            sequence=view.sequence, covariance=covariance.ravel().tolist())

    def _refined(self, view: AgentView, entries: list[tuple]) -> list[Any]:
        """The smoother's (time, x, y, heading, covariance) entries as refined poses, if anyone wants them."""
        if not self.refined_wanted:
            self.counters.refined_unbuilt += len(entries)
            return []
        return [self._pose_message(view, time_ns, x, y, heading, covariance, messages.Track.REFINED)
                for time_ns, x, y, heading, covariance in entries]

    def _pose_message(self, view: AgentView, time_ns: int, x: float, y: float, heading: float,
                      covariance: list[float], track: messages.Track) -> Any:
        """Its fixed fields copied from the agent's own (a third cheaper than naming them each time)."""
        message = _EstimatedPose()
        message.CopyFrom(view.pose_fields[track])
        message.timestamp_ns, message.x_m, message.y_m, message.heading_rad = time_ns, x, y, heading
        message.covariance.extend(covariance)
        message.correction_sequence = view.sequence
        return message

    def key_for(self, message: Any) -> str:
        """Where an output message goes on the bus."""
        if type(message) is _EstimatedPose:  # two a pose: each agent's pose keys are made once
            view = self.agents[message.agent_id]
            return view.refined_key if message.track == messages.Track.REFINED else view.live_key
        name = messages.type_name(message)
        if name == "Correction":
            return keys.correction(self.venue, message.agent_id)
        if name == "FieldMap":
            return keys.field_map(self.venue, message.agent_id)
        raise ValueError(f"{name} is not an output of the chairs' hub")


def _psd(matrix: np.ndarray) -> np.ndarray:
    """The nearest symmetric positive semi-definite matrix (eigenvalues below zero to zero)."""
    values, vectors = np.linalg.eigh(0.5 * (matrix + matrix.T))
    return (vectors * np.maximum(values, 0.0)) @ vectors.T

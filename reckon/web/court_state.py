"""What the live court view shows, in fixed-size state: no I/O, no clock (times are passed in).

Per agent: the latest live pose (with its 95 % position ellipse), the latest refined pose, the
latest truth and a short truth history to compare the live pose with, the error against truth and
its running mean, each device's latest DeviceStatus, when its last input message came, and its
correction counts. For the venue: a ring of the most recent corrections and QR scans. Every
container is bounded (per agent: TRUTH_HISTORY, POSE_HISTORY; corrections: `ring`), so the state
of a long session is as big as the state of a short one. Unknown agents (not in the session
description) are counted and ignored: an id from the bus never grows the state.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from protocol import messages
from protocol.session import AgentKind, Session

TRUTH_HISTORY = 256  # truth poses kept per agent (2.6 s at the simulator's 100 Hz) to meet a live pose's time
POSE_HISTORY = 256  # live poses kept per agent (5 s at 50 Hz) to place a correction at its measured time
TRUTH_TOLERANCE_NS = 200_000_000  # a live pose newer than the newest truth by more than this has no error yet
ELLIPSE_SCALE = math.sqrt(5.991)  # 95 % of a 2-D Gaussian (chi-square, 2 dof)
CORRECTION_RING = 64
KIND_NAMES = {kind.value: kind.name.lower() for kind in messages.CorrectionKind}


def finite(value: float) -> float | None:
    """The value, or None when NaN or infinite (JSON has neither, and the page would stop)."""
    return value if math.isfinite(value) else None


def ellipse(covariance: Any) -> list[float] | None:
    """[semi-major m, semi-minor m, angle of the major axis rad] of the 95 % position ellipse of a
    row-major 3 x 3 (x, y, heading) or 2 x 2 covariance; None when absent or not positive."""
    size = len(covariance)
    if size not in (4, 9):
        return None
    stride = 3 if size == 9 else 2
    xx, xy, yy = covariance[0], covariance[1], covariance[stride + 1]
    if not all(math.isfinite(v) for v in (xx, xy, yy)):
        return None
    mean, half = 0.5 * (xx + yy), math.hypot(0.5 * (xx - yy), xy)
    major, minor = mean + half, mean - half
    if minor < 0.0 or major <= 0.0:
        return None
    return [ELLIPSE_SCALE * math.sqrt(major), ELLIPSE_SCALE * math.sqrt(minor), 0.5 * math.atan2(2.0 * xy, xx - yy)]


@dataclass
class AgentState:
    agent_id: str
    kind: str
    live: dict[str, Any] | None = None
    refined: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    truth_history: deque = field(default_factory=lambda: deque(maxlen=TRUTH_HISTORY))  # (time ns, x, y)
    pose_history: deque = field(default_factory=lambda: deque(maxlen=POSE_HISTORY))  # (time ns, x, y)
    error_m: float | None = None
    error_sum_m: float = 0.0
    error_count: int = 0
    scored_ns: int | None = None  # time of the last live pose scored, so a pose is scored once
    status: dict[str, dict[str, Any]] = field(default_factory=dict)  # sensor -> latest DeviceStatus
    last_input_ns: int | None = None  # view clock when its last input message came
    corrections: dict[str, int] = field(default_factory=dict)

    def truth_at(self, time_ns: int) -> tuple[float, float] | None:
        """Truth position at `time_ns`, interpolated between the two truth poses around it; None
        when the history does not cover it. Walks from the newest: a live pose lags truth a little."""
        history = self.truth_history
        if not history or time_ns < history[0][0] or time_ns > history[-1][0] + TRUTH_TOLERANCE_NS:
            return None
        newer = history[-1]
        if time_ns >= newer[0]:
            return newer[1], newer[2]
        for older in reversed(history):
            if older[0] <= time_ns:
                share = (time_ns - older[0]) / (newer[0] - older[0])
                return older[1] + share * (newer[1] - older[1]), older[2] + share * (newer[2] - older[2])
            newer = older
        return None

    def pose_at(self, time_ns: int) -> tuple[float, float] | None:
        """Live position at `time_ns` (the last pose not after it, else the oldest kept)."""
        if not self.pose_history:
            return None
        chosen = self.pose_history[0]
        for entry in reversed(self.pose_history):
            if entry[0] <= time_ns:
                chosen = entry
                break
        return chosen[1], chosen[2]


class ViewState:
    """The court view's state for one session; `apply` messages, `score` the live error, `snapshot`."""

    def __init__(self, session: Session, ring: int = CORRECTION_RING):
        if ring < 1:
            raise ValueError(f"correction ring {ring} must hold at least 1 event")
        self.session = session
        self.agents = {agent.id: AgentState(agent.id, agent.kind.value) for agent in session.agents}
        self.events: deque[dict[str, Any]] = deque(maxlen=ring)
        self.event_count = 0  # events ever seen, so the page can tell new ones from old
        self.applied = 0
        self.unknown_agents = 0  # messages about an agent the session does not have
        self.not_finite = 0  # poses with a NaN or infinite position, not shown
        self.has_truth = False

    def apply(self, message: Any, now_ns: int, is_input: bool = False) -> None:
        """Take one message (hub input or output, truth, status) the view was handed at `now_ns`."""
        agent = self.agents.get(getattr(message, "agent_id", ""))
        if agent is None:
            self.unknown_agents += 1
            return
        self.applied += 1
        if is_input:
            agent.last_input_ns = now_ns
        name = messages.type_name(message)
        if name in ("EstimatedPose", "TruthPose") and not (math.isfinite(message.x_m) and math.isfinite(message.y_m)
                                                           and math.isfinite(message.heading_rad)):
            self.not_finite += 1
            return
        if name == "EstimatedPose":
            self._pose(agent, message, is_input)
        elif name == "TruthPose":
            self.has_truth = True
            agent.truth = {"t_ns": message.timestamp_ns, "x": message.x_m, "y": message.y_m,
                           "heading": message.heading_rad}
            if agent.truth_history and message.timestamp_ns < agent.truth_history[-1][0]:
                agent.truth_history.clear()  # the session went back in time (a new replay): start over
            agent.truth_history.append((message.timestamp_ns, message.x_m, message.y_m))
        elif name == "Correction":
            self._correction(agent, message, now_ns)
        elif name == "StandScan":
            self._event(agent, "qr", message.timestamp_ns, now_ns, finite(message.x_m), finite(message.y_m),
                        source=message.stand_id if message.accepted else f"refused: {message.reason}")
        elif name == "DeviceStatus":
            agent.status[message.sensor_id] = {
                "connected": message.connected,
                "battery_pct": None if message.battery_pct < 0 else finite(message.battery_pct),
                "last_sample_age_s": None if message.last_sample_age_s < 0 else finite(message.last_sample_age_s),
                "flags": list(message.flags), "received_ns": now_ns}

    def _pose(self, agent: AgentState, pose: Any, is_input: bool) -> None:
        entry = {"t_ns": pose.timestamp_ns, "x": pose.x_m, "y": pose.y_m, "heading": pose.heading_rad,
                 "ellipse": ellipse(pose.covariance), "correction_sequence": pose.correction_sequence}
        if pose.track == messages.Track.REFINED:
            agent.refined = entry
        elif not is_input or agent.live is None or agent.live.get("from_edge"):
            # The hub's live pose wins; an edge's own pose only stands in until the hub has spoken.
            entry["from_edge"] = is_input
            agent.live = entry
            agent.pose_history.append((pose.timestamp_ns, pose.x_m, pose.y_m))

    def _correction(self, agent: AgentState, correction: Any, now_ns: int) -> None:
        kind = KIND_NAMES.get(correction.kind, "unknown")
        agent.corrections[kind] = agent.corrections.get(kind, 0) + 1
        # Where the agent was measured to be: its pose at the correction's time plus the shift.
        dx, dy = finite(correction.dx_m), finite(correction.dy_m)
        then = agent.pose_at(correction.timestamp_ns)
        x, y = (then[0] + dx, then[1] + dy) if then and dx is not None and dy is not None else (None, None)
        self._event(agent, kind, correction.timestamp_ns, now_ns, x, y,
                    source=correction.source_id or correction.other_agent_id,
                    shift=[dx, dy] if dx is not None and dy is not None else None, sequence=correction.sequence)

    def _event(self, agent: AgentState, kind: str, time_ns: int, now_ns: int, x: float | None, y: float | None,
               **extra: Any) -> None:
        self.event_count += 1
        self.events.append({"n": self.event_count, "agent": agent.agent_id, "kind": kind, "t_ns": time_ns,
                            "received_ns": now_ns, "x": x, "y": y, **extra})

    def score(self) -> None:
        """Error of each agent's newest live pose that truth covers, against truth at its time; into the
        running mean. Poses and truth come by different routes (through the hub, or not) in either
        order: a pose ahead of the newest truth waits for it, so both are taken at one instant."""
        for agent in self.agents.values():
            if not agent.truth_history:
                continue
            newest_truth_ns = agent.truth_history[-1][0]
            live = next((p for p in reversed(agent.pose_history) if p[0] <= newest_truth_ns), None)
            if live is None or live[0] == agent.scored_ns:
                continue
            truth = agent.truth_at(live[0])
            if truth is None:
                continue
            agent.scored_ns = live[0]
            agent.error_m = math.hypot(live[1] - truth[0], live[2] - truth[1])
            agent.error_sum_m += agent.error_m
            agent.error_count += 1

    def snapshot(self, now_ns: int) -> dict[str, Any]:
        """The page's state: plain JSON values (None where unknown), ages in seconds at `now_ns`."""
        agents = {}
        for agent in self.agents.values():
            status = {sensor: {**values, "age_s": (now_ns - values["received_ns"]) / 1e9}
                      for sensor, values in sorted(agent.status.items())}
            agents[agent.agent_id] = {
                "kind": agent.kind, "live": agent.live, "refined": agent.refined, "truth": agent.truth,
                "error_m": agent.error_m,
                "mean_error_m": agent.error_sum_m / agent.error_count if agent.error_count else None,
                "scored": agent.error_count, "status": status,
                "input_age_s": None if agent.last_input_ns is None else (now_ns - agent.last_input_ns) / 1e9,
                "corrections": dict(agent.corrections)}
        return {"type": "state", "now_ns": now_ns, "agents": agents, "events": list(self.events),
                "event_count": self.event_count, "has_truth": self.has_truth, "not_finite": self.not_finite}


def venue_description(session: Session) -> dict[str, Any]:
    """What the page draws once: the court or the floor plan, beacons, stands, map points, agents."""
    venue = session.venue
    walkers = any(agent.kind is AgentKind.PEDESTRIAN for agent in session.agents)
    return {
        "type": "venue", "name": venue.name, "length_m": venue.court_length_m, "width_m": venue.court_width_m,
        "layout": "floor" if walkers or venue.floor_plan or venue.map_points else "court",
        "sport": "swim" if any(agent.kind is AgentKind.SWIMMER for agent in session.agents) else "court",
        "beacons": [{"id": b.id, "x": b.x_m, "y": b.y_m, "radius_m": b.radius_m} for b in venue.beacons],
        "stands": [{"id": s.id, "x": s.x_m, "y": s.y_m, "heading_deg": s.heading_deg} for s in venue.stands],
        "map_points": [{"id": p.id, "x": p.x_m, "y": p.y_m} for p in venue.map_points],
        "floor_plan": [[[list(map(float, point)) for point in ring] for ring in polygon] for polygon in venue.floor_plan],
        "agents": [{"id": agent.id, "kind": agent.kind.value} for agent in session.agents],
    }

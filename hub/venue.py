"""The hub's whole job at a venue: the chairs' corrections, the pedestrians' map matching
(hub/pedestrian/hub.py) and who is which camera track.

`hub.chair.hub.ChairHub` corrects the wheelchairs (beacons, collisions, fixes); once a camera's
first frame arrives, `hub.identity.engine.IdentityEngine` names its tracks from every agent's motion and
its identified positions go to ChairHub as video fixes, like an operator's. Same interface as
ChairHub: `on_message(message, arrival_ns) -> outputs`, `flush()`, `key_for(output)`. `clock`, if the
caller gives one (a wall clock in seconds), times the identity engine's hops (`IdentityEngine.update_s`).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from hub.chair.hub import ChairHub, HubSettings
from hub.chair.view import STALE_MPS
from hub.identity.engine import IdentityEngine, IdentitySettings
from hub.inputs import check_pose
from hub.pedestrian.hub import PedestrianHub
from protocol import keys, messages
from protocol.session import Session

_TRACK_IDENTITY, _CAMERA_FRAME = messages.CLASSES["TrackIdentity"], messages.CLASSES["CameraFrame"]
_ESTIMATED_POSE = messages.CLASSES["EstimatedPose"]


class VenueHub:
    def __init__(self, session: Session, settings: HubSettings = HubSettings(),
                 identity_settings: IdentitySettings = IdentitySettings(),
                 clock: Callable[[], float] | None = None):
        self.session = session
        self.chairs = ChairHub(session, settings)
        self.pedestrians = PedestrianHub(session)
        self.identity_settings = identity_settings
        self.clock = clock
        self.identity: IdentityEngine | None = None

    @property
    def agents(self) -> dict:
        return self.chairs.agents

    @property
    def counters(self) -> Any:
        return self.chairs.counters

    def on_message(self, message: Any, arrival_ns: int) -> list[Any]:
        camera = type(message) is _CAMERA_FRAME
        if camera and self.identity is None and "camera" in self.chairs.settings.corrections:
            self.identity = IdentityEngine(self.session, self.identity_settings, pose_of=self._pose_of,
                                           clock=self.clock)
        if self.identity is None:  # the usual case
            return [] if camera else self._to_its_kind(message, arrival_ns)
        if type(message) is _ESTIMATED_POSE:
            check_pose(message)  # before the identity engine takes it in, not only the agent's own hub
        out: list[Any] = []
        for produced in self.identity.on_message(message):
            if messages.type_name(produced) == "PositionFix":
                out += self.chairs.on_message(produced, arrival_ns)  # [] for an agent that is not a chair
            else:
                out.append(produced)
        if not camera:
            out += self._to_its_kind(message, arrival_ns)
        return out

    def _to_its_kind(self, message: Any, arrival_ns: int) -> list[Any]:
        """An agent's message to the hub of its kind (each ignores the other's agents)."""
        agent_id = message.agent_id
        if agent_id in self.chairs.agents:
            return self.chairs.on_message(message, arrival_ns)
        return self.pedestrians.on_message(message) if agent_id in self.pedestrians.agents else []

    def flush(self) -> list[Any]:
        return self.chairs.flush() + self.pedestrians.flush()

    def key_for(self, message: Any) -> str:
        if type(message) is _TRACK_IDENTITY:
            return keys.identity(self.session.venue.name, message.agent_id)
        if message.agent_id in self.pedestrians.agents:
            return self.pedestrians.key_for(message)
        return self.chairs.key_for(message)

    def _pose_of(self, agent_id: str, time_ns: int) -> tuple[np.ndarray, float] | None:
        """A chair's live position at `time_ns` and its sd: the edge's covariance, what it is missing
        (hub/chair/hub.py), and how far the chair may have gone since that pose if its poses have not
        reached `time_ns` yet (a device's link stalls, a burst)."""
        view = self.chairs.agents.get(agent_id)
        pose = view.pose_at(time_ns) if view is not None else None
        if pose is None:
            return None
        honest = pose[1] + view.extra
        stale_m = STALE_MPS * max(time_ns - view.latest_ns, 0) * 1e-9 if view.latest_ns is not None else 0.0
        return pose[0], float(np.hypot(np.sqrt(max(np.linalg.eigvalsh(honest).max(), 0.0)), stale_m))

"""The structural rules of the identity engine (hub/identity/engine.py): what it does about the tracker's own errors.

A camera's tracker breaks tracks off and starts new ones, swaps the ids of people who meet and merges
them into one track. Four rules follow these errors (docs/identity.md): a new track that starts where an
agent's broken-off track was heading (and where the hub has it) continues that identity and its
evidence in its first frame (`continue_tracks`), and so does one where the hub surely places a chair
that has no track, e.g. at the start of play (`_births`); tracks that meet may swap or merge, so the evidence
of the chairs involved restarts from the meeting (`encounters`); an agent whose track ends inside
a held one shares it until they part (`share`).

`TrackRules` is a part of the engine: it is given the engine's tracks, lost tracks and counters (the
same objects, which both change in place) and returns the TrackIdentity messages its rules decide.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from hub.identity.book import Lost, Track, identity_message
from hub.identity.cues import BIN_NS, BIN_S, AgentCues
from hub.identity.settings import IdentityCounters, IdentitySettings

START_SD_M = 0.1  # a chair's edge starts its filter at the session's start position with this sd


class TrackRules:
    """Continuation, births, encounters and shares: the rules that follow a tracker's errors, over the
    engine's own records (`tracks`, `lost`, `counters`: shared with it, changed in place)."""

    def __init__(self, settings: IdentitySettings, agents: list[AgentCues], is_chair: np.ndarray,
                 start_xy: dict[int, np.ndarray], tracks: dict[tuple[str, int], Track], lost: dict[int, Lost],
                 counters: IdentityCounters,
                 pose_of: Callable[[str, int], tuple[np.ndarray, float] | None] | None = None):
        self.settings = settings
        self.agents = agents
        self.is_chair = is_chair
        self.start_xy = start_xy  # where each chair's edge starts its filter, for births before its first pose
        self.tracks = tracks
        self.lost = lost
        self.counters = counters
        self.pose_of = pose_of  # the hub's (xy, sd) of an agent at a venue time, when it has one

    def _identity(self, agent: int, camera: str, track_id: int, score: float, now_ns: int) -> Any:
        return identity_message(self.agents[agent].agent_id, camera, track_id, score, now_ns)

    # -- continuation: a track that breaks off and comes back under a new id ------------------

    def continue_tracks(self, camera: str, new: list[tuple[str, int]], now_ns: int) -> list[Any]:
        """A new track inherits an agent's identity (and evidence) in its first frame when it starts where
        that agent's broken-off track was heading and, for an agent the hub places, where the hub has it;
        only if it is the one new track there, that agent the one candidate, and no other live track is
        within continue_clear_m (a second detection of someone tracked, or a split, starts next to them)."""
        s = self.settings
        if s.continue_max_s <= 0:
            return []
        holders = {t.agent: k for k, t in self.tracks.items() if t.agent >= 0}
        candidates: dict[int, Lost] = {}
        for i, lost in list(self.lost.items()):
            if now_ns - lost.last_ns > s.continue_max_s * 1e9:
                del self.lost[i]
            elif lost.camera == camera and i not in holders:
                candidates[i] = lost
        for i, key in holders.items():
            track = self.tracks[key]
            if key[0] == camera and track.cues.last_ns < now_ns:  # held, but not in this frame: it broke off
                candidates[i] = Lost.of(camera, track)
        out = self._end_shares(camera, new, now_ns)
        fresh = set(new)
        live = np.array([t.cues.latest_xy for k, t in self.tracks.items()
                         if k[0] == camera and t.cues.last_ns == now_ns and k not in fresh]).reshape(-1, 2)
        candidates.update(self._births(candidates, holders, live, now_ns))
        if not candidates:
            return out
        matches: dict[tuple[str, int], list[int]] = {}
        for key in new:
            xy = self.tracks[key].cues.latest_xy
            if len(live) and np.hypot(*(live - xy).T).min() < s.continue_clear_m:
                continue
            height = self.tracks[key].cues.latest_height
            matches[key] = [i for i, lost in candidates.items() if self._continues(i, lost, xy, now_ns)
                            and not abs(height - lost.height_m) > s.continue_height_m]  # NaN: no heights, no test
        poses = [self.pose_of(cues.agent_id, now_ns) if self.pose_of else None for cues in self.agents]
        for key, agents in matches.items():
            i = agents[0] if len(agents) == 1 else -1
            if i >= 0 and poses[i] is not None:  # ... and the hub expects nobody else nearly as close to it
                xy = self.tracks[key].cues.latest_xy
                mine = np.hypot(*(xy - poses[i][0]))
                if any(j != i and pose is not None and np.hypot(*(xy - pose[0])) < mine + s.continue_margin_m
                       for j, pose in enumerate(poses)):
                    agents.append(-1)
        per_agent: dict[int, int] = {}
        for agents in matches.values():
            for i in agents:
                per_agent[i] = per_agent.get(i, 0) + 1
        for key, agents in matches.items():
            if len(agents) != 1 or per_agent[agents[0]] != 1:
                continue
            i = agents[0]
            lost = candidates[i]
            if i in holders:
                self.tracks[holders[i]].agent = -1  # its drop, later, says nothing: the new identity replaces it
            track = self.tracks[key]
            track.cost_sum, track.cost_count = lost.cost_sum.copy(), lost.cost_count.copy()
            track.course = None if lost.course is None else lost.course.copy()
            track.agent, track.held_since_ns = i, now_ns
            self.lost.pop(i, None)
            self.unshare(i)
            self.counters.continuations += 1
            self.counters.births += lost.camera == ""
            self.counters.identity_changes += 1
            out.append(self._identity(i, camera, key[1], 0.0, now_ns))
        return out

    def _end_shares(self, camera: str, new: list[tuple[str, int]], now_ns: int) -> list[Any]:
        """A new track next to a shared (merged) one: the merge has split, and its sharers lose it."""
        out = []
        for key, track in self.tracks.items():
            if key[0] != camera or not track.sharers:
                continue
            here = track.cues.latest_xy
            if any(np.hypot(*(self.tracks[k].cues.latest_xy - here)) < self.settings.encounter_m for k in new):
                out += [self._identity(i, camera, 0, 0.0, now_ns) for i in track.sharers]
                track.sharers.clear()
        return out

    def _births(self, candidates: dict[int, Lost], holders: dict[int, tuple[str, int]], live: np.ndarray,
                now_ns: int) -> dict[int, Lost]:
        """Chairs with no track and no broken-off one that the hub places surely (sd <= birth_sd_m; at the
        start of play every chair, from its known start): a new track where the hub has one continues it
        as if its track had broken off there, standing (the same rules then decide). Not while a live
        track is already near that pose: the chair may be on it, unclaimed, and the new track someone
        else (a referee, a second detection)."""
        s = self.settings
        if s.birth_sd_m <= 0 or self.pose_of is None:
            return {}
        sharing = {i for t in self.tracks.values() for i in t.sharers}
        out = {}
        for i in np.flatnonzero(self.is_chair):
            i = int(i)
            if i in candidates or i in holders or i in sharing:
                continue
            pose = self.pose_of(self.agents[i].agent_id, now_ns)
            if pose is None:
                pose = (self.start_xy[i], START_SD_M)
            if pose[1] > s.birth_sd_m:
                continue
            if len(live) and np.hypot(*(live - pose[0]).T).min() < s.continue_gate_m + 3.0 * pose[1]:
                continue
            zeros = np.zeros((2, len(self.agents)))
            out[i] = Lost("", now_ns, np.asarray(pose[0], dtype=float), np.full(2, np.nan), zeros, zeros.copy())
        return out

    def _continues(self, i: int, lost: Lost, xy: np.ndarray, now_ns: int) -> bool:
        s = self.settings
        gap_s = max(now_ns - lost.last_ns, 0) * 1e-9
        velocity = np.where(np.isfinite(lost.velocity), lost.velocity, 0.0)
        heading = lost.xy + velocity * min(gap_s, s.continue_coast_s)
        if np.hypot(*(xy - heading)) > s.continue_gate_m + s.continue_spread_mps * gap_s:
            return False
        pose = self.pose_of(self.agents[i].agent_id, now_ns) if self.pose_of else None
        return pose is None or bool(np.hypot(*(xy - pose[0])) <= s.continue_gate_m + 3.0 * pose[1])

    # -- encounters and merges: tracks that meet may swap or merge ---------------------------

    def encounters(self, gone: list[tuple[str, int]], keys: list[tuple[str, int]], first: int,
                    now_ns: int) -> list[tuple[int, tuple[str, int]]]:
        """Tracks that came within encounter_m of each other since the last hop may have swapped or merged
        (a tracker errs only there): once the bins being scored are past their meeting, the evidence of
        the agents involved restarts, so who is who after it is decided by what follows. A held track
        that ends next to another (a merge, an occlusion) adds its agent to that one's encounter, and
        shares the nearest held one (returned: (agent, track key)) while the encounter lasts."""
        s = self.settings
        shares: list[tuple[int, tuple[str, int]]] = []
        if s.encounter_m <= 0 or not keys:
            return shares
        tracks = [self.tracks[k] for k in keys]
        bin_now = now_ns // BIN_NS
        span = int(round(s.hop_s / BIN_S)) + 1  # the bins since the last hop
        back = span + int(np.ceil(s.track_timeout_s / BIN_S)) + 1  # ... and back to where a dropped track ended
        lo = bin_now - back + 1
        xy = np.stack([t.cues.ring.block(lo, back)[:2] for t in tracks])  # (T, x/y, bins)
        x, y = xy[:, 0, -span:], xy[:, 1, -span:]
        with np.errstate(invalid="ignore"):
            near = np.hypot(x[:, None] - x[None], y[:, None] - y[None]) < s.encounter_m  # (T, T, bins); NaN: False
        np.einsum("iik->ik", near)[:] = False
        pairs = np.nonzero(np.triu(near.any(axis=2)))
        lasts = bin_now - np.argmax(near[pairs][:, ::-1], axis=1)  # the last bin each pair was near
        for a, b, last in zip(*pairs, lasts):
            members = {t.agent for t in (tracks[a], tracks[b]) if t.agent >= 0}
            for t in (tracks[a], tracks[b]):
                self._join(t, members, int(last))
        for key in gone:
            ended = self.tracks[key]
            last_bin = ended.cues.last_ns // BIN_NS
            if ended.agent < 0 or not lo <= last_bin <= bin_now:
                continue
            there = xy[:, :, last_bin - lo]
            with np.errstate(invalid="ignore"):
                close = np.hypot(*(there - ended.cues.latest_xy).T) < s.encounter_m
            for row in np.flatnonzero(close):
                self._join(tracks[row], {ended.agent}, last_bin)
            # a merge: the merged track (at the people's centroid) is within share_m of where this one
            # ended, and no track has started next to it since (that would be its continuation)
            with np.errstate(invalid="ignore"):
                inside = np.hypot(*(there - ended.cues.latest_xy).T) < s.share_m
            held = [row for row in np.flatnonzero(inside) if tracks[row].agent >= 0]
            successor = any(t.born_ns > ended.cues.last_ns
                            and np.hypot(*(t.cues.latest_xy - ended.cues.latest_xy)) < s.encounter_m for t in tracks)
            if s.share_merges and held and not successor:
                distance = np.hypot(*(there[held] - ended.cues.latest_xy).T)
                shares.append((ended.agent, keys[held[int(np.argmin(distance))]]))
        for t in tracks:
            if t.encounter and first > t.close_bin:
                for i in t.encounter:
                    keep = s.encounter_keep if i == t.agent else 0.0
                    t.cost_sum[:, i] *= keep
                    t.cost_count[:, i] *= keep
                    if t.course is not None and i != t.agent:  # the holder's usual angle is its chair's heading error
                        t.course[:, i] = 0.0
                t.encounter.clear()
                self.counters.encounters += 1
                for i in t.sharers:  # the merge is over: whoever shared it has no track until one is claimed
                    shares.append((i, None))
                t.sharers.clear()
        return shares

    def share(self, camera: str, shares: list, now_ns: int) -> list[Any]:
        """A merged track shows its holder and whoever's track ended inside it: those share it (many to
        one) until the merge ends; they get no fixes from it and stay free to claim tracks of their own."""
        out = []
        holding = {t.agent for t in self.tracks.values() if t.agent >= 0}
        for i, key in shares:
            if i in holding:
                continue
            if key is None:
                if not any(i in t.sharers for t in self.tracks.values()):
                    out.append(self._identity(i, camera, 0, 0.0, now_ns))
                continue
            if key not in self.tracks:
                continue
            self.unshare(i)
            self.tracks[key].sharers.add(i)
            self.counters.shares += 1
            out.append(self._identity(i, camera, key[1], 0.0, now_ns))
        return out

    def unshare(self, agent: int) -> None:
        for t in self.tracks.values():
            t.sharers.discard(agent)

    def _join(self, track: Track, agents: set[int], last_bin: int) -> None:
        """Agents that may now be on this track: their evidence on it restarts at once (what it showed before
        they met was someone else), the holder's at the end of the encounter. Only chairs: their dead-
        reckoned motion names them again within a second or two, while a pedestrian's weak cues need
        many seconds, and pedestrians in a room meet all the time (restarting them too: 42.6 % live in the
        paper's room against 48.5 %)."""
        agents = {i for i in agents if self.is_chair[i]}
        for i in agents - track.encounter - {track.agent}:
            track.cost_sum[:, i] = track.cost_count[:, i] = 0.0
            if track.course is not None:
                track.course[:, i] = 0.0
            if track.since_bin is None:
                track.since_bin = np.full(len(self.agents), -(2**62), dtype=np.int64)
            track.since_bin[i] = last_bin  # bins still to be scored from before they met do not count either
        track.encounter |= agents | ({track.agent} if track.agent >= 0 and self.is_chair[track.agent] else set())
        track.close_bin = max(track.close_bin, last_bin)

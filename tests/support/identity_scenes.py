"""Crafted scenes for the identity tests: people on given paths, their waist IMUs, a camera's tracks.

The IMU is the minimum the cues need, built from the path: gravity on z plus a vertical gait
oscillation at 1.9 Hz whose amplitude grows with speed (the camera-identity paper's relation), and
the turn rate on the gyro's z. Each person's steps start at their own phase (`phases`), and a camera
that reports head heights sees the head bob with them (`bob_m`). Tracks follow the paths with noise; which person a track follows
over time is given explicitly, so a scene can switch, merge or invent tracks.
"""

from __future__ import annotations

import numpy as np

from hub.identity.engine import IdentityEngine, IdentitySettings
from protocol import messages
from protocol.session import Agent, AgentKind, Mount, Sensor, Session, Venue

S = 1_000_000_000
IMU_HZ = 100.0
FPS = 20.0


def session(people: list[str], length_m: float = 5.6, width_m: float = 3.0, chairs: bool = False) -> Session:
    """Pedestrians with a waist sensor, or (chairs) wheelchairs with a seat sensor, named by `sensor_id`."""
    kind, mount = (AgentKind.WHEELCHAIR, Mount.SEAT) if chairs else (AgentKind.PEDESTRIAN, Mount.WAIST)
    agents = tuple(Agent(p, kind, sensors=(Sensor(sensor_id(p, chairs), mount, rate_hz=IMU_HZ, forward_axis="+x",
                                                  left_axis="+y"),))
                   for p in people)
    return Session(Venue("room", length_m, width_m), agents)


def sensor_id(person: str, chairs: bool = False) -> str:
    return f"{person}-seat" if chairs else f"{person}-waist"


def edge_poses(agent_id: str, times: np.ndarray, xy: np.ndarray, offset_m: tuple[float, float],
               rate_hz: float = 25.0) -> list[tuple[int, object]]:
    """(arrival_ns, EstimatedPose) as a chair's edge would publish them: the path shifted by a drift."""
    velocity = np.gradient(xy, times, axis=0)
    heading = np.arctan2(velocity[:, 1], velocity[:, 0])
    out = []
    for k in range(0, len(times), int(IMU_HZ / rate_hz)):
        pose = messages.new("EstimatedPose", timestamp_ns=int(times[k] * S), agent_id=agent_id,
                            x_m=float(xy[k, 0] + offset_m[0]), y_m=float(xy[k, 1] + offset_m[1]),
                            heading_rad=float(heading[k]), covariance=[0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.01],
                            method="reckon", track=messages.Track.LIVE)
        out.append((int(times[k] * S) + 25_000_000, pose))
    return out


def waypoints_path(points: list[tuple[float, float, float]], rate_hz: float = IMU_HZ) -> tuple[np.ndarray, np.ndarray]:
    """(time_s, xy) sampled at rate_hz through (t, x, y) waypoints, smoothed so speed changes gently."""
    times = np.arange(points[0][0], points[-1][0], 1.0 / rate_hz)
    xy = np.column_stack([np.interp(times, [p[0] for p in points], [p[1] for p in points]),
                          np.interp(times, [p[0] for p in points], [p[2] for p in points])])
    kernel = np.hanning(int(0.6 * rate_hz))
    kernel /= kernel.sum()
    pad = len(kernel)
    padded = np.vstack([np.repeat(xy[:1], pad, 0), xy, np.repeat(xy[-1:], pad, 0)])
    smooth = np.column_stack([np.convolve(padded[:, k], kernel, mode="same") for k in range(2)])[pad:-pad]
    return times, smooth


def gait_phase(times: np.ndarray, xy: np.ndarray, start_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(speed m/s, step phase rad) along a path: the phase advances at 1.9 Hz while walking."""
    velocity = np.gradient(xy, times, axis=0)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    return speed, start_rad + 2 * np.pi * np.cumsum(np.where(speed > 0.2, 1.9, 0.0)) / IMU_HZ


def imu_batches(agent_id: str, times: np.ndarray, xy: np.ndarray, rng: np.random.Generator,
                gait_g_per_mps: float = 0.18, clock_offset_s: float = 0.0, chairs: bool = False,
                phase_rad: float = 0.0) -> list[tuple[int, object]]:
    """(arrival_ns, ImuBatch) every 0.2 s for a waist sensor on this path, its steps from `phase_rad`."""
    velocity = np.gradient(xy, times, axis=0)
    speed, phase = gait_phase(times, xy, phase_rad)
    heading = np.unwrap(np.arctan2(velocity[:, 1], velocity[:, 0]))
    turn_dps = np.degrees(np.gradient(heading, times)) * (speed > 0.2)
    accel = np.zeros((len(times), 3))
    accel[:, 2] = 1.0 + gait_g_per_mps * speed * np.sin(phase) + rng.normal(0, 0.01, len(times))
    accel[:, 0] = 0.05 * speed * np.sin(phase / 2) + rng.normal(0, 0.01, len(times))
    gyro = rng.normal(0, 0.5, (len(times), 3))
    gyro[:, 2] += turn_dps
    device_ns = ((times + clock_offset_s) * S).astype(np.int64)
    out = []
    step = int(0.2 * IMU_HZ)
    for k, start in enumerate(range(0, len(times), step)):
        part = slice(start, start + step)
        batch = messages.imu_batch(agent_id, sensor_id(agent_id, chairs), k, device_ns[part], accel[part], gyro[part], None)
        arrival = int(times[part][-1] * S) + 20_000_000
        batch.received_ns = arrival
        out.append((arrival, batch))
    return out


def camera_frames(paths: dict[str, tuple[np.ndarray, np.ndarray]], tracks: list[tuple[int, str, float, float]],
                  rng: np.random.Generator, noise_m: float = 0.05, end_s: float | None = None,
                  camera: str = "cam1", heights: dict[str, float] | None = None,
                  height_noise_m: float = 0.03, bob_m: float = 0.0,
                  phases: dict[str, float] | None = None) -> list[tuple[int, object]]:
    """(arrival_ns, CameraFrame) at FPS. `tracks`: (track id, person or "a+b" merge or "" false, start s, end s).
    With `heights` (person -> head height, m) the frames report each track's height as a stereo tracker
    does (a merge at its people's mean, a false track at 1.7 m), with `height_noise_m` per frame; the
    head bobs `bob_m` with each person's steps (their `phases`, as imu_batches), down as the waist's
    acceleration is up."""
    bob = {p: (t_xy[0], *gait_phase(t_xy[0], t_xy[1], (phases or {}).get(p, 0.0))) for p, t_xy in paths.items()} \
        if bob_m else {}
    end_s = end_s if end_s is not None else max(t[3] for t in tracks)
    out = []
    wander = {}
    for k, t in enumerate(np.arange(0.0, end_s, 1.0 / FPS)):
        ids, xs, ys, hs = [], [], [], []
        for track_id, who, start, end in tracks:
            if not start <= t < end:
                continue
            if who == "":
                centre = wander.setdefault(track_id, np.array([2.8, 1.5]))
                centre += rng.normal(0, 0.03, 2)
                position = centre
            else:
                people = who.split("+")
                position = np.mean([[np.interp(t, paths[p][0], paths[p][1][:, j]) for j in range(2)] for p in people], axis=0)
            ids.append(track_id)
            xs.append(float(position[0] + rng.normal(0, noise_m)))
            ys.append(float(position[1] + rng.normal(0, noise_m)))
            if heights is not None:
                tall = np.mean([heights[p] + _bob_at(bob, p, t, bob_m) for p in who.split("+")]) if who else 1.7
                hs.append(float(tall + rng.normal(0, height_noise_m)))
        frame = messages.new("CameraFrame", timestamp_ns=int(t * S), camera_id=camera, frame=k + 1, track_id=ids,
                             x_m=xs, y_m=ys, position_sd_m=noise_m, height_m=hs)
        out.append((int(t * S) + 30_000_000, frame))
    return out


def _bob_at(bob: dict, person: str, t: float, bob_m: float) -> float:
    if person not in bob:
        return 0.0
    times, speed, phase = bob[person]
    k = min(int(np.searchsorted(times, t)), len(speed) - 1)
    return -bob_m * min(float(speed[k]), 1.5) / 1.5 * float(np.sin(phase[k]))


def write_scene(path, paths: dict[str, tuple[np.ndarray, np.ndarray]], tracks: list[tuple[int, str, float, float]],
                end_s: float, seed: int = 1) -> None:
    """The scene as a session log: truth poses, IMU batches, camera frames and their truth labels."""
    from protocol import keys
    from protocol.session_log import SessionWriter

    rng = np.random.default_rng(seed)
    scene = session(list(paths))
    items = []
    for person, (times, xy) in paths.items():
        for arrival, batch in imu_batches(person, times, xy, rng):
            items.append((arrival, keys.imu("room", person, batch.sensor_id), batch))
        for k in range(0, len(times), int(IMU_HZ / 20)):
            items.append((int(times[k] * S), keys.truth("room", person),
                          messages.new("TruthPose", timestamp_ns=int(times[k] * S), agent_id=person,
                                       x_m=float(xy[k, 0]), y_m=float(xy[k, 1]))))
    for arrival, frame in camera_frames(paths, tracks, rng, end_s=end_s):
        items.append((arrival, keys.camera_tracks("room", "cam1"), frame))
        who = {track_id: person for track_id, person, start, end in tracks}
        label = messages.new("TruthTrackLabel", timestamp_ns=frame.timestamp_ns, camera_id="cam1", frame=frame.frame,
                             track_id=list(frame.track_id), person_id=[who[t] for t in frame.track_id])
        items.append((arrival, keys.camera_truth("room", "cam1"), label))
    items.sort(key=lambda item: item[0])
    with SessionWriter(path, scene) as writer:
        for log_ns, topic, message in items:
            writer.write(topic, message, log_ns)


# The crossing scene: three people on waypoint paths for 30 s in the room; a and b cross at about 6 s.
CROSSING = {
    "a": waypoints_path([(0, 0.5, 1.0), (2, 0.5, 1.0), (8, 5.0, 2.0), (11, 5.0, 2.0), (16, 1.0, 0.6), (20, 1.0, 0.6),
                         (26, 4.5, 2.5), (30, 4.5, 2.5)]),
    "b": waypoints_path([(0, 5.0, 1.0), (3, 5.0, 1.0), (9, 0.6, 2.0), (12, 2.5, 2.5), (15, 2.5, 2.5), (21, 5.0, 0.5),
                         (30, 5.0, 0.5)]),
    "c": waypoints_path([(0, 2.8, 0.4), (5, 2.8, 0.4), (7, 2.0, 1.5), (13, 2.0, 1.5), (18, 4.0, 1.0), (24, 1.5, 2.5),
                         (30, 1.5, 2.5)]),
}


def run(paths: dict, tracks: list, seed: int = 1, end_s: float = 30.0, settings: IdentitySettings = IdentitySettings(),
        pose_of=None):
    """Feed a scene in arrival order; returns (engine, [(time s, agent, track id)] identity changes)."""
    rng = np.random.default_rng(seed)
    events = [e for p, (t, xy) in paths.items() for e in imu_batches(p, t, xy, rng)]
    events += camera_frames(paths, tracks, rng, end_s=end_s)
    events.sort(key=lambda e: e[0])
    engine = IdentityEngine(session(list(paths)), settings, pose_of=pose_of)
    changes = []
    for _, message in events:
        for out in engine.on_message(message):
            if out.DESCRIPTOR.name == "TrackIdentity":
                changes.append((out.timestamp_ns / S, out.agent_id, out.track_id))
    return engine, changes


def holder_at(changes: list, agent: str, time_s: float) -> int:
    """The track id the agent had at time_s (0: none)."""
    held = 0
    for t, who, track in changes:
        if who == agent and t <= time_s:
            held = track
    return held

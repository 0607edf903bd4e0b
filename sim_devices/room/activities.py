"""Where each person goes: activities chosen one after another, and the pelvis path they make.

Each person runs a small state machine (the paper's protocol, sec. 3.1 and 4.2: walk forwards,
backwards and sideways, stand still, turn, sit on one of the chairs and rise, freely). A walk has a
target inside the room and a cruise speed; the commanded velocity slows for the stop
(v = sqrt(2 a d)), bends around people ahead (never into them: a hard minimum distance of two body
radii) and changes at most `people.accel_mps2`. Heading follows the travel direction for forward
walks (a walker turns before setting off), stays for backward and sideways walks, and is turned with
a smooth, rate-limited controller. Sitting: walk to the spot in front of a free chair, turn to face
away from it, sit down (the pelvis moves back onto the seat), sit, rise. Leaving (the paper's
subjects B and C): a chosen wearer, when their time comes, walks out through the nearest wall,
waits out of the cameras' view for their absence and walks back in (`away.*`).

The loop runs at the IMU rate over all people at once; choices are made only when an activity ends.
The pelvis path is then low-pass filtered (zero phase) so its acceleration is that of a body, not of
the controller's corners; the gait's within-step motion is added later (gait.py).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

from sim_devices.room.params import RoomParams, away_shares, chair_count, room_size
from sim_devices.room.person import Person

CONTROL_HZ = 25.0  # controller rate; the path is interpolated to the IMU rate and low-passed
PATH_CUTOFF_HZ = 1.5  # pelvis path low-pass: walking starts/stops/turns take >= 0.5 s; steps are added later
ARRIVE_M = 0.08  # a walk ends this close to its target, nearly stopped
STOPPED_MPS = 0.08
TURN_DONE_RAD = math.radians(2.0)
TARGET_TRIES = 20
MIN_STEP_WALK_M = 0.3  # a backward or sideways walk shorter than this (near a wall) becomes a turn


class Activity(enum.IntEnum):
    STAND = 0
    WALK_FORWARD = 1
    WALK_BACKWARD = 2
    WALK_SIDEWAYS = 3
    TURN = 4
    SIT_DOWN = 5
    SEATED = 6
    STAND_UP = 7
    AWAY = 8  # outside the sensing area (the cameras' view), waiting to come back


WALKS = (Activity.WALK_FORWARD, Activity.WALK_BACKWARD, Activity.WALK_SIDEWAYS)


@dataclass(frozen=True)
class Chair:
    x_m: float  # seat (pelvis position when seated)
    y_m: float
    facing_rad: float  # a seated person faces this way


@dataclass(frozen=True)
class Transition:
    """A sit-down (down=True) or stand-up over samples [start, end)."""

    person: int
    start: int
    end: int
    down: bool


@dataclass
class Plan:
    """The pelvis path of every person, (n, people) arrays at the IMU rate."""

    time_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray  # facing, unwrapped (continuous)
    activity: np.ndarray  # int8 Activity codes
    transitions: list[Transition]
    chairs: list[Chair]
    room_m: tuple[float, float]


def place_chairs(people: int, params: RoomParams) -> list[Chair]:
    """Chairs against the long walls, alternating sides, spread along the room, facing into it."""
    length, width = room_size(people, params.room)
    margin = params.room.wall_margin_m
    count = chair_count(people, params.room)
    chairs = []
    for index in range(count):
        x = length * (index // 2 + 1) / (math.ceil(count / 2) + 1)
        low = index % 2 == 0
        chairs.append(Chair(x, margin if low else width - margin, math.pi / 2 if low else -math.pi / 2))
    return chairs


class _State:
    """Per-person controller state (fixed-size arrays; lists only for the pending plan of a sit)."""

    def __init__(self, persons: list[Person], start_xy: np.ndarray, start_heading: np.ndarray):
        count = len(persons)
        self.pos = start_xy.copy()
        self.vel = np.zeros((count, 2))
        self.heading = start_heading.copy()
        self.activity = np.full(count, Activity.STAND, dtype=np.int8)
        self.target = start_xy.copy()
        self.goal_heading = start_heading.copy()
        self.cruise = np.zeros(count)
        self.end_s = np.zeros(count)  # STAND/SEATED/transitions: when it ends; walks: when to give up
        self.pending: list[list[tuple[Activity, float]]] = [[] for _ in range(count)]  # (activity, argument)
        self.chair = np.full(count, -1)  # chair reserved or used
        self.from_xy = start_xy.copy()  # transitions: start point
        self.begun_s = np.zeros(count)  # when the current activity started
        self.leave_s = np.full(count, np.inf)  # when a leaver next heads out of the sensing area
        self.absence_s = np.zeros(count)  # how long they stay out of view
        self.outside = np.zeros(count, dtype=bool)  # may be beyond the walls (leaving, away, coming back)


def plan_paths(persons: list[Person], duration_s: float, params: RoomParams, rng: np.random.Generator) -> Plan:
    """Simulate every person's activities for `duration_s`; the plan is at the IMU rate."""
    rate = params.sensors.rate_hz
    control_hz = min(CONTROL_HZ, rate)
    steps = int(math.floor(duration_s * control_hz)) + 2  # one past the end, for interpolation
    dt = 1.0 / control_hz
    length, width = room_size(len(persons), params.room)
    margin = params.room.wall_margin_m
    chairs = place_chairs(len(persons), params)
    owner = np.full(len(chairs), -1)
    state = _State(persons, _start_positions(len(persons), (length, width), params, rng),
                   rng.uniform(-math.pi, math.pi, len(persons)))
    state.end_s[:] = rng.uniform(0.5, 2.0, len(persons))  # everyone stands a moment first, then starts
    _schedule_absences(state, duration_s, params, rng)
    x, y = np.empty((steps, len(persons))), np.empty((steps, len(persons)))
    heading, activity = np.empty((steps, len(persons))), np.empty((steps, len(persons)), dtype=np.int8)
    free = np.empty((steps, len(persons)), dtype=bool)  # allowed beyond the walls at this step
    spans: list[tuple[int, float, float, bool]] = []  # (person, start s, end s, down)
    bounds = (margin, length - margin, margin, width - margin)
    for step in range(steps):
        now = step * dt
        due = (now >= state.leave_s) & np.isin(state.activity, (Activity.STAND, Activity.SEATED))
        state.end_s[due] = np.minimum(state.end_s[due], now)  # time to leave: stop standing, get up
        for person in np.flatnonzero(_finished(state, now)).tolist():
            previous = Activity(int(state.activity[person]))
            if previous in (Activity.SIT_DOWN, Activity.STAND_UP):
                spans.append((person, float(state.begun_s[person]), now, previous is Activity.SIT_DOWN))
            _next_activity(person, state, now, persons[person], chairs, owner, bounds, params, rng)
        _move(state, now, dt, bounds, params)
        x[step], y[step] = state.pos[:, 0], state.pos[:, 1]
        heading[step], activity[step] = state.heading, state.activity
        free[step] = state.outside
    for person in np.flatnonzero(np.isin(state.activity, (Activity.SIT_DOWN, Activity.STAND_UP))).tolist():
        # still running at the end: its planned end lies past the last sample
        spans.append((person, float(state.begun_s[person]), float(state.end_s[person]),
                      bool(state.activity[person] == Activity.SIT_DOWN)))
    time_s = np.arange(int(round(duration_s * rate)) + 1) / rate
    control_s = np.arange(steps) * dt
    columns = range(len(persons))
    x, y, heading = (np.stack([np.interp(time_s, control_s, values[:, i]) for i in columns], axis=1)
                     for values in (x, y, heading))
    nearest = np.minimum(np.floor(time_s * control_hz + 1e-9).astype(np.int64), steps - 1)
    activity, free = activity[nearest], free[nearest]
    transitions = [Transition(person, int(round(start * rate)), int(round(end * rate)), down)
                   for person, start, end, down in spans]
    x, y = _smooth(x, rate), _smooth(y, rate)
    x = np.where(free, x, np.clip(x, margin - 0.05, length - margin + 0.05))
    y = np.where(free, y, np.clip(y, margin - 0.05, width - margin + 0.05))
    return Plan(time_s, x, y, _smooth(heading, rate), activity, transitions, chairs, (length, width))


def _schedule_absences(state: _State, duration_s: float, params: RoomParams, rng: np.random.Generator) -> None:
    """Pick the wearers who leave the sensing area once (away.leaver_share), each absence's length
    (away_shares: the paper's 58 s and 180 s of 297 s for 3 wearers) and when it starts (uniform, with
    5 % of the session free before, 10 % after). A leaver heads out when their current activity ends (after
    rising, if seated) and stays away for the whole absence, beyond `away.beyond_m` past the nearest wall."""
    shares = away_shares(len(state.pos), params.away)
    if not shares:
        return
    leavers = rng.permutation(len(state.pos))[:len(shares)]
    for person, share in zip(leavers.tolist(), shares):
        absence = share * duration_s
        latest = max(0.05 * duration_s, duration_s - absence - 0.1 * duration_s)
        state.leave_s[person] = rng.uniform(0.05 * duration_s, latest)
        state.absence_s[person] = absence


def _exit_point(pos: np.ndarray, room_m: tuple[float, float], beyond_m: float) -> np.ndarray:
    """Straight out through the nearest wall, `beyond_m` past it."""
    x, y = float(pos[0]), float(pos[1])
    length, width = room_m
    options = [(x, (-beyond_m, y)), (length - x, (length + beyond_m, y)), (y, (x, -beyond_m)),
               (width - y, (x, width + beyond_m))]
    return np.array(min(options, key=lambda option: option[0])[1])


def _smooth(values: np.ndarray, rate: float) -> np.ndarray:
    if len(values) < 16:
        return values
    sos = butter(2, PATH_CUTOFF_HZ, fs=rate, output="sos")
    return np.asarray(sosfiltfilt(sos, values, axis=0, padlen=min(len(values) - 1, int(rate))))


def _start_positions(count: int, room_m: tuple[float, float], params: RoomParams,
                     rng: np.random.Generator) -> np.ndarray:
    """Random standing places at least 3 body radii apart (rejection sampling; after 200 tries the last
    candidate is kept, which only a room far too small for its people needs)."""
    margin, spacing = params.room.wall_margin_m, 3.0 * params.crowd.body_radius_m
    points: list[np.ndarray] = []
    for _ in range(count):
        for _ in range(200):
            candidate = rng.uniform((margin, margin), (room_m[0] - margin, room_m[1] - margin))
            if all(np.hypot(*(candidate - p)) >= spacing for p in points):
                break
        points.append(candidate)
    return np.array(points).reshape(count, 2)


def _finished(state: _State, now: float) -> np.ndarray:
    act = state.activity
    timed = np.isin(act, (Activity.STAND, Activity.SEATED, Activity.SIT_DOWN, Activity.STAND_UP, Activity.AWAY)) \
        & (now >= state.end_s)
    walking = np.isin(act, WALKS)
    arrived = (np.hypot(*(state.target - state.pos).T) < ARRIVE_M) & (np.hypot(*state.vel.T) < STOPPED_MPS)
    gave_up = walking & (now >= state.end_s)
    turned = (act == Activity.TURN) & (np.abs(_wrap(state.goal_heading - state.heading)) < TURN_DONE_RAD)
    return timed | (walking & arrived) | gave_up | turned


def _next_activity(person: int, state: _State, now: float, traits: Person, chairs: list[Chair],
                   owner: np.ndarray, bounds: tuple[float, float, float, float], params: RoomParams,
                   rng: np.random.Generator) -> None:
    """Start the person's next activity."""
    previous = Activity(int(state.activity[person]))
    if previous is Activity.STAND_UP:
        owner[state.chair[person]] = -1
        state.chair[person] = -1
    far = np.hypot(*(state.target[person] - state.pos[person])) > 0.3
    leaving = bool(state.pending[person]) and state.pending[person][0][0] is Activity.AWAY
    if previous in WALKS and state.pending[person] and far and not leaving:
        _release(person, state, owner)  # blocked on the way to a chair: give it up
    if state.outside[person] and previous in WALKS and not leaving and not far:
        state.outside[person] = False  # back inside the area
    activity = params.activity
    if previous in WALKS and leaving and far:
        kind, argument = Activity.WALK_FORWARD, -1.0  # blocked on the way out: carry on
    elif previous is Activity.AWAY:
        kind, argument = Activity.WALK_FORWARD, float("nan")  # back in, to a random point
    elif not state.pending[person] and previous not in (Activity.SIT_DOWN, Activity.SEATED) \
            and now >= state.leave_s[person]:
        state.leave_s[person] = np.inf
        state.outside[person] = True
        room_m = (bounds[0] + bounds[1], bounds[2] + bounds[3])  # the walls: the bounds grown by the margin
        state.target[person] = _exit_point(state.pos[person], room_m, params.away.beyond_m)
        state.pending[person] = [(Activity.AWAY, 0.0)]
        kind, argument = Activity.WALK_FORWARD, -1.0
    elif state.pending[person]:
        kind, argument = state.pending[person].pop(0)
    elif previous is Activity.SIT_DOWN:
        kind, argument = Activity.SEATED, 0.0
    elif previous is Activity.SEATED:
        kind, argument = Activity.STAND_UP, 0.0
    else:
        names = ("walk_forward", "walk_backward", "walk_sideways", "stand", "turn", "sit")
        weights = np.array([getattr(activity, f"{name}_weight") for name in names])
        free = np.flatnonzero(owner < 0)
        if not len(free):
            weights[-1] = 0.0
        choice = names[int(rng.choice(len(names), p=weights / weights.sum()))]
        if choice == "sit":
            chair = int(free[rng.integers(len(free))])
            owner[chair], state.chair[person] = person, chair
            seat = chairs[chair]
            front = (seat.x_m + params.gait.sit_back_m * math.cos(seat.facing_rad),
                     seat.y_m + params.gait.sit_back_m * math.sin(seat.facing_rad))
            state.pending[person] = [(Activity.TURN, seat.facing_rad), (Activity.SIT_DOWN, 0.0)]
            state.target[person] = front
            kind, argument = Activity.WALK_FORWARD, -1.0  # -1: target already set
        else:
            kind = {"walk_forward": Activity.WALK_FORWARD, "walk_backward": Activity.WALK_BACKWARD,
                    "walk_sideways": Activity.WALK_SIDEWAYS, "stand": Activity.STAND, "turn": Activity.TURN}[choice]
            argument = float("nan")
    _start(person, kind, argument, state, now, traits, chairs, bounds, params, rng)


def _release(person: int, state: _State, owner: np.ndarray) -> None:
    if state.chair[person] >= 0:
        owner[state.chair[person]] = -1
    state.chair[person] = -1
    state.pending[person] = []


def _start(person: int, kind: Activity, argument: float, state: _State, now: float, traits: Person,
           chairs: list[Chair], bounds: tuple[float, float, float, float], params: RoomParams,
           rng: np.random.Generator) -> None:
    people, activity = params.people, params.activity
    pos, facing = state.pos[person], float(state.heading[person])
    state.begun_s[person] = now
    if kind is Activity.WALK_FORWARD:
        if argument != -1.0:
            state.target[person] = _forward_target(pos, bounds, params, rng)
        state.cruise[person] = traits.speed_factor * rng.uniform(people.forward_speed_min_mps, people.forward_speed_max_mps)
    elif kind in (Activity.WALK_BACKWARD, Activity.WALK_SIDEWAYS):
        side = 1.0 if rng.random() < 0.5 else -1.0
        angle = facing + math.pi if kind is Activity.WALK_BACKWARD else facing + side * math.pi / 2
        wanted = rng.uniform(activity.step_walk_min_m, activity.step_walk_max_m)
        room = _free_run(pos, angle, bounds)
        if room < MIN_STEP_WALK_M:
            _start(person, Activity.TURN, float("nan"), state, now, traits, chairs, bounds, params, rng)
            return
        distance = min(wanted, room)
        state.target[person] = pos + distance * np.array([math.cos(angle), math.sin(angle)])
        low, high = ((people.backward_speed_min_mps, people.backward_speed_max_mps) if kind is Activity.WALK_BACKWARD
                     else (people.sideways_speed_min_mps, people.sideways_speed_max_mps))
        state.cruise[person] = traits.speed_factor * rng.uniform(low, high)
        state.goal_heading[person] = facing
    elif kind is Activity.TURN:
        if math.isnan(argument):
            sign = 1.0 if rng.random() < 0.5 else -1.0
            argument = facing + sign * math.radians(rng.uniform(activity.turn_min_deg, activity.turn_max_deg))
        state.goal_heading[person] = facing + float(_wrap(argument - facing))
    elif kind is Activity.STAND:
        state.end_s[person] = now + rng.uniform(activity.stand_min_s, activity.stand_max_s)
    elif kind in (Activity.SIT_DOWN, Activity.STAND_UP):
        seat = chairs[state.chair[person]]
        state.from_xy[person] = pos
        front = np.array([seat.x_m, seat.y_m]) + params.gait.sit_back_m * np.array(
            [math.cos(seat.facing_rad), math.sin(seat.facing_rad)])
        state.target[person] = (seat.x_m, seat.y_m) if kind is Activity.SIT_DOWN else front
        state.end_s[person] = now + rng.uniform(activity.transition_min_s, activity.transition_max_s)
    elif kind is Activity.SEATED:
        state.end_s[person] = now + rng.uniform(activity.sit_min_s, activity.sit_max_s)
    elif kind is Activity.AWAY:
        state.end_s[person] = now + float(state.absence_s[person])
    if kind in WALKS:
        distance = float(np.hypot(*(state.target[person] - pos)))
        state.end_s[person] = now + distance / max(state.cruise[person], 0.1) + 3.0 + activity.give_up_s
    state.activity[person] = kind
    if kind not in WALKS:
        state.vel[person] = 0.0


def _forward_target(pos: np.ndarray, bounds: tuple[float, float, float, float], params: RoomParams,
                    rng: np.random.Generator) -> np.ndarray:
    low, high = params.activity.walk_min_m, params.activity.walk_max_m
    candidate = pos
    for _ in range(TARGET_TRIES):
        candidate = rng.uniform((bounds[0], bounds[2]), (bounds[1], bounds[3]))
        if low <= np.hypot(*(candidate - pos)) <= high:
            return candidate
    return candidate


def _free_run(pos: np.ndarray, angle: float, bounds: tuple[float, float, float, float]) -> float:
    """Distance from `pos` along `angle` to the walkable area's edge."""
    direction = (math.cos(angle), math.sin(angle))
    limits = []
    for axis, (low, high) in enumerate(((bounds[0], bounds[1]), (bounds[2], bounds[3]))):
        if abs(direction[axis]) > 1e-9:
            edge = high if direction[axis] > 0 else low
            limits.append((edge - pos[axis]) / direction[axis])
    return max(0.0, min(limits))


def _move(state: _State, now: float, dt: float, bounds: tuple[float, float, float, float], params: RoomParams) -> None:
    people = params.people
    act = state.activity
    walking = np.isin(act, WALKS)
    offset = state.target - state.pos
    distance = np.hypot(*offset.T)
    direction = offset / np.maximum(distance, 1e-9)[:, None]
    speed = np.minimum(state.cruise, np.sqrt(2.0 * people.accel_mps2 * np.maximum(distance - 0.5 * ARRIVE_M, 0.0)))
    # heading: forward walkers face their travel direction and turn before setting off
    forward = act == Activity.WALK_FORWARD
    travel = np.arctan2(direction[:, 1], direction[:, 0])
    goal = np.where(forward & (distance > 0.2), state.heading + _wrap(travel - state.heading), state.goal_heading)
    state.goal_heading = np.where(forward, goal, state.goal_heading)
    error = _wrap(state.goal_heading - state.heading)
    speed = np.where(forward, speed * np.clip(np.cos(error), 0.0, 1.0) ** 2, speed)
    command = np.where(walking[:, None], direction * speed[:, None], 0.0)
    command += _avoidance(state, command, walking, params)
    change = command - state.vel
    limit = people.accel_mps2 * dt
    size = np.hypot(*change.T)
    state.vel = state.vel + change * np.minimum(1.0, limit / np.maximum(size, 1e-12))[:, None]
    turning = np.isin(act, (Activity.TURN, Activity.WALK_FORWARD, Activity.WALK_BACKWARD, Activity.WALK_SIDEWAYS,
                            Activity.STAND))
    rate = np.clip(people.yaw_gain_per_s * error, -math.radians(people.yaw_rate_max_dps),
                   math.radians(people.yaw_rate_max_dps))
    state.heading = state.heading + np.where(turning, rate, 0.0) * dt
    state.pos = state.pos + state.vel * dt
    _scripted(state, now)
    _separate(state, params)
    inside = ~state.outside
    state.pos[inside, 0] = np.clip(state.pos[inside, 0], bounds[0], bounds[1])
    state.pos[inside, 1] = np.clip(state.pos[inside, 1], bounds[2], bounds[3])


def _scripted(state: _State, now: float) -> None:
    """Sit-down and stand-up move the pelvis between the front spot and the seat, minimum jerk."""
    moving = np.isin(state.activity, (Activity.SIT_DOWN, Activity.STAND_UP))
    for person in np.flatnonzero(moving).tolist():
        span = max(state.end_s[person] - state.begun_s[person], 1e-6)
        s = min(max((now - state.begun_s[person]) / span, 0.0), 1.0)
        share = s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)
        state.pos[person] = state.from_xy[person] + share * (state.target[person] - state.from_xy[person])
        state.vel[person] = 0.0
    seated = state.activity == Activity.SEATED
    state.vel[seated] = 0.0


def _avoidance(state: _State, command: np.ndarray, walking: np.ndarray, params: RoomParams) -> np.ndarray:
    """Sideways velocity away from people ahead within avoid_range_m, and a slow-down (vectorised)."""
    crowd = params.crowd
    if len(state.pos) < 2 or not walking.any():
        return np.zeros_like(command)
    delta = state.pos[:, None, :] - state.pos[None, :, :]  # i minus j
    distance = np.hypot(delta[..., 0], delta[..., 1])
    np.fill_diagonal(distance, np.inf)
    contact = 2.0 * crowd.body_radius_m
    weight = np.clip((crowd.avoid_range_m - distance) / (crowd.avoid_range_m - contact), 0.0, 1.0)
    speed = np.hypot(*command.T)
    heading = command / np.maximum(speed, 1e-9)[:, None]
    away = delta / np.maximum(distance, 1e-9)[..., None]
    ahead = np.clip(-np.einsum("ijk,ik->ij", away, heading), 0.0, 1.0)  # 1: j straight ahead of i
    left = np.stack([-heading[:, 1], heading[:, 0]], axis=1)
    side = np.einsum("ijk,ik->ij", away, left)  # > 0: j is on i's right, so step left
    side = np.where(np.abs(side) < 0.05, 1.0, np.sign(side))  # head-on: both keep to the left
    push = (weight * ahead * side).sum(axis=1)
    slow = np.clip((weight * ahead).max(axis=1), 0.0, 0.8)
    result = left * (crowd.avoid_gain_mps * push)[:, None] - command * slow[:, None]
    return np.where((walking & (speed > 1e-6))[:, None], result, 0.0)


def _separate(state: _State, params: RoomParams) -> None:
    """No two pelvis centres closer than two body radii: push the movable ones apart."""
    contact = 2.0 * params.crowd.body_radius_m
    if len(state.pos) < 2:
        return
    delta = state.pos[:, None, :] - state.pos[None, :, :]
    distance = np.hypot(delta[..., 0], delta[..., 1])
    close = np.argwhere(np.triu(distance < contact, 1))
    fixed = np.isin(state.activity, (Activity.SIT_DOWN, Activity.SEATED, Activity.STAND_UP))
    for first, second in close.tolist():
        gap = max(distance[first, second], 1e-6)
        push = (contact - gap) * (delta[first, second] / gap if gap > 1e-6 else np.array([1.0, 0.0]))
        if fixed[first] and fixed[second]:
            continue
        share_first = 0.0 if fixed[first] else (1.0 if fixed[second] else 0.5)
        state.pos[first] += share_first * push
        state.pos[second] -= (1.0 - share_first) * push


def _wrap(angle: np.ndarray | float) -> np.ndarray:
    return np.remainder(np.asarray(angle) + math.pi, 2.0 * math.pi) - math.pi

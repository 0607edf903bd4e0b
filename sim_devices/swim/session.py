"""A swimming session: every agent's set at once, written as one session log (MCAP).

Agents (all start together at the session epoch; each floats at its wall 3-5 s first):
- `s<i>-crawl-<route>`, i = 1..swimmers, for each route: crawl with waist, back and head sensors
  (the paper's four subjects and placements); one swimmer's straight and diagonal sets share the
  body (traits drawn from the swimmer's seed);
- `k<i>-<route>`: a kickboard with one sensor (`<agent>-board`), kicked by swimmer k<i>;
- `s<i>-<stroke>-straight` for breaststroke, backstroke and butterfly, i = 1..min(2, swimmers).
Straight sets start in the inner six lanes (a lane may be shared: swimmers do not interact), diagonal
sets spread over the starts that keep their corners inside the pool.

Streams, each in non-decreasing log time, merged in log-time order:
- ImuBatch per sensor, `sensors.batch_samples` samples, device clock (= true time), `sequence` =
  batch index, log time = true time of the batch's last sample + latency (in order per sensor);
- TruthPose per agent at 50 Hz (x, y, heading of travel), log time = its timestamp;
- TruthLength per length, timestamp = the wall touch, log time = the touch.
Determinism: agent and swimmer seeds are fixed children of `SeedSequence(seed)`; no wall clock.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from protocol import keys, messages
from protocol.errors import ConfigError
from protocol.messages import imu_batch
from protocol.session import AgentKind, Agent, Mount, Route, Sensor, Session, Venue
from sim_devices.common import Item, write_merged
from sim_devices.swim.params import STROKES, SwimParams, check
from sim_devices.swim.simulate import MAX_LENGTHS, SensorStream, SetTruth, simulate_set_detail
from sim_devices.swim.timeline import default_start_y

VENUE = "pool"
DEFAULT_STROKES = STROKES
BODY_MOUNTS = (Mount.WAIST, Mount.BACK, Mount.HEAD)
OTHER_STROKE_SWIMMERS = 2  # breaststroke, backstroke, butterfly: swimmers each
STRAIGHT_LANES = (3, 4, 2, 5, 1, 6)  # inner lanes (0-based of 8), filled centre first
MAX_SWIMMERS = 20
SIM_SHARE = 0.5  # share of the progress bar for simulating (the rest: writing)


@dataclass(frozen=True)
class AgentPlan:
    agent_id: str
    stroke: str
    route: Route
    mounts: tuple[Mount, ...]
    seed: int
    swimmer_seed: int
    start_y_m: float


@dataclass(frozen=True)
class SwimSummary:
    """What a swimming simulation produced."""

    output: str
    seed: int
    swimmers: int
    lengths: int
    agents: int
    sensors: int
    duration_s: float
    imu_samples: int
    imu_batches: int
    truth_poses: int
    truth_lengths: int
    swum_m: dict[str, list[float]]  # per agent, per length

    def __str__(self) -> str:
        straight = [d for agent, ds in self.swum_m.items() if "straight" in agent for d in ds]
        diagonal = [d for agent, ds in self.swum_m.items() if "diagonal" in agent for d in ds]
        lines = [f"{self.output}: {self.agents} agents, {self.sensors} sensors, {self.lengths} lengths each, "
                 f"{self.duration_s:.1f} s, seed {self.seed}",
                 f"  IMU: {self.imu_samples} samples in {self.imu_batches} batches; truth poses: {self.truth_poses}; "
                 f"truth lengths: {self.truth_lengths}"]
        for name, values in (("straight", straight), ("diagonal", diagonal)):
            if values:
                lines.append(f"  swum per {name} length: {min(values):.2f}-{max(values):.2f} m")
        return "\n".join(lines)


def plan_agents(seed: int, swimmers: int, strokes: Sequence[str], routes: Sequence[Route],
                params: SwimParams) -> list[AgentPlan]:
    """The session's agents in a fixed order, with their seeds and lane positions."""
    pool = params.pool
    rows: list[tuple[str, str, Route, tuple[Mount, ...], int]] = []
    for stroke in strokes:
        if stroke == "kick":
            rows += [(f"k{i}-{route.value}", stroke, route, (Mount.KICKBOARD,), 2000 + i)
                     for i in range(1, swimmers + 1) for route in routes]
        elif stroke == "crawl":
            rows += [(f"s{i}-crawl-{route.value}", stroke, route, BODY_MOUNTS, 1000 + i)
                     for i in range(1, swimmers + 1) for route in routes]
        else:
            rows += [(f"s{i}-{stroke}-straight", stroke, Route.STRAIGHT, BODY_MOUNTS, 1000 + i)
                     for i in range(1, min(OTHER_STROKE_SWIMMERS, swimmers) + 1)]
    diagonal = [row for row in rows if row[2] is Route.DIAGONAL]
    low = default_start_y(Route.DIAGONAL, params)
    high = pool.width_m - pool.side_margin_m
    plans, straight_count, diagonal_count = [], 0, 0
    for number, (agent_id, stroke, route, mounts, swimmer_number) in enumerate(rows):
        if route is Route.DIAGONAL:
            start_y = low + (high - low) * (diagonal_count + 0.5) / len(diagonal)
            diagonal_count += 1
        else:
            lane = STRAIGHT_LANES[straight_count % len(STRAIGHT_LANES)]
            start_y = pool.lane_width_m * (lane + 0.5) + (pool.width_m - 8 * pool.lane_width_m) / 2.0
            straight_count += 1
        plans.append(AgentPlan(agent_id, stroke, route, mounts, _child(seed, number), _child(seed, swimmer_number),
                               start_y))
    return plans


def _child(seed: int, key: int) -> int:
    return int(np.random.SeedSequence(seed, spawn_key=(key,)).generate_state(1)[0])


def simulate_swim(output: Path, seed: int = 1, swimmers: int = 4, lengths: int = 4,
                  strokes: Sequence[str] = DEFAULT_STROKES, routes: Sequence[Route] = (Route.STRAIGHT, Route.DIAGONAL),
                  params: SwimParams | None = None, progress: Callable[[float], None] | None = None) -> SwimSummary:
    """Simulate a swimming session and write it to `output`; `progress(share)` with share in [0, 1].

    ConfigError for a bad seed, swimmer or length count, stroke or route, or an unwritable output.
    """
    params = params or SwimParams()
    check(params)
    if isinstance(swimmers, bool) or not isinstance(swimmers, int) or not 1 <= swimmers <= MAX_SWIMMERS:
        raise ConfigError(f"swimmers: {swimmers!r} is not an integer in [1, {MAX_SWIMMERS}]")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed: {seed!r} is not a non-negative integer")
    if isinstance(lengths, bool) or not isinstance(lengths, int) or not 1 <= lengths <= MAX_LENGTHS:
        raise ConfigError(f"lengths: {lengths!r} is not an integer in [1, {MAX_LENGTHS}]")
    for stroke in strokes:
        if stroke not in STROKES:
            raise ConfigError(f"strokes: {stroke!r} is not one of {', '.join(STROKES)}")
    try:
        routes = tuple(Route(route) for route in routes)
    except ValueError as error:
        raise ConfigError(f"routes: {error}") from None
    report = progress or (lambda share: None)
    plans = plan_agents(seed, swimmers, strokes, routes, params)
    if not plans:
        raise ConfigError("strokes: no agents to simulate")
    sets: list[tuple[AgentPlan, list[SensorStream], SetTruth, dict[str, Any]]] = []
    for number, plan in enumerate(plans):
        streams, truth, detail = simulate_set_detail(plan.stroke, plan.route, plan.mounts, lengths, plan.seed, params,
                                                     plan.agent_id, swimmer_seed=plan.swimmer_seed,
                                                     start_y_m=plan.start_y_m)
        devices = {s.sensor_id: {"mount": s.mount.value, "tilt_deg": detail.tilt_deg[s.mount],
                                 "accel_bias_g": detail.imus[s.mount].errors["accel"].bias.tolist(),
                                 "gyro_bias_dps": detail.imus[s.mount].errors["gyro"].bias.tolist()} for s in streams}
        # float32 is what an ImuBatch carries; keeping it halves the memory of a default session
        streams = [dataclasses.replace(s, accel_g=s.accel_g.astype(np.float32), gyro_dps=s.gyro_dps.astype(np.float32))
                   for s in streams]
        sets.append((plan, streams, truth, {"swimmer": detail.swimmer.to_dict(), "devices": devices}))
        report(SIM_SHARE * (number + 1) / len(plans))
    session = _describe(sets, seed, swimmers, lengths, strokes, routes, params)
    latency_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(9999,)))
    counts = {"batches": 0}
    sources: list[Iterator[Item]] = [_imu_items(plan.agent_id, s, params, latency_rng, counts)
                                     for plan, streams, _, _ in sets for s in streams]
    sources += [_truth_items(plan.agent_id, truth) for plan, _, truth, _ in sets]
    samples = sum(len(s.time_ns) for _, streams, _, _ in sets for s in streams)
    total = samples / params.sensors.batch_samples + 1.0
    write_merged(output, session, sources, lambda written: report(SIM_SHARE + (1.0 - SIM_SHARE) * min(written / total, 0.99)))
    report(1.0)
    epoch_ns = params.link.start_unix_s * 1_000_000_000
    end_ns = max(int(truth.time_ns[-1]) for _, _, truth, _ in sets)
    return SwimSummary(
        output=str(output), seed=seed, swimmers=swimmers, lengths=lengths, agents=len(sets),
        sensors=sum(len(streams) for _, streams, _, _ in sets), duration_s=(end_ns - epoch_ns) * 1e-9,
        imu_samples=samples, imu_batches=counts["batches"],
        truth_poses=sum(len(truth.time_ns) for _, _, truth, _ in sets),
        truth_lengths=sum(len(truth.push_ns) for _, _, truth, _ in sets),
        swum_m={plan.agent_id: truth.swum_m.tolist() for plan, _, truth, _ in sets})


def _describe(sets: list[tuple[AgentPlan, list[SensorStream], SetTruth, dict[str, Any]]], seed: int, swimmers: int,
              lengths: int, strokes: Sequence[str], routes: Sequence[Route], params: SwimParams) -> Session:
    rate = params.sensors.rate_hz
    agents = []
    for plan, streams, truth, _ in sets:
        sensors = tuple(Sensor(s.sensor_id, s.mount, rate, forward_axis="+x", left_axis="+y") for s in streams)
        agents.append(Agent(plan.agent_id, kind=AgentKind.SWIMMER, sensors=sensors, start_x_m=float(truth.x_m[0]),
                            start_y_m=float(truth.y_m[0]), start_heading_rad=float(truth.heading_rad[0]),
                            route=plan.route))
    source = {"generator": "sim_devices.swim", "seed": seed, "swimmers": swimmers, "lengths": lengths,
              "strokes": list(strokes), "routes": [r.value for r in routes], "params": dataclasses.asdict(params),
              "agents": {plan.agent_id: {"stroke": plan.stroke, "route": plan.route.value, "seed": plan.seed,
                                         "swimmer_seed": plan.swimmer_seed, **extra}
                         for plan, _, _, extra in sets}}
    return Session(Venue(VENUE, params.pool.length_m, params.pool.width_m), tuple(agents), source)


def _imu_items(agent_id: str, stream: SensorStream, params: SwimParams, rng: np.random.Generator,
               counts: dict[str, int]) -> Iterator[Item]:
    size, link = params.sensors.batch_samples, params.link
    batches = math.ceil(len(stream.time_ns) / size)
    last = stream.time_ns[np.minimum(np.arange(1, batches + 1) * size, len(stream.time_ns)) - 1]
    extra_ms = rng.exponential(link.latency_jitter_ms, batches) if link.latency_jitter_ms > 0 else np.zeros(batches)
    log_ns = np.maximum.accumulate(last + np.round((link.latency_ms + extra_ms) * 1e6).astype(np.int64))
    topic = keys.imu(VENUE, agent_id, stream.sensor_id)
    return _imu_generator(agent_id, stream, log_ns, size, topic, counts)


def _imu_generator(agent_id: str, stream: SensorStream, log_ns: np.ndarray, size: int, topic: str,
                   counts: dict[str, int]) -> Iterator[Item]:
    for batch in range(len(log_ns)):
        rows = slice(batch * size, (batch + 1) * size)
        message = imu_batch(agent_id, stream.sensor_id, batch, stream.time_ns[rows], stream.accel_g[rows],
                            stream.gyro_dps[rows], None)
        counts["batches"] += 1
        yield int(log_ns[batch]), 0, topic, message


def _truth_items(agent_id: str, truth: SetTruth) -> Iterator[Item]:
    """TruthPose at 50 Hz and TruthLength at each touch, in time order (a length after its touch pose)."""
    pose_topic, length_topic = keys.truth(VENUE, agent_id), keys.truth_length(VENUE, agent_id)
    touches = iter(range(len(truth.touch_ns)))
    pending = next(touches, None)
    for row in range(len(truth.time_ns)):
        stamp = int(truth.time_ns[row])
        while pending is not None and int(truth.touch_ns[pending]) < stamp:
            yield _length_item(agent_id, truth, pending, length_topic)
            pending = next(touches, None)
        yield stamp, 1, pose_topic, messages.new(
            "TruthPose", timestamp_ns=stamp, agent_id=agent_id, x_m=float(truth.x_m[row]), y_m=float(truth.y_m[row]),
            heading_rad=float(truth.heading_rad[row]))
    while pending is not None:
        yield _length_item(agent_id, truth, pending, length_topic)
        pending = next(touches, None)


def _length_item(agent_id: str, truth: SetTruth, index: int, topic: str) -> Item:
    stamp = int(truth.touch_ns[index])
    return stamp, 2, topic, messages.new(
        "TruthLength", timestamp_ns=stamp, agent_id=agent_id, index=index + 1, start_ns=int(truth.push_ns[index]),
        swum_distance_m=float(truth.swum_m[index]), lane_distance_m=float(truth.lane_m[index]),
        stroke_count=int(truth.strokes[index]), stroke=truth.stroke, route=truth.route.value)

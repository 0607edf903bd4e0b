"""`reckon bench` on a tiny game: the result's shape, and how live poses are paired for latency.

Never asserts a speed: the numbers depend on the machine; docs/benchmarks.md holds measured ones.
"""

from __future__ import annotations

import json
import math

import pytest

from protocol import bus as wire
from protocol import keys, messages
from protocol.session import Mount
from protocol.session_log import read_description
from protocol.errors import ReckonError
from reckon.bench import play as play_module
from reckon.bench.latency import latencies
from reckon.bench.pipeline import run_bench
from reckon.bench.report import format_table
from reckon.transport.bus import Received


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    lines: list[str] = []
    result = run_bench(out, players=2, duration_s=5.0, seed=1, progress=lines.append)
    return out, result, lines


def test_result_has_the_four_numbers_positive_and_finite(bench):
    _, result, lines = bench
    numbers = [result["edge_samples_per_s"], result["pipeline_realtime_factor"], result["latency_ms"]["p50"],
               result["latency_ms"]["p99"], result["rss_mb"]["edge"], result["rss_mb"]["hub"]]
    assert set(result) == {"edge_samples_per_s", "pipeline_realtime_factor", "latency_ms", "rss_mb", "machine",
                           "details"}
    assert set(result["latency_ms"]) == {"p50", "p99"} and set(result["rss_mb"]) == {"edge", "hub"}
    assert all(isinstance(n, float) and math.isfinite(n) and n > 0 for n in numbers), numbers
    assert result["latency_ms"]["p50"] <= result["latency_ms"]["p99"]
    json.dumps(result, allow_nan=False)  # JSON-able as it is
    assert lines, "progress was never called"


def test_details_account_for_every_pose(bench):
    _, result, _ = bench
    details = result["details"]
    latency = details["latency"]
    assert latency["unmatched"] == 0
    assert latency["edge_poses"] == latency["live_poses"] > 0
    assert latency["processing_ms"]["count"] + latency["warmup_excluded"]["count"] == latency["edge_poses"]
    pipeline = details["pipeline"]
    assert pipeline["hub_inputs"]["pose/edge"] == pipeline["hub_outputs"]["pose/live"]
    assert details["edge"]["kernel_samples"] >= 1_000_000
    assert "pipeline" in format_table(result)
    for run in (pipeline, latency):  # every kept run started in step: a late attempt was done again
        assert run["start_allowance_s"] >= 1.0 and all(late > 0 for late in run["late_starts_s"])


def test_edges_never_up_by_their_start_are_given_up_naming_how_late(bench, monkeypatch):
    out, _, _ = bench
    allowances: list[float] = []

    def too_short(edges: int, startup_cpu_s: float, cores: int) -> float:
        allowances.append(0.001 * 2 ** len(allowances))
        return allowances[-1]

    monkeypatch.setattr(play_module, "start_allowance_s", too_short)
    with pytest.raises(ReckonError, match=r"not up by their common start in 3 attempts \(late by [0-9.]+, [0-9.]+, "
                                          r"[0-9.]+ s"):
        play_module.play(out / "latency-game.mcap", out / "late", 1.0)
    assert len(allowances) == 1  # each attempt doubles the one before, not asks again


def _received(key: str, message, received_ns: int, source_ns: int) -> Received:
    payload, encoding = wire.encode(message)
    return Received(key, payload, encoding, False, received_ns, source_ns)


def test_latency_runs_from_the_batch_whose_push_made_the_pose(bench):
    out, _, _ = bench
    session = read_description(out / "game.mcap")
    venue, agent = session.venue.name, session.agents[0]
    seat = agent.sensor(Mount.SEAT).id
    wheel = agent.sensor(Mount.LEFT_WHEEL).id
    ms = 1_000_000
    t0 = 10_000 * ms  # device time of the seat sample the pose is for, past the warm-up
    start = messages.new("EstimatedPose", timestamp_ns=0, agent_id=agent.id, heading_rad=0.25)
    pose = messages.new("EstimatedPose", timestamp_ns=t0, agent_id=agent.id, heading_rad=0.5)
    seat_batch = messages.new("ImuBatch", agent_id=agent.id, sensor_id=seat, timestamp_ns=t0 - 5 * ms,
                              sample_offset_ns=[0, 5 * ms])
    wheel_batch = messages.new("ImuBatch", agent_id=agent.id, sensor_id=wheel, timestamp_ns=t0, sample_offset_ns=[0])
    first_batch = messages.new("ImuBatch", agent_id=agent.id, sensor_id=seat, timestamp_ns=0, sample_offset_ns=[0])
    received = [
        _received(keys.imu(venue, agent.id, seat), first_batch, 0, 0),
        _received(keys.pose(venue, agent.id, "edge"), start, 1 * ms, 1 * ms),
        _received(keys.pose(venue, agent.id, "live"), start, 2 * ms, 2 * ms),
        _received(keys.imu(venue, agent.id, seat), seat_batch, 100 * ms, 100 * ms),  # carries t0
        _received(keys.imu(venue, agent.id, wheel), wheel_batch, 130 * ms, 130 * ms),  # completes it
        _received(keys.pose(venue, agent.id, "edge"), pose, 131 * ms, 131 * ms),
        _received(keys.pose(venue, agent.id, "live"), pose, 133 * ms, 132 * ms),
    ]
    result = latencies(received, session, warmup_s=1.0)
    assert result["unmatched"] == 0
    assert result["warmup_excluded"]["count"] == 1
    assert result["processing_ms"]["p50"] == pytest.approx(3.0)  # 133 - 130: from the wheel batch
    assert result["from_seat_batch_ms"]["p50"] == pytest.approx(33.0)  # 133 - 100
    assert result["parts_ms"]["edge"]["p50"] == pytest.approx(1.0)

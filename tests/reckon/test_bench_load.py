"""`reckon bench load` and `reckon bench soak` at tiny sizes: the results' shape and the zero-drop
invariant, never a speed (docs/benchmarks.md holds measured numbers). Also the hub's O(1)
collision-pairing check against the scan of every agent it replaces."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hub.chair.hub import ChairHub, HubSettings
from protocol import messages
from protocol.errors import ReckonError
from protocol.session_log import LogMessages
from reckon.bench.load import run_load
from reckon.bench.load_report import format_load
from reckon.bench.load_spec import COURT_AGENTS, LoadSpec, contacts, load_session
from reckon.bench.soak import format_soak, run_soak


@pytest.fixture(scope="module")
def load(tmp_path_factory):
    out = tmp_path_factory.mktemp("load")
    lines: list[str] = []
    return run_load(out, agents=6, rate_hz=50.0, duration_s=2.0, progress=lines.append), lines


def test_load_result_shape_and_nothing_dropped(load):
    result, lines = load
    assert {"agents", "rate_hz", "duration_s", "hub_cpu_cores", "latency_ms", "rss_mb", "dropped", "skipped",
            "corrections", "machine", "details"} <= set(result)
    assert result["dropped"] == 0 and result["skipped"] == 0
    details = result["details"]
    assert details["generated"]["poses"] == 6 * 100  # 2 s at 50 Hz
    assert details["watched"]["live"] == details["generated"]["poses"]  # one live pose per pose, each seen
    assert details["watched"]["duplicates"] == 0 and details["watched"]["strays"] == 0
    assert details["hub"]["inputs"] == details["hub_expected_inputs"]
    assert details["poses_in_percentiles"] > 0
    lat = result["latency_ms"]
    assert 0 < lat["p50"] <= lat["p99"] <= lat["max"]
    assert result["hub_cpu_cores"] > 0 and result["rss_mb"]["hub_peak"] > 0 and isinstance(result["kept_up"], bool)
    json.dumps(result, allow_nan=False)
    assert "dropped 0" in format_load(result) and lines


def test_two_hubs_share_the_courts_and_nothing_is_dropped(tmp_path):
    result = run_load(tmp_path, agents=30, rate_hz=20.0, duration_s=2.0, progress=lambda line: None, hubs=2)
    details = result["details"]
    assert result["hubs"] == 2 and result["dropped"] == 0 and result["skipped"] == 0
    assert details["watched"]["live"] == details["generated"]["poses"] == 30 * 40
    assert details["watched"]["strays"] == 0 and details["watched"]["duplicates"] == 0
    hubs = details["hubs"]
    assert set(hubs) == {"hub1", "hub2"}
    # 3 courts in blocks (court c to hub c * 2 // 3): the first hub takes two courts' chairs, the second one
    # court's; each gives a live pose per pose (its refined track nobody takes is not made)
    assert [hubs[name]["outputs"] >= poses for name, poses in (("hub1", 20 * 40), ("hub2", 10 * 40))] == [True, True]
    assert sum(h["inputs"] for h in hubs.values()) == details["hub"]["inputs"] == details["hub_expected_inputs"]
    assert "2 hubs (courts sharded)" in format_load(result)


def test_a_recording_hub_records_every_input_and_both_tracks(tmp_path):
    result = run_load(tmp_path, agents=6, rate_hz=20.0, duration_s=2.0, progress=lambda line: None, record=True)
    assert result["recorded"] and result["dropped"] == 0 and "recording" in format_load(result)
    counts = {"edge": 0, "live": 0, "refined": 0}
    for _, topic, message in LogMessages(tmp_path / "hub.mcap"):
        if messages.type_name(message) == "EstimatedPose":
            counts[topic.rsplit("/", 1)[-1]] += 1
    poses = result["details"]["generated"]["poses"]
    assert counts == {"edge": poses, "live": poses, "refined": poses}  # the refined track made: it is recorded


def test_more_hubs_than_courts_is_refused():
    with pytest.raises(ReckonError, match="--hubs 3 must be 1-2"):
        LoadSpec(agents=20, hubs=3)


def test_soak_result_shape(tmp_path):
    result = run_soak(tmp_path, hours=30 / 3600, progress=lambda _: None, plot=tmp_path / "rss.png")
    processes = result["details"]["processes"]
    assert set(processes) == {"hub", "edge chair01", "edge chair02"}
    for curve in processes.values():
        assert 0 < curve["first"] <= curve["max"] and curve["last"] <= curve["max"] <= curve["peak_vmhwm"] + 1
    assert "0 samples skipped" in result["details"]["hub_summary"]
    assert (tmp_path / "rss.png").stat().st_size > 0
    assert "VmHWM" in format_soak(result)


def test_contacts_finds_each_approach_once_within_its_court():
    touching = np.zeros((2, COURT_AGENTS, COURT_AGENTS), dtype=bool)
    xy = np.arange(2 * 11, dtype=float).reshape(11, 2) * 10.0  # 11 chairs: the second court has one
    xy[3] = xy[1] + [0.5, 0.0]  # chairs 1 and 3 touch
    xy[10] = xy[9] + [0.1, 0.0]  # 9 and 10 are close but on different courts
    pairs, touching = contacts(xy, touching)
    assert pairs == [(1, 3)]
    assert contacts(xy, touching)[0] == []  # still touching: not a new contact


def _stream(spec: LoadSpec, ticks: int, rng: np.random.Generator) -> list:
    """Poses of every chair, with impacts; chair 5 falls silent half-way (it goes stale)."""
    ids = [spec.agent_id(i) for i in range(spec.agents)]
    out = []
    for tick in range(ticks):
        for i, agent_id in enumerate(ids):
            if i == 5 and tick > ticks // 2:
                continue
            time_ns = 10**18 + tick * spec.period_ns + int(rng.integers(0, 5_000_000))
            out.append(messages.new("EstimatedPose", timestamp_ns=time_ns, agent_id=agent_id,
                                    x_m=float(i % COURT_AGENTS) * 0.5, y_m=float(rng.normal(0, 0.1)), heading_rad=0.0,
                                    covariance=[0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.01], method="reckon"))
            if rng.random() < 0.02:
                out.append(messages.new("ImpactEvent", timestamp_ns=time_ns - int(rng.integers(0, 300_000_000)),
                                        agent_id=agent_id, sensor_id=f"{agent_id}-s", peak_g=9.0))
    return out


def test_pairing_check_gives_what_scanning_every_agent_gives():
    spec = LoadSpec(agents=12)
    session = load_session(spec)
    settings = HubSettings(stale_s=1.0, lag_s=1.0)
    fast, scanning = ChairHub(session, settings), ChairHub(session, settings)
    scanning._live_agent_short = lambda posed, hold_ns: False  # always compute the watermark over every agent
    compared = 0
    for n, message in enumerate(_stream(spec, 600, np.random.default_rng(3))):
        arrival = 10**18 + n * 400_000  # chair 5's silence outlasts stale_s
        a, b = fast.on_message(message, arrival), scanning.on_message(message, arrival)
        assert [m.SerializeToString() for m in a] == [m.SerializeToString() for m in b]
        compared += len(a)
    assert fast.counters.pairs == scanning.counters.pairs > 0 and compared > 0
    assert fast.counters.groups == scanning.counters.groups

"""A deliberately wrong correction does not make the tracks worse (issue 22's robustness goal).

A simulated game run in lockstep (`reckon eval`'s path: the edges' and the hub's code), once as
simulated and once with two wrong corrections injected into its raw inputs:
- a beacon pass at the wrong goal: a chair 20 m or more from a goal's beacon hears it as a chair
  passing under it would (peak at the beacon's 1 m power, 2 s of sightings at 10 Hz);
- a collision between chairs about 10 m apart: both seats jolted at the same instant, 12 g, each
  pushed away from the other along the line between them (what a contact's pushes say), so only
  the distance can tell it is none.
The injected inputs must reach the hub (a pass it rules on, two impacts it pairs or refuses), and
over the 30 s after each the live and refined tracks of the chairs involved must be no worse.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hub.chair.corrections import BeaconLevels
from hub.chair.hub import HubSettings
from protocol import messages
from protocol.session import Mount
from protocol.session_log import read_session
from reckon.evaluation.reckon_run import log_inputs, run_lockstep
from sim_devices.wheelchair import simulate

S = 1_000_000_000
BEACON_AT_S, CONTACT_AT_S, AFTER_S = 30.0, 40.0, 30.0
JOLT_G = (8.0, 12.0, 8.0)  # a 10 ms half-sine at 200 Hz, the edge reads about 7 g: a contact's


@pytest.fixture(scope="module")
def game(tmp_path_factory):
    path = tmp_path_factory.mktemp("wrong") / "game.mcap"
    simulate(players=6, duration_s=90, seed=2, output=path)
    data = read_session(path)
    return data, log_inputs(path)


def truth_at(data, agent: str, time_ns: np.ndarray) -> np.ndarray:
    truth = data.truth[agent]
    return np.stack([np.interp(time_ns, truth.time_ns, truth.x_m), np.interp(time_ns, truth.time_ns, truth.y_m)], 1)


def device_offset_ns(inputs: list, sensor_id: str) -> int:
    """Arrival minus device time of a sensor's batches' last samples, at the median (clock offset + latency)."""
    gaps = [arrival - (m.timestamp_ns + m.sample_offset_ns[-1]) for arrival, m in inputs
            if messages.type_name(m) == "ImuBatch" and m.sensor_id == sensor_id and len(m.sample_offset_ns)]
    return int(np.median(gaps))


def seat_of(data, agent: str):
    return next(s for s in data.session.agent(agent).sensors if s.mount is Mount.SEAT)


def wrong_pass(data, inputs: list) -> tuple[list, str, str]:
    """Sightings of the goal's beacon furthest from any chair at BEACON_AT_S, by that chair."""
    t0 = min(series.time_ns[0] for series in data.truth.values())
    at = np.array([t0 + int(BEACON_AT_S * S)])
    agent, beacon = max(((a, b) for a in data.truth for b in data.session.venue.beacons),
                        key=lambda ab: math.dist(truth_at(data, ab[0], at)[0], (ab[1].x_m, ab[1].y_m)))
    assert math.dist(truth_at(data, agent, at)[0], (beacon.x_m, beacon.y_m)) > 20.0
    seat = seat_of(data, agent)
    offset = device_offset_ns(inputs, seat.id)
    added = []
    for k in range(-10, 11):
        venue_ns = int(at[0]) + k * S // 10
        sighting = messages.new("BeaconSighting", timestamp_ns=venue_ns - offset, agent_id=agent, sensor_id=seat.id,
                                beacon_id=beacon.id, rssi_dbm=beacon.tx_power_dbm - 0.3 * abs(k))
        added.append((venue_ns + 5_000_000, sighting))
    return added, agent, beacon.id


def axis_of(axis: str) -> tuple[int, float]:
    return "xyz".index(axis[1]), (1.0 if axis[0] == "+" else -1.0)


def wrong_contact(data, inputs: list) -> tuple[dict, tuple[str, str], float]:
    """The seat batches of two chairs about 10 m apart (the pair and instant from CONTACT_AT_S on closest
    to it), jolted apart there; and that instant (s into the game)."""
    t0 = min(series.time_ns[0] for series in data.truth.values())
    best = None
    for seconds in np.arange(CONTACT_AT_S, CONTACT_AT_S + 10.0, 0.5):
        where = {agent: truth_at(data, agent, np.array([t0 + int(seconds * S)]))[0] for agent in data.truth}
        for a in where:
            for b in where:
                if a < b and (best is None or abs(math.dist(where[a], where[b]) - 10.0) < best[0]):
                    best = (abs(math.dist(where[a], where[b]) - 10.0), float(seconds), a, b, where)
    _, seconds, a, b, where = best
    at = t0 + int(seconds * S)
    assert 8.0 < math.dist(where[a], where[b]) < 12.0
    replaced = {}
    for me, other in ((a, b), (b, a)):
        seat = seat_of(data, me)
        away = (where[me] - where[other]) / np.linalg.norm(where[me] - where[other])
        truth = data.truth[me]
        heading = float(np.interp(at, truth.time_ns, np.unwrap(truth.heading_rad)))
        forward = away[0] * math.cos(heading) + away[1] * math.sin(heading)
        left = -away[0] * math.sin(heading) + away[1] * math.cos(heading)
        push = np.zeros(3)
        for axis, value in ((seat.forward_axis, forward), (seat.left_axis, left)):
            index, sign = axis_of(axis)
            push[index] += sign * value
        device_at = at - device_offset_ns(inputs, seat.id)
        for position, (arrival, batch) in enumerate(inputs):
            if messages.type_name(batch) != "ImuBatch" or batch.sensor_id != seat.id:
                continue
            times = batch.timestamp_ns + np.asarray(batch.sample_offset_ns, dtype=np.int64)
            first = int(np.searchsorted(times, device_at))
            if first + len(JOLT_G) > len(times) or first == 0 and times[0] > device_at + S // 100:
                continue
            jolted = messages.ImuBatch()
            jolted.CopyFrom(batch)  # the clean run shares the inputs: never edit them
            accel = np.array(jolted.accel_g).reshape(-1, 3)
            for k, g in enumerate(JOLT_G):
                accel[first + k] += g * push
            jolted.accel_g[:] = accel.ravel().tolist()
            replaced[position] = (arrival, jolted)
            break
    assert len(replaced) == 2, "both seats' batches at the contact's time"
    return replaced, (a, b), seconds


def track_error(data, track: np.ndarray, agent: str, from_s: float) -> float:
    t0 = min(series.time_ns[0] for series in data.truth.values())
    window = (track[:, 0] >= t0 + from_s * S) & (track[:, 0] < t0 + (from_s + AFTER_S) * S)
    rows = track[window]
    return float(np.mean(np.linalg.norm(rows[:, 1:3] - truth_at(data, agent, rows[:, 0]), axis=1)))


def test_a_beacon_pass_at_the_wrong_goal_and_a_collision_10_m_apart_leave_the_tracks_no_worse(game, monkeypatch):
    data, inputs = game
    ruled = []  # (beacon, peak) of every pass the hub ruled on
    original = BeaconLevels.close
    monkeypatch.setattr(BeaconLevels, "close", lambda self, beacon_id, peak_dbm: (
        ruled.append((beacon_id, peak_dbm)), original(self, beacon_id, peak_dbm))[1])
    sightings, passer, beacon_id = wrong_pass(data, inputs)
    jolted, pair, contact_s = wrong_contact(data, inputs)
    injected = [jolted.get(i, item) for i, item in enumerate(inputs)] + sightings
    injected.sort(key=lambda item: item[0])  # stable: the log's own order within an arrival time
    settings = HubSettings(corrections=("beacon", "collision"), lag_s=10.0)
    clean_hub, clean_live, clean_refined = run_lockstep(data.session, inputs, settings)
    hub, live, refined = run_lockstep(data.session, injected, settings)

    # Both wrong corrections reached the hub and were ruled on.
    assert hub.chairs.counters.impacts == clean_hub.chairs.counters.impacts + 2
    tx_power = next(b.tx_power_dbm for b in data.session.venue.beacons if b.id == beacon_id)
    assert ruled.count((beacon_id, tx_power)) == 1  # the clean game never peaks at the 1 m power

    for agent, from_s in ((passer, BEACON_AT_S), (pair[0], contact_s), (pair[1], contact_s)):
        for name, clean, wrong in (("live", clean_live, live), ("refined", clean_refined, refined)):
            before, after = track_error(data, clean[agent], agent, from_s), track_error(data, wrong[agent], agent, from_s)
            assert after <= 1.05 * before + 0.02, (agent, name, before, after)

"""BLE: lost IMU batches, delivery latency, and goal-beacon sightings (`radio.*`).

Batch loss is bursty (Gilbert-Elliott): a good state that loses nothing and a bad state that loses
every batch, with a mean bad run of `loss_burst_batches` and a bad share of `batch_loss_rate`.
A lost batch is never written, so the receiver sees a gap in the sequence numbers.

Beacon sightings: each beacon advertises every `advertising_interval_ms` plus the 0-10 ms random
advDelay of the BLE specification. A receiver (the seat sensor, at `receiver_height_m`) hears an
advertisement with probability `scan_efficiency` if its RSSI reaches `sensitivity_dbm`:
    RSSI = tx_power - 10 n log10(d) + shadowing + fading - body loss      (dBm, rounded)
with d the 3-D distance (beacon at its height, receiver at the seat), n = `path_loss_exponent`,
shadowing a per receiver-beacon log-normal process (SD `shadowing_db`, correlation time
`shadowing_time_s`), fading white per packet (`fading_db`), and the body loss rising from 0 with
the beacon ahead to `body_loss_db` with it behind the player: body_loss * (1 - cos(bearing)) / 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from sim_devices.wheelchair.motion import Motion
from sim_devices.wheelchair.params import RadioParams

ADV_DELAY_MAX_S = 0.010  # BLE advDelay: 0-10 ms added to every advertising interval (Core spec)


def batch_losses(batches: int, params: RadioParams, rng: np.random.Generator) -> np.ndarray:
    """(batches,) bool, True = lost; alternating good/bad runs of geometric length."""
    lost = np.zeros(batches, dtype=bool)
    rate = params.batch_loss_rate
    if rate <= 0 or batches == 0:
        return lost
    to_good = 1.0 / params.loss_burst_batches
    to_bad = min(rate * to_good / (1.0 - rate), 1.0)
    index, bad = 0, bool(rng.random() < rate)
    while index < batches:
        run = int(rng.geometric(to_good if bad else to_bad))
        if bad:
            lost[index:index + run] = True
        index += run
        bad = not bad
    return lost


def latencies_s(count: int, params: RadioParams, rng: np.random.Generator) -> np.ndarray:
    """Delivery latency (s) of `count` packets: fixed part plus an exponential tail."""
    tail = rng.exponential(params.latency_jitter_ms, count) if params.latency_jitter_ms > 0 else np.zeros(count)
    return (params.latency_ms + tail) * 1e-3


@dataclass(frozen=True)
class BeaconSite:
    """A goal beacon and its advertising instants (true time, s)."""

    beacon_id: str
    x_m: float
    y_m: float
    height_m: float
    tx_power_dbm: float
    advertising_s: np.ndarray


def advertising_times(duration_s: float, params: RadioParams, rng: np.random.Generator) -> np.ndarray:
    """Advertising instants of one beacon over [0, duration_s)."""
    interval = params.advertising_interval_ms * 1e-3
    count = int(duration_s / interval) + 2
    gaps = interval + rng.uniform(0.0, ADV_DELAY_MAX_S, count)
    times = rng.uniform(0.0, interval) + np.concatenate([[0.0], np.cumsum(gaps[:-1])])
    return times[times < duration_s]


def sightings(motion: Motion, agent: int, beacon: BeaconSite, params: RadioParams,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(true times s, RSSI dBm) of the advertisements of `beacon` that the agent's receiver heard."""
    times = beacon.advertising_s
    if len(times) == 0:
        return times, np.zeros(0)
    rate = 1.0 / (motion.time_s[1] - motion.time_s[0]) if len(motion.time_s) > 1 else 1.0
    step = np.minimum((times * rate).astype(int), len(motion.time_s) - 1)
    dx = beacon.x_m - motion.x_m[step, agent]
    dy = beacon.y_m - motion.y_m[step, agent]
    distance = np.sqrt(dx**2 + dy**2 + (beacon.height_m - params.receiver_height_m) ** 2)
    bearing = np.arctan2(dy, dx) - motion.heading_rad[step, agent]
    body = params.body_loss_db * (1.0 - np.cos(bearing)) / 2.0
    rssi = (beacon.tx_power_dbm - 10.0 * params.path_loss_exponent * np.log10(distance)
            + _shadowing(len(times), params, rng) + rng.normal(0.0, 1.0, len(times)) * params.fading_db - body)
    rssi = np.round(rssi)
    heard = (rssi >= params.sensitivity_dbm) & (rng.random(len(times)) < params.scan_efficiency)
    return times[heard], rssi[heard]


def _shadowing(count: int, params: RadioParams, rng: np.random.Generator) -> np.ndarray:
    """Stationary AR(1) shadowing (dB) at the advertising instants, SD `shadowing_db`."""
    noise = rng.normal(0.0, 1.0, count + 1)
    if params.shadowing_db <= 0:
        return np.zeros(count)
    correlation = math.exp(-params.advertising_interval_ms * 1e-3 / params.shadowing_time_s)
    scale = params.shadowing_db * math.sqrt(1.0 - correlation**2)
    start = noise[count] * params.shadowing_db * correlation  # a stationary state before the first instant
    return lfilter([scale], [1.0, -correlation], noise[:count], zi=[start])[0]

"""BLE beacons on each floor and what a phone's scan hears of them.

Beacons hang `ble.height_m` above their floor at the layout's beacon places (the first N per
floor). The venue file states each one's nominal tx power (-59 dBm at 1 m, the iBeacon figure);
the true one differs by up to `tx_power_error_db`. Every advertising event (interval + 0-10 ms
advDelay, a random start) is reported with chance `reception_chance`, when its RSSI is at least
`sensitivity_dbm`; the reported RSSI (whole dBm) is

    RSSI = tx_true - 10 n log10(d) - floor_loss x slabs - body_loss x blocking - S_b(x, y) + F + o   (eq. 1)

d: 3-D distance phone-beacon (at least 0.1 m); n: the venue's path-loss exponent (drawn once);
slabs: floors between the phone's storey and the beacon's; blocking in [0, 1]: how squarely the
walker's body lies between (the cosine of the angle between the direction to the beacon and the
phone's side of the body, negative part: the hand phone is in front of the body, the pocket phone
on its front right); S_b: shadowing, a Gaussian field over (x, y) per beacon and phone storey (SD
`shadowing_db`, correlation exp(-d^2 / 2 L^2), a sum of SHADOW_WAVES random plane waves with
wavevectors ~ N(0, 1/L^2) per axis); F: per-packet fading (SD `fading_db`); o: the phone's offset.
The world (beacon draws, exponent, shadowing) is drawn once per session; the offset per phone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.session import Beacon, Mount
from sim_devices.pedestrian.params import BleParams

NOMINAL_TX_DBM = -59.0  # the venue file's figure for every beacon
ADV_DELAY_MAX_S = 0.010  # BLE advDelay: 0-10 ms added to each advertising event
SHADOW_WAVES = 16
MIN_DISTANCE_M = 0.1
POCKET_SIDE_RAD = -math.radians(45.0)  # the pocket phone's outward side: front right of the body
BEACON_UUID = "f7826da6-4fa2-4e98-8024-bc5b71e0893e"  # a fixed, made-up iBeacon UUID for the venue


def venue_beacons(places: tuple[tuple[int, float, float], ...], per_floor: int, height_m: float) -> tuple[Beacon, ...]:
    """The first `per_floor` places of each floor as the venue file states them (nominal tx power)."""
    out = []
    for floor in sorted({place[0] for place in places}):
        mine = [place for place in places if place[0] == floor][:per_floor]
        for number, (_, x, y) in enumerate(mine, start=1):
            out.append(Beacon(f"b{floor}-{number}", x, y, tx_power_dbm=NOMINAL_TX_DBM, height_m=height_m,
                              identity=f"ibeacon:{BEACON_UUID}:{floor}:{number}", floor=floor))
    return tuple(out)


@dataclass(frozen=True)
class RadioWorld:
    beacons: tuple[Beacon, ...]
    tx_true_dbm: np.ndarray  # (b,)
    exponent: float
    shadow_k: np.ndarray  # (b, floors, waves, 2) rad/m
    shadow_phase: np.ndarray  # (b, floors, waves)
    shadow_amplitude_db: float
    floors: int

    @classmethod
    def draw(cls, beacons: tuple[Beacon, ...], floors: int, ble: BleParams, rng: np.random.Generator) -> "RadioWorld":
        count = len(beacons)
        tx = NOMINAL_TX_DBM + rng.uniform(-ble.tx_power_error_db, ble.tx_power_error_db, count)
        exponent = float(rng.uniform(ble.path_loss_exponent_min, ble.path_loss_exponent_max))
        k = rng.normal(0.0, 1.0 / ble.shadowing_distance_m, (count, floors, SHADOW_WAVES, 2))
        phase = rng.uniform(0.0, 2.0 * math.pi, (count, floors, SHADOW_WAVES))
        return cls(beacons, tx, exponent, k, phase, ble.shadowing_db * math.sqrt(2.0 / SHADOW_WAVES), floors)

    def shadowing_db(self, index: int, storey: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """S_b at (n, 2) positions on storeys (n,) (clipped to the floors drawn)."""
        rows = np.clip(storey, 0, self.floors - 1)
        k, phase = self.shadow_k[index][rows], self.shadow_phase[index][rows]  # (n, waves, 2), (n, waves)
        return self.shadow_amplitude_db * np.sum(np.cos(np.einsum("nwj,nj->nw", k, xy) + phase), axis=1)

    def record(self) -> dict[str, object]:
        return {"path_loss_exponent": self.exponent,
                "tx_power_dbm": {b.id: float(tx) for b, tx in zip(self.beacons, self.tx_true_dbm)}}


@dataclass(frozen=True)
class Sightings:
    sensor_id: str
    walker_s: np.ndarray  # (n,) reception times from the walker's start
    beacon_index: np.ndarray  # (n,) into RadioWorld.beacons
    rssi_dbm: np.ndarray  # (n,) whole dBm
    offset_db: float


def scan(sensor_id: str, mount: Mount, walker_time_s: np.ndarray, position_m: np.ndarray, body_yaw_rad: np.ndarray,
         world: RadioWorld, floor_height_m: float, ble: BleParams, rng: np.random.Generator) -> Sightings:
    """One phone's sightings over its walk: motion (IMU rate) -> every beacon's received advertisements."""
    duration = float(walker_time_s[-1])
    rate = 1.0 / float(walker_time_s[1] - walker_time_s[0])
    offset = float(rng.normal(0.0, ble.phone_offset_db))
    side = POCKET_SIDE_RAD if mount is Mount.POCKET else 0.0
    interval = ble.advertising_interval_ms * 1e-3
    times, indices, values = [], [], []
    for index, beacon in enumerate(world.beacons):
        count = int(duration / interval) + 2
        events = rng.uniform(0.0, interval) + np.cumsum(interval + rng.uniform(0.0, ADV_DELAY_MAX_S, count))
        events = events[events <= duration]
        heard = rng.random(len(events)) < ble.reception_chance
        fading = rng.normal(0.0, ble.fading_db, len(events))
        events, fading = events[heard], fading[heard]
        rows = np.minimum(np.round(events * rate).astype(np.int64), len(walker_time_s) - 1)
        phone = position_m[rows]
        storey = np.floor(phone[:, 2] / floor_height_m).astype(np.int64) if floor_height_m > 0 else np.zeros(len(rows), np.int64)
        target = np.array([beacon.x_m, beacon.y_m, beacon.floor * floor_height_m + beacon.height_m])
        offset_m = target[None, :] - phone
        distance = np.maximum(np.linalg.norm(offset_m, axis=1), MIN_DISTANCE_M)
        facing = body_yaw_rad[rows] + side
        horizontal = np.maximum(np.hypot(offset_m[:, 0], offset_m[:, 1]), 1e-6)
        cosine = (offset_m[:, 0] * np.cos(facing) + offset_m[:, 1] * np.sin(facing)) / horizontal
        blocking = np.clip(-cosine, 0.0, 1.0)
        slabs = np.abs(storey - beacon.floor)
        rssi = (world.tx_true_dbm[index] - 10.0 * world.exponent * np.log10(distance)  # eq. 1
                - ble.floor_loss_db * slabs - ble.body_loss_db * blocking
                - world.shadowing_db(index, storey, phone[:, :2]) + fading + offset)
        rssi = np.round(rssi)
        keep = rssi >= ble.sensitivity_dbm
        times.append(events[keep]), indices.append(np.full(int(keep.sum()), index)), values.append(rssi[keep])
    walker_s = np.concatenate(times) if times else np.zeros(0)
    order = np.argsort(walker_s, kind="stable")
    return Sightings(sensor_id, walker_s[order], np.concatenate(indices)[order].astype(np.int64) if indices
                     else np.zeros(0, np.int64), np.concatenate(values)[order] if values else np.zeros(0), offset)

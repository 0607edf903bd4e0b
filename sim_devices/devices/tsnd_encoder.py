"""Samples -> ATR-Promotions TSND121/151 frames: the inverse of `edge.decoders.tsnd`.

0x80: `9A 80 | tick u32 | acc x y z | gyro x y z | BCC`, the six values 3-byte signed
little-endian in 0.1 mg and 0.01 deg/s; 0x81: `9A 81 | tick | mag x y z | BCC` in 0.1 uT.
The tick is the device clock in ms since midnight (time_ns // 1e6 modulo a day). Values are
rounded to the wire's units and clipped to a range (the device saturates at its range; the
3-byte field holds +-838 g). Encoding is vectorised: a 1000 Hz hour is 3.6 M frames.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from edge.decoders.tsnd import ACC_GYRO, DAY_MS, DPS_PER_COUNT, G_PER_COUNT, HEADER, MAGNETOMETER, UT_PER_COUNT

INT24_MAX = 2**23 - 1
INERTIAL_BYTES = 25  # 9A, code, 22 parameter bytes, BCC
MAGNETOMETER_BYTES = 16  # 9A, code, 13 parameter bytes, BCC


def ticks_ms(time_ns: np.ndarray) -> np.ndarray:
    """Device clock ns (any epoch) -> TSND ticks: whole ms, modulo one day."""
    return (np.asarray(time_ns, dtype=np.int64) // 1_000_000) % DAY_MS


def counts(values: np.ndarray, per_count: float, limit: float) -> np.ndarray:
    """Physical values -> integer counts, rounded, clipped to +-limit (in physical units)."""
    clipped = np.clip(np.asarray(values, dtype=np.float64), -limit, limit)
    return np.clip(np.rint(clipped / per_count), -INT24_MAX, INT24_MAX).astype(np.int64)


def _frames(code: int, ticks: np.ndarray, fields: np.ndarray) -> np.ndarray:
    """(N,) ticks and (N, K) int counts -> (N, 2 + 4 + 3K + 1) uint8 frames."""
    n = len(ticks)
    tick_bytes = np.asarray(ticks, dtype="<u4").view(np.uint8).reshape(n, 4)
    # little-endian int32 two's complement, low three bytes: the 3-byte signed field
    value_bytes = np.asarray(fields, dtype="<i4").view(np.uint8).reshape(n, -1, 4)[:, :, :3].reshape(n, -1)
    head = np.tile(np.array([HEADER, code], dtype=np.uint8), (n, 1))
    body = np.concatenate([head, tick_bytes, value_bytes], axis=1)
    check = np.bitwise_xor.reduce(body, axis=1).reshape(n, 1)
    return np.concatenate([body, check], axis=1)


def inertial_frames(time_ns: np.ndarray, accel_g: np.ndarray, gyro_dps: np.ndarray, *,
                    acc_range_g: float = 16.0, gyro_range_dps: float = 2000.0) -> np.ndarray:
    """(N, 25) uint8: one 0x80 frame per sample, values clipped to the ranges."""
    fields = np.concatenate([counts(accel_g, G_PER_COUNT, acc_range_g),
                             counts(gyro_dps, DPS_PER_COUNT, gyro_range_dps)], axis=1)
    return _frames(ACC_GYRO, ticks_ms(time_ns), fields)


def magnetometer_frames(time_ns: np.ndarray, mag_gauss: np.ndarray) -> np.ndarray:
    """(N, 16) uint8: one 0x81 frame per sample (gauss -> 0.1 uT; 1 gauss = 100 uT)."""
    ut = np.asarray(mag_gauss, dtype=np.float64) * 100.0
    return _frames(MAGNETOMETER, ticks_ms(time_ns), counts(ut, UT_PER_COUNT, INT24_MAX * UT_PER_COUNT))


def encode_samples(time_ns: np.ndarray, accel_g: np.ndarray, gyro_dps: np.ndarray,
                   mag_gauss: np.ndarray | None = None, *, mag_every: int = 10) -> Iterator[tuple[int, bytes]]:
    """Yield (time_ns, frame bytes) in stream order. A 0x81 frame goes out just before the 0x80
    of every `mag_every`-th sample (so a batcher pairs that sample with it); None: no 0x81."""
    if mag_every < 1:
        raise ValueError(f"mag_every {mag_every} must be >= 1")
    inertial = inertial_frames(time_ns, accel_g, gyro_dps)
    magnetometer = None if mag_gauss is None else magnetometer_frames(time_ns, mag_gauss)
    for i, stamp in enumerate(np.asarray(time_ns, dtype=np.int64).tolist()):
        if magnetometer is not None and i % mag_every == 0:
            yield stamp, magnetometer[i].tobytes()
        yield stamp, inertial[i].tobytes()


def fuzz_frames(rng: np.random.Generator, start_ms: int, count: int) -> list[bytes]:
    """`reckon fuzz`'s intact frames (edge.decoders.tsnd.DEVICE): `count` 0x80 frames 1 ms apart (a
    0x81 every 10th) with random in-range values."""
    time_ns = (start_ms + np.arange(count, dtype=np.int64)) * 1_000_000
    accel, gyro = rng.uniform(-15.9, 15.9, (count, 3)), rng.uniform(-1990, 1990, (count, 3))
    mag = rng.uniform(-0.6, 0.6, (count, 3))
    return [frame for _, frame in encode_samples(time_ns, accel, gyro, mag, mag_every=10)]

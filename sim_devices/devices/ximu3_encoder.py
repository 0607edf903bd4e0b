"""Samples -> x-io x-IMU3 data-message bytes: the inverse of `edge.decoders.ximu3`.

Layouts (x-IMU3 User Manual, "Data messages"): binary = id (ASCII id + 0x80), u64 timestamp us,
little-endian f32 arguments, byte-stuffed (0x0A -> DB DC, 0xDB -> DB DD), then LF; ASCII =
`I,<timestamp us>,gx,gy,gz,ax,ay,az\\r\\n` with four decimal places, as the device prints them.
Units: gyro deg/s, accel g, magnetometer a.u. (1 a.u. ~ 50 uT, see MAG_UT_PER_AU).
"""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from edge.decoders.ximu3 import BINARY_INERTIAL, BINARY_MAGNETOMETER, MAG_UT_PER_AU

ASCII_DECIMALS = 4  # the device's own ASCII precision


def stuff(body: bytes) -> bytes:
    """Byte stuffing of a binary message body (without its LF). ESC first, so new ESCs stay single."""
    return body.replace(b"\xdb", b"\xdb\xdd").replace(b"\n", b"\xdb\xdc")


def inertial_binary(timestamp_us: int, gyro_dps: Sequence[float], accel_g: Sequence[float]) -> bytes:
    body = BINARY_INERTIAL.pack(ord("I") + 0x80, timestamp_us, *gyro_dps, *accel_g)
    return stuff(body) + b"\n"


def magnetometer_binary(timestamp_us: int, mag_au: Sequence[float]) -> bytes:
    return stuff(BINARY_MAGNETOMETER.pack(ord("M") + 0x80, timestamp_us, *mag_au)) + b"\n"


def inertial_ascii(timestamp_us: int, gyro_dps: Sequence[float], accel_g: Sequence[float]) -> bytes:
    numbers = ",".join(f"{value:.{ASCII_DECIMALS}f}" for value in (*gyro_dps, *accel_g))
    return f"I,{timestamp_us},{numbers}\r\n".encode("ascii")


def magnetometer_ascii(timestamp_us: int, mag_au: Sequence[float]) -> bytes:
    numbers = ",".join(f"{value:.{ASCII_DECIMALS}f}" for value in mag_au)
    return f"M,{timestamp_us},{numbers}\r\n".encode("ascii")


def time_ns_to_us(time_ns: int) -> int:
    """Device clock ns -> the x-IMU3's whole microseconds (rounded to nearest)."""
    return (int(time_ns) + 500) // 1000


def encode_samples(time_ns: np.ndarray, gyro_dps: np.ndarray, accel_g: np.ndarray,
                   mag_gauss: np.ndarray | None = None, *, ascii: bool = False, mag_every: int = 1,
                   ut_per_au: float = MAG_UT_PER_AU) -> Iterator[tuple[int, bytes]]:
    """Yield (time_ns, message bytes) per message, in stream order.

    time_ns int (N,), gyro_dps/accel_g (N, 3), mag_gauss (N, 3) or None. A magnetometer message
    (sample i's field, converted to a.u.) goes out just before inertial sample i for every
    `mag_every`-th sample, so a decoder pairing "latest magnetometer reading" pairs it with i.
    """
    if mag_every < 1:
        raise ValueError(f"mag_every {mag_every} must be >= 1")
    inertial = inertial_ascii if ascii else inertial_binary
    magnetometer = magnetometer_ascii if ascii else magnetometer_binary
    au_per_gauss = 100.0 / ut_per_au
    gyro = np.asarray(gyro_dps, dtype=np.float64).tolist()
    accel = np.asarray(accel_g, dtype=np.float64).tolist()
    mag = None if mag_gauss is None else (np.asarray(mag_gauss, dtype=np.float64) * au_per_gauss).tolist()
    for i, stamp in enumerate(np.asarray(time_ns, dtype=np.int64).tolist()):
        timestamp_us = time_ns_to_us(stamp)
        if mag is not None and i % mag_every == 0:
            yield stamp, magnetometer(timestamp_us, mag[i])
        yield stamp, inertial(timestamp_us, gyro[i], accel[i])


def fuzz_frames(rng: np.random.Generator, start_ms: int, count: int) -> list[bytes]:
    """`reckon fuzz`'s intact frames (edge.decoders.ximu3.DEVICE): `count` I messages 1 ms apart (an
    M every 10th), binary or ASCII as the block draws."""
    time_ns = (start_ms + np.arange(count, dtype=np.int64)) * 1_000_000
    gyro, accel = rng.uniform(-1990, 1990, (count, 3)), rng.uniform(-15.9, 15.9, (count, 3))
    mag = rng.uniform(-0.6, 0.6, (count, 3))
    ascii = bool(rng.integers(0, 2))
    return [frame for _, frame in encode_samples(time_ns, gyro, accel, mag, ascii=ascii, mag_every=10)]

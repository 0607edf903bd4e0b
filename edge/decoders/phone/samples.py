"""A phone's motion samples -> ImuBatch messages: checks, acceleration units, alignment, batching.

Pure (no socket, no clock, no asyncio): edge/sources/phone/server.py feeds it what edge/decoders/phone/parse.py
parsed and stamps `received_ns`; edge/decoders/phone/rotation.py tells the rotation rate's unit. These
live in reckon/ beside their only adapter; they could move to edge/decoders/.

Frame: the phone's, Android's convention (x right, y to the top of the screen, z out of it), as
both inputs report. In: m/s^2, deg/s, uT. Out: g (m/s^2 / 9.80665), deg/s, gauss (uT / 100).

Per-sample problems (NaN, time going backwards) drop that sample only, a gap closes the batch
early; all are counted in `Counters` and described in the `problems` list each `feed` returns,
which the adapter logs at a limited rate. Acceleration reported in g instead of m/s^2 (|a| near
1 at rest) is detected per window of `unit_window` samples and converted (a problem says so);
acceleration without gravity (|a| near 0, e.g. a "linear acceleration" sensor) is refused,
counted, and re-checked on every window, so a stream that gets better is taken again.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocol import messages
from protocol.errors import ConfigError
from protocol.messages import STANDARD_GRAVITY_MS2, UT_PER_GAUSS
from edge.decoders.phone.parse import Sample

# |a| averaged over a window: gravity in m/s^2 is 9.8; the same in g is 1. Walking swings |a| by
# +-50 %, so the bands are wide; between them nothing can be told and the window is refused.
MS2_BAND = (6.0, 14.0)
G_BAND = (0.6, 1.4)
MAX_ABS_ACCEL_MS2 = 2000.0  # ~200 g: beyond any phone's range, a broken value
MAX_ABS_GYRO_DPS = 20000.0  # ~55 rev/s: ditto
MAX_ABS_MAG_UT = 10000.0


@dataclass(frozen=True)
class PhoneSettings:
    """samples_per_batch: samples per ImuBatch (default 25: 4 batches/s at a phone's 100 Hz).
    gap_ns: a step between samples longer than this is a gap: the batch closes, `gaps` counts
    it (default 0.25 s: browsers deliver 60-100 Hz, a backgrounded page stops for seconds).
    max_mag_age_ns: a magnetometer reading further from a sample than this is not paired with it
    (default 0.2 s). unit_window: samples averaged to tell m/s^2 from g (default 25).
    max_pending: accelerometer readings held waiting for a later gyroscope reading (default 2000,
    20 s at 100 Hz); beyond that the oldest are refused as "no gyroscope"."""

    samples_per_batch: int = 25
    gap_ns: int = 250_000_000
    max_mag_age_ns: int = 200_000_000
    unit_window: int = 25
    max_pending: int = 2000

    def __post_init__(self) -> None:
        for name, value, low, high in (("samples_per_batch", self.samples_per_batch, 1, 10_000),
                                       ("gap_ns", self.gap_ns, 1, 4_000_000_000),
                                       ("max_mag_age_ns", self.max_mag_age_ns, 0, 10_000_000_000),
                                       ("unit_window", self.unit_window, 1, 10_000),
                                       ("max_pending", self.max_pending, 1, 1_000_000)):
            if not low <= value <= high:
                raise ConfigError(f"phone settings: {name} {value} is outside [{low}, {high}]")


@dataclass
class Counters:
    """What came in and what was done with it; every field a count."""

    messages: int = 0
    samples_in: int = 0
    samples_out: int = 0
    batches: int = 0
    bad_messages: int = 0  # not JSON, wrong shape: the whole message
    non_finite: int = 0  # NaN, inf, null or out-of-range values: the sample
    backwards: int = 0  # time not after the previous sample's: the sample
    gaps: int = 0
    converted_g: int = 0  # samples reported in g, converted
    converted_rad_s: int = 0  # samples whose rotation rate came in rad/s, converted
    refused_units: int = 0  # samples whose units could not be told (no gravity)
    without_gyro: int = 0  # accelerometer readings with no gyroscope reading around them
    ignored_names: int = 0  # Sensor Logger readings of other sensors
    orientation: int = 0  # DeviceOrientation samples (no protocol message carries them yet)
    scans: int = 0


def _finite(xyz: tuple[float, float, float] | None, limit: float) -> bool:
    return xyz is None or all(math.isfinite(v) and abs(v) <= limit for v in xyz)


class Aligner:
    """Sensor Logger's separate streams -> paired samples at the accelerometer's times.

    The rotation rate at an accelerometer time is interpolated linearly between the gyroscope
    readings on either side, so an accelerometer reading waits (in `pending`, bounded) until a
    gyroscope reading at or after it arrives, possibly in a later push. The magnetometer reading
    is the latest at or before the sample, if within max_mag_age_ns. Readings whose time goes
    backwards within their stream are dropped and counted."""

    def __init__(self, settings: PhoneSettings, counters: Counters):
        self.settings, self.counters = settings, counters
        self.pending: deque[tuple[int, tuple[float, float, float]]] = deque()  # bounded by max_pending
        self._gyro_before: tuple[int, tuple[float, float, float]] | None = None
        self._mag: tuple[int, tuple[float, float, float]] | None = None
        self._last = {"accel": -1, "gyro": -1, "mag": -1}

    def _ordered(self, name: str, readings: list[tuple[int, tuple[float, float, float]]],
                 problems: list[str]) -> list[tuple[int, tuple[float, float, float]]]:
        kept = []
        for reading in sorted(readings, key=lambda r: r[0]):  # a push may list a stream out of order
            if reading[0] <= self._last[name]:
                self.counters.backwards += 1
                problems.append(f"{name} reading at {reading[0]} ns is not after the previous one "
                                f"({self._last[name]} ns): dropped")
                continue
            self._last[name] = reading[0]
            kept.append(reading)
        return kept

    def feed(self, streams: dict[str, list[tuple[int, tuple[float, float, float]]]], problems: list[str]) -> list[Sample]:
        accel = self._ordered("accel", streams.get("accel", []), problems)
        gyro = self._ordered("gyro", streams.get("gyro", []), problems)
        mags = self._ordered("mag", streams.get("mag", []), problems)
        self.pending.extend(accel)
        out: list[Sample] = []
        mag_index = 0
        for time_ns, rate in gyro:
            while self.pending and self.pending[0][0] <= time_ns:
                a_time, a_xyz = self.pending.popleft()
                before = self._gyro_before
                if before is None:
                    if a_time < time_ns:  # before the first gyroscope reading: nothing to pair with
                        self.counters.without_gyro += 1
                        continue
                    gyro_dps = rate
                else:
                    w = (a_time - before[0]) / (time_ns - before[0])
                    gyro_dps = tuple(b + w * (r - b) for b, r in zip(before[1], rate))  # type: ignore[assignment]
                while mag_index < len(mags) and mags[mag_index][0] <= a_time:
                    self._mag = mags[mag_index]
                    mag_index += 1
                mag = self._mag[1] if self._mag and a_time - self._mag[0] <= self.settings.max_mag_age_ns else None
                out.append((a_time, a_xyz, gyro_dps, mag))  # type: ignore[arg-type]
            self._gyro_before = (time_ns, rate)
        if mag_index < len(mags):
            self._mag = mags[-1]
        overflow = len(self.pending) - self.settings.max_pending
        if overflow > 0:
            for _ in range(overflow):
                self.pending.popleft()
            self.counters.without_gyro += overflow
            problems.append(f"{overflow} accelerometer readings refused: no gyroscope reading after them "
                            f"(more than {self.settings.max_pending} waiting); turn the gyroscope on in the app")
        return out


class MotionBatcher:
    """Paired samples -> ImuBatch messages (g, deg/s, gauss), in order, with the checks above.

    `feed(samples) -> (batches, problems)`; `flush()` at the end of the stream returns the held
    samples. A batch carries `mag_gauss` only when every sample has a reading. Memory is bounded:
    one batch and one unit window."""

    def __init__(self, agent_id: str, sensor_id: str, settings: PhoneSettings | None = None,
                 counters: Counters | None = None):
        self.agent_id, self.sensor_id = agent_id, sensor_id
        self.settings = settings or PhoneSettings()
        self.counters = counters or Counters()
        self.sequence = 0  # of the next batch
        self.scale: float | None = None  # m/s^2 per reported unit, once told; None while undecided
        self.gyro_scale = 1.0  # deg/s per reported unit: RotationUnitCheck sets it for a phone in rad/s
        self._window: list[Sample] = []  # samples waiting for the unit decision
        self._batch: list[Sample] = []
        self._last_ns = -1

    def feed(self, samples: list[Sample]) -> tuple[list[Any], list[str]]:
        out: list[Any] = []
        problems: list[str] = []
        for sample in samples:
            self.counters.samples_in += 1
            time_ns, accel, gyro, mag = sample
            if time_ns < 0 or not (_finite(accel, MAX_ABS_ACCEL_MS2) and _finite(gyro, MAX_ABS_GYRO_DPS)
                                   and _finite(mag, MAX_ABS_MAG_UT)):
                self.counters.non_finite += 1
                problems.append(f"sample at {time_ns} ns has a missing, NaN or out-of-range value: dropped")
                continue
            if time_ns <= self._last_ns:
                self.counters.backwards += 1
                problems.append(f"sample at {time_ns} ns is not after the previous one ({self._last_ns} ns): dropped")
                continue
            self._last_ns = time_ns
            self._window.append(sample)
            if len(self._window) >= self.settings.unit_window:
                self._release(out, problems)
        return out, problems

    def flush(self) -> tuple[list[Any], list[str]]:
        out: list[Any] = []
        problems: list[str] = []
        if self._window:
            self._release(out, problems)
        self._close(out)
        return out, problems

    def _release(self, out: list[Any], problems: list[str]) -> None:
        """Decide the window's acceleration unit, then batch it (or refuse it)."""
        window, self._window = self._window, []
        mean = sum(math.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2) for _, a, _, _ in window) / len(window)
        if MS2_BAND[0] <= mean <= MS2_BAND[1]:
            scale = 1.0
        elif G_BAND[0] <= mean <= G_BAND[1]:
            scale = STANDARD_GRAVITY_MS2
            self.counters.converted_g += len(window)
            if self.scale != scale:
                problems.append(f"acceleration looks like g, not m/s^2 (mean |a| {mean:.2f} over {len(window)} "
                                "samples, 9.8 expected): converting")
        else:
            self.counters.refused_units += len(window)
            problems.append(f"acceleration refused: mean |a| {mean:.2f} over {len(window)} samples is neither "
                            f"gravity in m/s^2 ({MS2_BAND[0]}-{MS2_BAND[1]}) nor in g ({G_BAND[0]}-{G_BAND[1]}); "
                            "send acceleration including gravity")
            return
        self.scale = scale
        for time_ns, accel, gyro, mag in window:
            if self._batch and (time_ns - self._batch[-1][0] > self.settings.gap_ns):
                self.counters.gaps += 1
                problems.append(f"gap of {(time_ns - self._batch[-1][0]) / 1e6:.0f} ms before {time_ns} ns "
                                f"(more than {self.settings.gap_ns / 1e6:.0f} ms)")
                self._close(out)
            elif self._batch and time_ns - self._batch[0][0] > 0xFFFFFFFF:  # uint32 offsets: 4.29 s
                self._close(out)
            turn = self.gyro_scale
            if turn != 1.0:
                self.counters.converted_rad_s += 1
            self._batch.append((time_ns, (accel[0] * scale, accel[1] * scale, accel[2] * scale),
                                (gyro[0] * turn, gyro[1] * turn, gyro[2] * turn), mag))
            if len(self._batch) >= self.settings.samples_per_batch:
                self._close(out)

    def _close(self, out: list[Any]) -> None:
        if not self._batch:
            return
        batch, self._batch = self._batch, []
        times = np.array([s[0] for s in batch], dtype=np.int64)
        accel_g = np.array([s[1] for s in batch]) / STANDARD_GRAVITY_MS2
        gyro_dps = np.array([s[2] for s in batch])
        mag = None if any(s[3] is None for s in batch) else np.array([s[3] for s in batch]) / UT_PER_GAUSS
        out.append(messages.imu_batch(self.agent_id, self.sensor_id, self.sequence, times, accel_g, gyro_dps, mag))
        self.sequence += 1
        self.counters.batches += 1
        self.counters.samples_out += len(batch)

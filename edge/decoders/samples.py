"""One device's decoded x-IMU3 frames -> `ImuBatch` messages of a fixed size, in constant memory.

Each inertial sample is paired with the latest magnetometer reading, or with none when there has
been none within `max_mag_age_us`. A batch carries `mag_gauss` only when every one of its samples
has a reading (the schema's "empty when the device has no magnetometer"). Times stay in the
device clock: timestamp_ns = timestamp_us * 1000.

A batch is closed early, never split or reordered, when the next sample is not later than the
previous one (device reset or repeated sample: counted in `clock_jumps`) or lies beyond the
4.29 s a uint32 sample offset holds. Rejected frames are ignored here (the decoder counts them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable

from edge.decoders.ximu3 import MAG_UT_PER_AU, Frame, InertialFrame, MagnetometerFrame
from protocol import messages
from protocol.errors import ConfigError

MAX_OFFSET_NS = 0xFFFFFFFF  # ImuBatch.sample_offset_ns is uint32


@dataclass(frozen=True)
class BatchSettings:
    """samples_per_batch: samples per ImuBatch (default 20: 10 batches/s at 200 Hz, ~0.8 KB each;
    larger saves bandwidth, smaller cuts latency). max_mag_age_us: a magnetometer reading further
    than this from an inertial sample is not paired with it (default 0.5 s; the x-IMU3 samples its
    magnetometer at 20 Hz). mag_ut_per_au: field strength of 1 a.u. in uT (default 50, see
    edge.decoders.ximu3.MAG_UT_PER_AU)."""

    samples_per_batch: int = 20
    max_mag_age_us: int = 500_000
    mag_ut_per_au: float = MAG_UT_PER_AU

    def __post_init__(self) -> None:
        if not 1 <= self.samples_per_batch <= 10_000:
            raise ConfigError(f"samples_per_batch: {self.samples_per_batch} is outside [1, 10000]")
        if self.max_mag_age_us < 0:
            raise ConfigError(f"max_mag_age_us: {self.max_mag_age_us} is negative")
        if not 0.0 < self.mag_ut_per_au < 1e4:
            raise ConfigError(f"mag_ut_per_au: {self.mag_ut_per_au} is outside (0, 10000)")


class ImuBatcher:
    """`feed(frames) -> list[ImuBatch]`, `flush() -> list[ImuBatch]` at end of stream."""

    def __init__(self, agent_id: str, sensor_id: str, settings: BatchSettings | None = None):
        self.agent_id, self.sensor_id = agent_id, sensor_id
        self.settings = settings or BatchSettings()
        size = self.settings.samples_per_batch
        self._gauss_per_au = self.settings.mag_ut_per_au / 100.0
        # Preallocated, reused for every batch: memory does not grow with the stream.
        self._time_ns = [0] * size
        self._gyro = [0.0] * (3 * size)
        self._accel = [0.0] * (3 * size)
        self._mag = [0.0] * (3 * size)
        self._count = 0
        self._all_have_mag = True
        self._mag_time_us: int | None = None
        self._mag_gauss = (0.0, 0.0, 0.0)
        self.sequence = 0  # of the next batch
        self.samples = 0
        self.batches = 0
        self.samples_without_mag = 0
        self.clock_jumps = 0

    def feed(self, frames: Iterable[Frame]) -> list[Any]:
        out: list[Any] = []
        for frame in frames:
            if isinstance(frame, InertialFrame):
                self._add(frame, out)
            elif isinstance(frame, MagnetometerFrame):
                self._mag_time_us = frame.timestamp_us
                scale = self._gauss_per_au
                self._mag_gauss = (frame.mag_au[0] * scale, frame.mag_au[1] * scale, frame.mag_au[2] * scale)
        return out

    def flush(self) -> list[Any]:
        """Emit the partial batch, if any."""
        out: list[Any] = []
        if self._count:
            out.append(self._emit())
        return out

    def _add(self, frame: InertialFrame, out: list[Any]) -> None:
        time_ns = frame.timestamp_us * 1000
        count = self._count
        if count:
            if time_ns <= self._time_ns[count - 1]:
                self.clock_jumps += 1
                out.append(self._emit())
            elif time_ns - self._time_ns[0] > MAX_OFFSET_NS:
                out.append(self._emit())
            count = self._count
        self._time_ns[count] = time_ns
        i = 3 * count
        self._gyro[i:i + 3] = frame.gyro_dps
        self._accel[i:i + 3] = frame.accel_g
        mag_time = self._mag_time_us
        if mag_time is not None and abs(frame.timestamp_us - mag_time) <= self.settings.max_mag_age_us:
            self._mag[i:i + 3] = self._mag_gauss
        else:
            self._all_have_mag = False
            self.samples_without_mag += 1
        self._count = count + 1
        self.samples += 1
        if self._count == self.settings.samples_per_batch:
            out.append(self._emit())

    def _emit(self) -> Any:
        count, start = self._count, self._time_ns[0]
        batch = messages.new(
            "ImuBatch", timestamp_ns=start, agent_id=self.agent_id, sensor_id=self.sensor_id,
            sequence=self.sequence, sample_offset_ns=[t - start for t in self._time_ns[:count]],
            accel_g=self._accel[:3 * count], gyro_dps=self._gyro[:3 * count],
            mag_gauss=self._mag[:3 * count] if self._all_have_mag else [])
        self.sequence = (self.sequence + 1) & 0xFFFFFFFF
        self.batches += 1
        self._count = 0
        self._all_have_mag = True
        return batch

"""A simulated ATR-Promotions TSND121/151 on a real pseudo-terminal (`pty.PtyDevice`). Unlike the
x-IMU3 of `ximu3` it is commanded: it answers the host and streams only while measuring.

    with TsndDevice.from_session("swim.mcap", "swimmer-waist", speed=1) as dev:   # idle, listening
        with SerialSource.from_url(f"serial://{dev.port}?protocol=tsnd&rate_hz=1000") as source:
            ...   # the source's setup commands start the measurement; its teardown stops it

Commands (edge.decoders.tsnd builders) and answers:
- 0x13 start: 0x93 (status 1, start time of day, end "year 100" = none), then the 0x88 event, and
  0x80 frames stream from where the last measurement stopped (the first sample at first);
- 0x15 stop: 0x8F 00, then the 0x89 event (status 0) if it was measuring;
- 0x16 acc+gyro period, 0x18 magnetometer period, 0x22 / 0x25 ranges: 0x8F 00, or 0x8F 01 while
  measuring or for a value out of range;
- 0x3C status: 0xBC 02 (Bluetooth, command mode) or 03 (measuring); any other command: 0x8F 01.
When the samples run out the device stops by itself and sends 0x89.

Samples come at their own rate; a commanded period is met by sending every k-th sample, k =
period / sample period rounded, at least 1 (data at 200 Hz cannot stream at 1000 Hz). Each frame's
tick is its sample's own time (ms since midnight, see tsnd_encoder). A 0x81 frame (when 0x18 set
a period and the samples have a magnetometer) goes just before the 0x80 of the same sample.
Values are clipped to the commanded ranges (default +-16 g, +-2000 deg/s).

Pacing: after start, sample i is written at (time_ns[i] - time_ns[first]) / speed; speed 0 or inf
writes as fast as the reader takes it (the pty's small buffer holds the writer back).

Faults (`pty.Faults`, seeded, decided up front per sample index i, counted from 1 as i + 1):
garbage before every Nth sample's frames (never damages a frame), one byte dropped from every Nth
0x80 frame, one byte changed in every Nth 0x80 frame (its BCC then fails). `damaged` holds the
sample indices whose 0x80 frame was damaged; `streamed` the indices sent, in order.
"""

from __future__ import annotations

import os
import select
import threading
import time
from array import array
from pathlib import Path
from typing import Self

import numpy as np

from edge.decoders import tsnd
from edge.decoders.tsnd import TsndDecoder, TsndMessage, build_frame
from sim_devices.devices.pty import POLL_S, WRITE_BLOCK_BYTES, Faults, PtyDevice, session_series
from sim_devices.devices.tsnd_encoder import inertial_frames, magnetometer_frames

BLOCK_SAMPLES = 160  # samples encoded at once: about one 4 KB write
COMMAND_READ_BYTES = 4096  # host commands are a few bytes each: one read takes all that are waiting
NO_END = [100, 1, 1, 0, 0, 0]  # 0x93 end time meaning "none" (maselab checks for it)


class TsndDevice(PtyDevice):
    """Context manager: on enter the pty exists and the device listens; on exit it stops and
    closes both ends (a reader then sees the device disappear)."""

    def __init__(self, time_ns: np.ndarray, accel_g: np.ndarray, gyro_dps: np.ndarray,
                 mag_gauss: np.ndarray | None = None, *, speed: float = 1.0, faults: Faults | None = None):
        self.time_ns = np.asarray(time_ns, dtype=np.int64)
        count = len(self.time_ns)
        if count < 2 or np.any(np.diff(self.time_ns) <= 0):
            raise ValueError("time_ns must hold two or more strictly increasing times")
        for name, values in (("accel_g", accel_g), ("gyro_dps", gyro_dps), ("mag_gauss", mag_gauss)):
            if values is not None and np.shape(values) != (count, 3):
                raise ValueError(f"{name} has shape {np.shape(values)}, expected ({count}, 3)")
        super().__init__(speed=speed)
        self.accel_g, self.gyro_dps = np.asarray(accel_g, float), np.asarray(gyro_dps, float)
        self.mag_gauss = None if mag_gauss is None else np.asarray(mag_gauss, float)
        self.faults = faults or Faults()
        self.damaged = self._damaged_indices(count)
        self.sample_period_ns = int(np.median(np.diff(self.time_ns)))
        # device settings, as the host commands them (until then: the lcdsmao app's 10 ms, widest ranges)
        self.period_ms = 10
        self.mag_period_ms = 0
        self.acc_range_g, self.gyro_range_dps = 16, 2000
        self.measuring = False
        self.streamed = array("q")  # sample indices sent, in order
        self.commands: list[int] = []  # command codes received, in order
        self.finished = threading.Event()  # every sample was sent
        self.idle = threading.Event()  # not measuring (set until a start, and again after a stop)
        self.idle.set()
        self._next = 0  # next sample to send
        self._first = 0  # sample at which this measurement started (pacing origin)
        self._start_wall = 0.0
        self._out = bytearray()
        self._listener = TsndDecoder(tsnd.COMMAND_PARAM_BYTES)

    def open(self) -> Self:
        """Create the pty pair and start listening."""
        super().open()
        self._start_thread()
        return self

    def expected_indices(self) -> list[int]:
        """The streamed samples whose 0x80 frame arrived intact (a decoder must recover all of them)."""
        return [index for index in self.streamed if index not in self.damaged]

    # -- the device thread ----------------------------------------------------------------------

    def _serve(self, master: int) -> None:
        while not self._stop.is_set():
            wait_s = self._stream() if self.measuring else POLL_S
            # with bytes to write, select returns as soon as the pty takes more
            readable, writable, _ = select.select([master], [master] if self._out else [], [],
                                                  POLL_S if self._out else min(wait_s, POLL_S))
            if readable:
                self._commands(os.read(master, COMMAND_READ_BYTES))
            if writable and self._out:
                del self._out[:self._write(master, self._out)]

    def _commands(self, data: bytes) -> None:
        for frame in self._listener.feed(data):
            if isinstance(frame, TsndMessage):
                self.commands.append(frame.code)
                self._answer(frame.code, frame.params)

    def _answer(self, code: int, params: bytes) -> None:
        if code == 0x13:
            if self.measuring or self._next >= len(self.time_ns):  # already measuring, or nothing left
                self._send(tsnd.ACK, [1])
            else:
                self._start()
        elif code == 0x15:
            self._send(tsnd.ACK, [0])
            if self.measuring:
                self._end()
        elif code == 0x3C:
            self._send(0xBC, [3 if self.measuring else 2])
        elif code in (0x16, 0x18, 0x22, 0x25):
            self._send(tsnd.ACK, [0 if not self.measuring and self._setting(code, params) else 1])
        else:
            self._send(tsnd.ACK, [1])

    def _setting(self, code: int, params: bytes) -> bool:
        value = params[0]
        if code == 0x16 and 1 <= value <= tsnd.MAX_PERIOD_MS:
            self.period_ms = value
        elif code == 0x18 and (value == 0 or 10 <= value <= tsnd.MAX_PERIOD_MS):
            self.mag_period_ms = value
        elif code == 0x22 and value < len(tsnd.ACC_RANGES_G):
            self.acc_range_g = tsnd.ACC_RANGES_G[value]
        elif code == 0x25 and value < len(tsnd.GYRO_RANGES_DPS):
            self.gyro_range_dps = tsnd.GYRO_RANGES_DPS[value]
        else:
            return False
        return True

    def _start(self) -> None:
        seconds = int(self.time_ns[self._next] // 1_000_000_000) % 86_400
        # status 1 (set), start yy mm dd h m s: the samples carry no date, so 2000-01-01
        self._send(0x93, [1, 0, 1, 1, seconds // 3600, seconds // 60 % 60, seconds % 60] + NO_END)
        self._send(tsnd.STARTED, [0])
        self.measuring = True
        self.idle.clear()
        self._first, self._start_wall = self._next, time.monotonic()

    def _end(self) -> None:
        self.measuring = False
        self._send(tsnd.STOPPED, [0])  # 0: stopped by command or end time
        self.idle.set()

    def _send(self, code: int, params: list[int]) -> None:
        self._out += build_frame(code, params)

    def _stream(self) -> float:
        """Queue the frames that are due (at most one block); seconds until the next is due."""
        if len(self._out) >= WRITE_BLOCK_BYTES:
            return 0.0
        stride = max(1, round(self.period_ms * 1_000_000 / self.sample_period_ns))
        indices = np.arange(self._next, min(len(self.time_ns), self._next + stride * BLOCK_SAMPLES), stride)
        if len(indices) == 0:
            self._end()
            self.finished.set()
            return POLL_S
        if self.paced:
            due_s = self.due_s(self.time_ns[indices] - self.time_ns[self._first])
            elapsed_s = time.monotonic() - self._start_wall
            ready = int(np.searchsorted(due_s, elapsed_s, side="right"))
            if ready == 0:
                return float(due_s[0]) - elapsed_s  # > 0: not yet due
            indices = indices[:ready]
        self._queue(indices, stride)
        self._next = int(indices[-1]) + stride
        return 0.0

    def _queue(self, indices: np.ndarray, stride: int) -> None:
        inertial = inertial_frames(self.time_ns[indices], self.accel_g[indices], self.gyro_dps[indices],
                                   acc_range_g=self.acc_range_g, gyro_range_dps=self.gyro_range_dps)
        mag_stride = max(1, round(self.mag_period_ms * 1_000_000 / self.sample_period_ns))
        with_mag = self.mag_gauss is not None and self.mag_period_ms > 0
        magnetometer = magnetometer_frames(self.time_ns[indices], self.mag_gauss[indices]) if with_mag else None
        for row, index in enumerate(indices.tolist()):
            self._out += self._garbage_before(index)
            if magnetometer is not None and (index - self._first) % mag_stride < stride:  # one per mag period
                self._out += magnetometer[row].tobytes()
            self._out += self._damage(index, inertial[row].tobytes())
            self.streamed.append(index)

    # -- faults ---------------------------------------------------------------------------------

    def _damaged_indices(self, count: int) -> frozenset[int]:
        hit: set[int] = set()
        for every in (self.faults.drop_every, self.faults.corrupt_every):
            if every:
                hit.update(range(every - 1, count, every))
        return frozenset(hit)

    def _rng(self, index: int, purpose: int) -> np.random.Generator:
        return np.random.default_rng((self.faults.seed, purpose, index))  # per sample: independent of what streamed

    def _garbage_before(self, index: int) -> bytes:
        every = self.faults.garbage_every
        if not every or (index + 1) % every:
            return b""
        low, high = self.faults.garbage_bytes
        rng = self._rng(index, 0)
        return rng.integers(0, 256, int(rng.integers(low, high + 1)), dtype=np.uint8).tobytes()

    def _damage(self, index: int, frame: bytes) -> bytes:
        if index not in self.damaged:
            return frame
        rng = self._rng(index, 1)
        at = int(rng.integers(1, len(frame)))  # never the 0x9A: damage inside the frame
        if self.faults.drop_every and (index + 1) % self.faults.drop_every == 0:
            return frame[:at] + frame[at + 1:]
        return frame[:at] + bytes((frame[at] ^ int(rng.integers(1, 256)),)) + frame[at + 1:]

    # -- construction ---------------------------------------------------------------------------

    @classmethod
    def from_session(cls, session_path: Path | str, sensor_id: str, *, speed: float = 1.0,
                     faults: Faults | None = None) -> "TsndDevice":
        """Play one sensor of a session log (a simulated or imported swim)."""
        series = session_series(session_path, sensor_id)
        return cls(series.time_ns, series.accel_g, series.gyro_dps, series.mag_gauss, speed=speed, faults=faults)

"""A simulated x-IMU3 on a real pseudo-terminal: pyserial (and so `edge.sources.serial`)
opens `dev.port` exactly as it would open /dev/ttyUSB0.

    with SerialDevice.from_session("game.mcap", "chair01-seat", speed=20) as dev:
        with SerialSource(f"serial://{dev.port}?baud=115200") as source:  # open the reader first
            dev.play()
            ...
        dev.wait_done(timeout_s=5)

pyserial flushes the port's input when it opens it (tcflush), so bytes written before the reader
opened are gone, as they are with a real device: open the reader, then `play()`.

Pacing: message i is written at `(time_ns[i] - time_ns[0]) / speed` after `play()`; speed 0 or
inf writes as fast as the reader takes it. The pty's buffer is small (a few KB): a slow reader
slows the writer, nothing is dropped except by the fault injector.

Faults (seeded, decided up front so a test knows which messages were damaged): random garbage
before every Nth message (never damages a message), one byte dropped from every Nth message, an
invalid escape (0xDB 0x00) inserted into every Nth message. `damaged` lists the indices hit.
"""

from __future__ import annotations

import math
import os
import select
import threading
import time
import tty
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from protocol.errors import InputError
from sim_devices.devices.ximu3_encoder import encode_samples

WRITE_BLOCK_BYTES = 4096  # bytes gathered before one write when running ahead of schedule
POLL_S = 0.05  # how often a blocked writer checks for stop


@dataclass(frozen=True)
class Faults:
    """garbage_every / drop_every / corrupt_every: every Nth message (0 = never); garbage_bytes:
    inclusive range of garbage lengths (bytes drawn from 0..255, so 0x0A and 0xDB occur)."""

    seed: int = 0
    garbage_every: int = 0
    garbage_bytes: tuple[int, int] = (1, 32)
    drop_every: int = 0
    corrupt_every: int = 0


def _apply_faults(messages: Sequence[tuple[int, bytes]],
                  faults: Faults) -> tuple[list[tuple[int, bytes]], frozenset[int]]:
    """-> (stamp, bytes) to write, garbage sharing the stamp of the message it precedes; damaged indices."""
    rng = np.random.default_rng(faults.seed)
    plan: list[tuple[int, bytes]] = []
    damaged = set()
    low, high = faults.garbage_bytes
    for index, (stamp, message) in enumerate(messages):
        number = index + 1
        if faults.garbage_every and number % faults.garbage_every == 0:
            length = int(rng.integers(low, high + 1))
            plan.append((stamp, rng.integers(0, 256, length, dtype=np.uint8).tobytes()))
        if faults.drop_every and number % faults.drop_every == 0:
            cut = int(rng.integers(0, len(message)))
            message = message[:cut] + message[cut + 1:]
            damaged.add(index)
        if faults.corrupt_every and number % faults.corrupt_every == 0:
            at = int(rng.integers(1, max(2, len(message) - 1)))
            message = message[:at] + b"\xdb\x00" + message[at:]
            damaged.add(index)
        plan.append((stamp, message))
    return plan, frozenset(damaged)


class SerialDevice:
    """Plays a list of (time_ns, message bytes) into a pty. Context manager: opens on enter, stops
    and closes on exit; `play()` starts the writer thread; `wait_done()` waits for its end."""

    def __init__(self, messages: Sequence[tuple[int, bytes]], *, speed: float = 1.0, faults: Faults | None = None):
        if not speed >= 0.0:
            raise ValueError(f"speed {speed} must be >= 0 (0 or inf = as fast as possible)")
        self.messages = list(messages)  # (time_ns, bytes) as encoded, before faults
        self.speed = speed
        self.faults = faults or Faults()
        self._plan, self.damaged = _apply_faults(self.messages, self.faults)
        self.bytes_total = sum(len(payload) for _, payload in self._plan)
        self.bytes_written = 0
        self.port = ""  # slave path, set by open()
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._done = threading.Event()
        self.error: BaseException | None = None  # what ended the writer early, if anything

    def stream_bytes(self) -> bytes:
        """Every byte play() writes, in order (faults applied)."""
        return b"".join(payload for _, payload in self._plan)

    def open(self) -> "SerialDevice":
        """Create the pty pair; the slave is put in raw mode at once so that no byte is translated
        (CR/LF mapping, XON/XOFF, echo) before the reader configures the port."""
        if self._master is None:
            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.port = os.ttyname(self._slave)
        return self

    def play(self) -> None:
        """Start writing in a background thread (once)."""
        if self._master is None:
            self.open()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"SerialDevice {self.port}", daemon=True)
            self._thread.start()

    def wait_done(self, timeout_s: float) -> bool:
        """True once every byte has been written (or the writer stopped); False on timeout."""
        return self._done.wait(timeout_s)

    def close(self) -> None:
        """Stop the writer and close both ends: a reader then sees the device disappear (EIO)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = None
        self._done.set()

    def __enter__(self) -> "SerialDevice":
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- writer thread --------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            paced = 0.0 < self.speed < math.inf
            start = time.monotonic()
            first_stamp = self._plan[0][0] if self._plan else 0
            block = bytearray()
            for stamp, payload in self._plan:
                if paced:
                    due = start + (stamp - first_stamp) / 1e9 / self.speed
                    ahead = due - time.monotonic()
                    if ahead > 0:
                        if block and not self._write_all(block):
                            return
                        block.clear()
                        if self._stop.wait(ahead):
                            return
                block += payload
                if len(block) >= WRITE_BLOCK_BYTES:
                    if not self._write_all(block):
                        return
                    block.clear()
            if block:
                self._write_all(block)
        except OSError as error:  # the pty was closed under us
            self.error = error
        finally:
            self._done.set()

    def _write_all(self, data: bytearray) -> bool:
        view = memoryview(data)
        while view:
            if self._stop.is_set() or self._master is None:
                return False
            _, writable, _ = select.select([], [self._master], [], POLL_S)
            if not writable:
                continue
            try:
                written = os.write(self._master, view)
            except BlockingIOError:
                continue
            view = view[written:]
            self.bytes_written += written
        return True

    # -- construction ---------------------------------------------------------------------------

    @classmethod
    def from_arrays(cls, time_ns: np.ndarray, gyro_dps: np.ndarray, accel_g: np.ndarray,
                    mag_gauss: np.ndarray | None = None, *, ascii: bool = False, mag_every: int = 1,
                    speed: float = 1.0, faults: Faults | None = None) -> "SerialDevice":
        """Samples in device-clock ns, deg/s, g and gauss (None: no magnetometer messages)."""
        messages = list(encode_samples(time_ns, gyro_dps, accel_g, mag_gauss, ascii=ascii, mag_every=mag_every))
        return cls(messages, speed=speed, faults=faults)

    @classmethod
    def from_session(cls, session_path: Path | str, sensor_id: str, *, ascii: bool = False, mag_every: int = 1,
                     speed: float = 1.0, faults: Faults | None = None) -> "SerialDevice":
        """Play one sensor of a session log (a simulated or imported game)."""
        from protocol.session_log import read_session  # mcap only when a session is read

        data = read_session(session_path)
        if sensor_id not in data.imu:
            raise InputError(f"{session_path}: no IMU {sensor_id!r} (has: {', '.join(sorted(data.imu)) or 'none'})")
        series = data.imu[sensor_id]
        return cls.from_arrays(series.time_ns, series.gyro_dps, series.accel_g, series.mag_gauss,
                               ascii=ascii, mag_every=mag_every, speed=speed, faults=faults)

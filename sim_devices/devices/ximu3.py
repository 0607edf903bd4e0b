"""A simulated x-IMU3 on a real pseudo-terminal (`pty.PtyDevice`): pyserial (and so
`edge.sources.serial`) opens `dev.port` exactly as it would open /dev/ttyUSB0.

    with SerialDevice.from_session("game.mcap", "chair01-seat", speed=20) as dev:
        with SerialSource(f"serial://{dev.port}?baud=115200") as source:  # open the reader first
            dev.play()
            ...
        dev.wait_done(timeout_s=5)

pyserial flushes the port's input when it opens it (tcflush), so bytes written before the reader
opened are gone, as they are with a real device: open the reader, then `play()`.

Pacing: message i is written at `(time_ns[i] - time_ns[0]) / speed` after `play()`; speed 0 or
inf writes as fast as the reader takes it.

Faults (`pty.Faults`, seeded, decided up front so a test knows which messages were damaged):
random garbage before every Nth message (never damages a message), one byte dropped from every Nth
message, an invalid escape (0xDB 0x00) inserted into every Nth message. `damaged` lists the
indices hit.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from sim_devices.devices.pty import WRITE_BLOCK_BYTES, Faults, PtyDevice, session_series
from sim_devices.devices.ximu3_encoder import encode_samples


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


class SerialDevice(PtyDevice):
    """Plays a list of (time_ns, message bytes) into a pty. Context manager: opens on enter, stops
    and closes on exit; `play()` starts the writer thread; `wait_done()` waits for its end."""

    def __init__(self, messages: Sequence[tuple[int, bytes]], *, speed: float = 1.0, faults: Faults | None = None):
        super().__init__(speed=speed)
        self.messages = list(messages)  # (time_ns, bytes) as encoded, before faults
        self.faults = faults or Faults()
        self._plan, self.damaged = _apply_faults(self.messages, self.faults)
        self.bytes_total = sum(len(payload) for _, payload in self._plan)
        self._done = threading.Event()

    def stream_bytes(self) -> bytes:
        """Every byte play() writes, in order (faults applied)."""
        return b"".join(payload for _, payload in self._plan)

    def play(self) -> None:
        """Start writing in a background thread (once)."""
        self.open()
        self._start_thread()

    def wait_done(self, timeout_s: float) -> bool:
        """True once every byte has been written (or the writer stopped); False on timeout."""
        return self._done.wait(timeout_s)

    def close(self) -> None:
        super().close()
        self._done.set()

    # -- writer thread --------------------------------------------------------------------------

    def _serve(self, master: int) -> None:
        start = time.monotonic()
        first_stamp = self._plan[0][0] if self._plan else 0
        block = bytearray()
        for stamp, payload in self._plan:
            if self.paced:
                ahead = start + self.due_s(stamp - first_stamp) - time.monotonic()
                if ahead > 0:
                    if block and not self._write_all(master, block):
                        return
                    block.clear()
                    if self._stop.wait(ahead):
                        return
            block += payload
            if len(block) >= WRITE_BLOCK_BYTES:
                if not self._write_all(master, block):
                    return
                block.clear()
        if block:
            self._write_all(master, block)

    def _ended(self) -> None:
        self._done.set()

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
        series = session_series(session_path, sensor_id)
        return cls.from_arrays(series.time_ns, series.gyro_dps, series.accel_g, series.mag_gauss,
                               ascii=ascii, mag_every=mag_every, speed=speed, faults=faults)

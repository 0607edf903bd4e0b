"""What every simulated serial device shares: a real pseudo-terminal, one device thread, pacing, faults.

pyserial (and so `edge.sources.serial`) opens `device.port` exactly as it would open /dev/ttyUSB0.
The slave end is put in raw mode as soon as the pair exists, so that no byte is translated (CR/LF
mapping, XON/XOFF, echo) before the reader configures the port; the master end is non-blocking and
the device thread waits on `select`, checking for stop every `POLL_S`. The pty's buffer is small
(a few KB): a slow reader slows the writer, nothing is dropped except by the fault injector.

Pacing: a sample `offset_ns` after the first is due `offset_ns / speed` after the device starts;
speed 0 or inf writes as fast as the reader takes it.

A subclass writes `_serve` (the thread's body); `close()` stops the thread and closes both ends,
and a reader then sees the device disappear (EIO).
"""

from __future__ import annotations

import math
import os
import select
import threading
import tty
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Self, overload

import numpy as np

from protocol.errors import InputError

if TYPE_CHECKING:
    from protocol.session_log import ImuSeries  # mcap only when a session is read

WRITE_BLOCK_BYTES = 4096  # bytes gathered before one write when running ahead of schedule
POLL_S = 0.05  # how often a blocked device thread checks for stop
JOIN_S = 2.0  # how long close() waits for the device thread


@dataclass(frozen=True)
class Faults:
    """garbage_every / drop_every / corrupt_every: every Nth message (0 = never); garbage_bytes:
    inclusive range of garbage lengths (bytes drawn from 0..255, so 0x0A and 0xDB occur). Each
    device says what a message is and how it is damaged."""

    seed: int = 0
    garbage_every: int = 0
    garbage_bytes: tuple[int, int] = (1, 32)
    drop_every: int = 0
    corrupt_every: int = 0


class PtyDevice:
    """A device at the far end of a pseudo-terminal. Context manager: the pty exists on enter; on
    exit the device thread stops and both ends close. `error` holds what ended the thread early."""

    def __init__(self, *, speed: float = 1.0):
        if not speed >= 0.0:
            raise ValueError(f"speed {speed} must be >= 0 (0 or inf = as fast as possible)")
        self.speed = speed
        self.port = ""  # slave path, set by open()
        self.bytes_written = 0
        self.error: BaseException | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def paced(self) -> bool:
        """False when the device writes as fast as the reader takes it (speed 0 or inf)."""
        return 0.0 < self.speed < math.inf

    @overload
    def due_s(self, offset_ns: int) -> float: ...
    @overload
    def due_s(self, offset_ns: np.ndarray) -> np.ndarray: ...

    def due_s(self, offset_ns: int | np.ndarray) -> float | np.ndarray:
        """Seconds after the start at which data `offset_ns` (device clock) after the first is due."""
        return offset_ns * 1e-9 / self.speed

    def open(self) -> Self:
        """Create the pty pair (once)."""
        if self._master is None:
            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.port = os.ttyname(self._slave)
        return self

    def close(self) -> None:
        """Stop the device thread and close both ends."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=JOIN_S)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = None

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the device thread ----------------------------------------------------------------------

    def _start_thread(self) -> None:
        """Start the device thread (once; the pty must be open)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._thread_main, name=f"{type(self).__name__} {self.port}",
                                            daemon=True)
            self._thread.start()

    def _thread_main(self) -> None:
        try:
            if self._master is not None:  # not closed before the thread ran
                self._serve(self._master)
        except OSError as error:  # the pty was closed under us
            self.error = error
        except Exception as error:  # a bug: kept for the test to report (it would only print in a thread)
            self.error = error
            raise
        finally:
            self._ended()

    def _serve(self, master: int) -> None:
        raise NotImplementedError

    def _ended(self) -> None:
        """Called on the device thread when `_serve` returns or fails."""

    def _write(self, master: int, data: bytes | bytearray | memoryview) -> int:
        """Write what the pty takes now (0 when it is full); counted in `bytes_written`."""
        try:
            written = os.write(master, data)
        except BlockingIOError:
            return 0
        self.bytes_written += written
        return written

    def _write_all(self, master: int, data: bytes | bytearray) -> bool:
        """Write all of `data`, waiting for the reader; False if stopped first."""
        view = memoryview(data)
        while view:
            if self._stop.is_set() or self._master is None:
                return False
            _, writable, _ = select.select([], [master], [], POLL_S)
            if writable:
                view = view[self._write(master, view):]
        return True


def session_series(session_path: Path | str, sensor_id: str) -> ImuSeries:
    """One sensor's samples from a session log (a simulated or imported one), for a device to play.
    InputError names the sensors there are when `sensor_id` is not one of them."""
    from protocol.session_log import read_session  # mcap only when a session is read

    data = read_session(session_path)
    if sensor_id not in data.imu:
        raise InputError(f"{session_path}: no IMU {sensor_id!r} (has: {', '.join(sorted(data.imu)) or 'none'})")
    return data.imu[sensor_id]

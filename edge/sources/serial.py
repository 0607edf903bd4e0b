"""Serial-port adapter: `serial://PORT?baud=115200` -> decoded frames.

    with SerialSource.from_url("serial:///dev/rfcomm0?protocol=tsnd&rate_hz=1000", record_raw=log.write) as source:
        for frame in source.iter_frames(stop_event):
            ...

URL: `serial://` + the port (`serial:///dev/ttyUSB0`, `serial://COM3`) + optional query keys
`baud` (bits/s, default 115200; a USB x-IMU3 ignores it), `read_timeout_s` (longest wait of
one read, default 0.05 s: the stop event is checked that often), `protocol` (`ximu3`, the
default: an x-IMU3 that streams on its own; `tsnd`: an ATR-Promotions TSND121/151, which is
commanded) and, for tsnd only, `rate_hz` (default 1000; 1000 / rate_hz must be a whole number
of ms in 1..255: 1000, 500, 250, 200, 125, 100, ..., 4). Other keys or values fail with
ConfigError naming the URL.

`from_url` picks the decoder and the commands from `protocol`. A commanded device gets `setup`
bytes written right after the port opens (tsnd: stop, settings, ranges, start; every reopen
sends them again) and `teardown` bytes before it closes (tsnd: stop); `write` sends any other.

Every byte read is handed to `record_raw` before it is decoded, so what the device sent is kept
even when the decoder rejects it. Rejected frames are returned like the others (the caller may
store them) and summarised in one WARNING per `warn_every_s` at most, never one per frame.

A device that disappears (unplugged, Bluetooth link lost, pty closed) raises `DeviceDisconnected`
from `read_frames`/`iter_frames`; the exception's `frames` carries what the failing read still
decoded plus the partial message the decoder held (a TRUNCATED Rejected), all of it already given
to `record_raw`. A port that cannot
be opened raises `DeviceUnavailable`. Both are `protocol.errors.ReckonError`s (via `DeviceError`),
so the CLI prints one line; a caller that wants to reconnect catches `DeviceDisconnected`.

`SerialSources` is the edge's source for `SENSOR=serial://...` (one reader thread per device,
reconnecting), registered as the `serial` scheme (edge/sources/registry.py) with the doctor's
`check_serial`.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import Counter
from collections.abc import Iterable
from typing import Any, Callable, Iterator, NoReturn, Protocol, Sequence
from urllib.parse import parse_qs, urlsplit

import serial

from edge.decoders import tsnd, ximu3
from edge.decoders.devices import DeviceDecoder
from edge.decoders.samples import ImuBatcher
from edge.decoders.tsnd import TsndDecoder, period_for_rate, setup_commands, teardown_commands
from edge.decoders.ximu3 import InertialFrame, Ximu3Decoder
from edge.sources.registry import CheckRequest, Finding, Level, OpenRequest, Scheme, live_session
from edge.sources.threaded import ThreadedSource
from protocol.errors import ConfigError, ReckonError
from protocol.session import Session

log = logging.getLogger(__name__)

DEFAULT_BAUD = 115_200
DEFAULT_READ_TIMEOUT_S = 0.05
READ_SIZE = 4096  # bytes asked of one read; a read returns what has arrived, up to this
WRITE_TIMEOUT_S = 1.0  # a device that takes no command within this is treated as gone
URL_KEYS = ("baud", "read_timeout_s", "protocol", "rate_hz")
PROTOCOLS: dict[str, DeviceDecoder] = {"ximu3": ximu3.DEVICE, "tsnd": tsnd.DEVICE}  # a URL's `protocol`
DEFAULT_TSND_RATE_HZ = 1000.0  # the swimming paper's rate


class DeviceError(ReckonError):
    """A device source failed (base of the errors below)."""


class DeviceUnavailable(DeviceError):
    """The port cannot be opened (no such device, permission, busy)."""


class DeviceDisconnected(DeviceError):
    """The port failed while open: the device went away. `frames` holds what the last read still
    decoded plus the partial message the decoder held (TRUNCATED), so nothing is lost."""

    def __init__(self, message: str, frames: Sequence[Any] = ()):
        super().__init__(message)
        self.frames = list(frames)


class Decoder(Protocol):
    """What a source needs of a decoder (Ximu3Decoder, or any push-style decoder)."""

    def feed(self, chunk: bytes) -> list[Any]: ...

    def reset(self) -> list[Any]: ...


def parse_serial_url(url: str) -> tuple[str, int, float]:
    """`serial://PORT?baud=N&read_timeout_s=S` -> (port, baud, read_timeout_s). ConfigError on a
    wrong scheme, an empty port, an unknown key or a bad value."""
    parts = urlsplit(url)
    if parts.scheme != "serial":
        raise ConfigError(f"{url}: expected a serial:// URL")
    port = parts.netloc + parts.path
    if not port:
        raise ConfigError(f"{url}: no port (e.g. serial:///dev/ttyUSB0)")
    query = parse_qs(parts.query, keep_blank_values=True, strict_parsing=False)
    for key in query:
        if key not in URL_KEYS:
            raise ConfigError(f"{url}: unknown key {key!r} (allowed: {', '.join(URL_KEYS)})")
    baud = _number(url, query, "baud", DEFAULT_BAUD, int, 50, 20_000_000)
    timeout_s = _number(url, query, "read_timeout_s", DEFAULT_READ_TIMEOUT_S, float, 0.001, 10.0)
    parse_serial_protocol(url)
    return port, int(baud), float(timeout_s)


def parse_serial_protocol(url: str) -> tuple[str, float | None]:
    """(protocol, rate_hz) of a serial URL: ("ximu3", None) or ("tsnd", rate_hz). ConfigError for
    another protocol, rate_hz without protocol=tsnd, or a rate the TSND cannot be set to."""
    query = parse_qs(urlsplit(url).query, keep_blank_values=True)
    protocol = query.get("protocol", ["ximu3"])[-1]
    if protocol not in PROTOCOLS:
        raise ConfigError(f"{url}: protocol={protocol!r} is not one of {', '.join(PROTOCOLS)}")
    if protocol != "tsnd":
        if "rate_hz" in query:
            raise ConfigError(f"{url}: rate_hz is for protocol=tsnd (an x-IMU3's rate is set with its own software)")
        return protocol, None
    rate_hz = _number(url, query, "rate_hz", DEFAULT_TSND_RATE_HZ, float, 1.0, 1000.0)
    period_for_rate(rate_hz, f"{url}: rate_hz")
    return protocol, rate_hz


def _number(url: str, query: dict[str, list[str]], key: str, default: float, kind: type, low: float,
            high: float) -> float:
    if key not in query:
        return default
    text = query[key][-1]
    try:
        value: float = kind(text)
    except ValueError:
        raise ConfigError(f"{url}: {key}={text!r} is not a number") from None
    if not low <= value <= high:
        raise ConfigError(f"{url}: {key}={value} is outside [{low}, {high}]")
    return value


class SerialSource:
    """Reads a serial port and decodes it. Context manager; not thread-safe (one reader)."""

    def __init__(self, url: str, decoder: Decoder, *, record_raw: Callable[[bytes], None] | None = None,
                 warn_every_s: float = 5.0, clock: Callable[[], float] = time.monotonic, setup: bytes = b"",
                 teardown: bytes = b""):
        self.url = url
        self.port, self.baud, self.read_timeout_s = parse_serial_url(url)
        self.decoder = decoder
        self.record_raw = record_raw
        self.setup, self.teardown = bytes(setup), bytes(teardown)
        self.warn_every_s = warn_every_s
        self._clock = clock
        self._serial: serial.Serial | None = None
        self.bytes_read = 0
        self.frames_read = 0
        self._unreported: Counter[str] = Counter()
        self._last_warning = clock()

    @classmethod
    def from_url(cls, url: str, *, decoder: Decoder | None = None, **options: Any) -> "SerialSource":
        """A source with the decoder and setup/teardown commands of the URL's `protocol`.
        `decoder`: reuse one (after a reconnect, so its counters and clock carry on)."""
        protocol, rate_hz = parse_serial_protocol(url)
        if protocol == "tsnd" and rate_hz is not None:
            return cls(url, decoder or TsndDecoder(), setup=setup_commands(rate_hz), teardown=teardown_commands(),
                       **options)
        return cls(url, decoder or Ximu3Decoder(), **options)

    def open(self) -> "SerialSource":
        """Open the port and send `setup`; DeviceUnavailable if either fails."""
        if self._serial is None:
            try:
                self._serial = serial.serial_for_url(self.port, baudrate=self.baud, timeout=self.read_timeout_s,
                                                     write_timeout=WRITE_TIMEOUT_S)
            except (serial.SerialException, OSError, ValueError) as error:
                raise DeviceUnavailable(f"{self.url}: cannot open {self.port} ({error})") from None
            if self.setup:
                try:
                    self.write(self.setup)
                except DeviceError as error:
                    self.close()
                    raise DeviceUnavailable(f"{self.url}: opened, but the setup commands failed ({error})") from None
        return self

    def close(self) -> None:
        """Send `teardown` (best effort: a device that is gone cannot be stopped) and close."""
        if self._serial is not None:
            if self.teardown:
                try:
                    self.write(self.teardown)
                except DeviceError as error:
                    log.warning("%s: teardown commands not sent (%s)", self.url, error)
            self._serial.close()
            self._serial = None
        self._report(force=True)

    def write(self, data: bytes) -> None:
        """Send bytes to the device and wait until they have left; DeviceDisconnected if the port
        fails or the device takes nothing within WRITE_TIMEOUT_S."""
        if self._serial is None:
            raise DeviceError(f"{self.url}: write on a closed source")
        try:
            self._serial.write(data)
            self._serial.flush()
        except (serial.SerialException, OSError) as error:
            raise DeviceDisconnected(f"{self.url}: cannot write {len(data)} bytes ({error})") from None

    def __enter__(self) -> "SerialSource":
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def read_frames(self) -> list[Any]:
        """One read (waits at most read_timeout_s for the first byte) -> decoded frames, possibly
        none. Raises DeviceDisconnected when the port fails."""
        if self._serial is None:
            raise DeviceError(f"{self.url}: read on a closed source")
        chunk = b""
        try:
            # read(1) returns at the first byte (or the timeout); then take what else has arrived.
            chunk = self._serial.read(1)
            waiting = self._serial.in_waiting if chunk else 0
            if waiting:
                chunk += self._serial.read(min(waiting, READ_SIZE))
        except (serial.SerialException, OSError) as error:
            self._lost(error, self._decode(chunk))
        return self._decode(chunk)

    def iter_frames(self, stop: threading.Event) -> Iterator[Any]:
        """Frames until `stop` is set (checked after every read, so within read_timeout_s)."""
        while not stop.is_set():
            yield from self.read_frames()

    def _decode(self, chunk: bytes) -> list[Any]:
        if not chunk:
            self._report(force=False)
            return []
        self.bytes_read += len(chunk)
        if self.record_raw is not None:
            self.record_raw(chunk)  # before decoding: nothing the device sent is lost
        frames = self.decoder.feed(chunk)
        self.frames_read += len(frames)
        self._count_rejected(frames)
        self._report(force=False)
        return frames

    def _lost(self, error: BaseException, last_frames: list[Any]) -> NoReturn:
        dropped = self.decoder.reset()
        self._count_rejected(dropped)
        self._report(force=True)
        raise DeviceDisconnected(f"{self.url}: device disconnected after {self.bytes_read} bytes ({error})",
                                 last_frames + dropped) from None

    def _count_rejected(self, frames: list[Any]) -> None:
        for frame in frames:
            reason = getattr(frame, "reason", None)
            if reason is not None:
                self._unreported[getattr(reason, "value", str(reason))] += 1

    def _report(self, force: bool) -> None:
        now = self._clock()
        if not self._unreported or (not force and now - self._last_warning < self.warn_every_s):
            return
        total = sum(self._unreported.values())
        reasons = ", ".join(f"{reason} {count}" for reason, count in self._unreported.most_common())
        log.warning("%s: %d rejected frames in the last %.1f s (%s); %d bytes read in all",
                    self.url, total, now - self._last_warning, reasons, self.bytes_read)
        self._unreported.clear()
        self._last_warning = now


class SerialSources(ThreadedSource):
    """One reader thread per `SENSOR=serial://PORT?...` source, all feeding one blocking queue.

    Each URL's `protocol` picks the decoder and the commands (SerialSource.from_url: an x-IMU3
    streams on its own, a TSND is set up and started on open, stopped on close).
    Ports are opened here, at once, so a device that is missing fails before anything starts.
    A device that goes away (link lost, unplugged, a read error) keeps its last frames; its reader
    then tries to open the port again, first after `RETRY_S`, the wait doubling up to `MAX_RETRY_S`,
    and carries on when the device is back (a by-id path that points at the new port finds it),
    for up to `reconnect_s`; after that its stream ends. `link(sensor)` says whether a sensor is
    connected and how often it came back; `device_ranges` its full scales (for saturation).
    Iterating yields ImuBatch messages, each stamped with the host clock at its arrival, until
    every stream has ended or `stop` is set.
    """

    RETRY_S = 0.1
    MAX_RETRY_S = 2.0

    def __init__(self, specs: list[tuple[str, str]], agent_id: str, stop: threading.Event, reconnect_s: float = 30.0):
        super().__init__(stop)
        self.reconnect_s = reconnect_s
        self.reconnects = 0
        self.sources = [(url, SerialSource.from_url(url).open(), ImuBatcher(agent_id, sensor_id))
                        for sensor_id, url in specs]
        self.connected = {sensor_id: True for sensor_id, _ in specs}
        self.reconnects_by_sensor = {sensor_id: 0 for sensor_id, _ in specs}
        self.device_ranges = {sensor_id: PROTOCOLS[parse_serial_protocol(url)[0]].full_scale for sensor_id, url in specs}
        for url, source, batcher in self.sources:
            self.start(self._read, url, source, batcher, name=f"serial {batcher.sensor_id}")

    def _put(self, batches: list[Any]) -> None:
        now = time.time_ns()
        for batch in batches:
            batch.received_ns = now
            self.put(batch)

    def _read(self, url: str, source: Any, batcher: Any) -> None:
        decoder = source.decoder  # kept across reconnects: its counters and device clock carry on
        try:
            while not self.stop.is_set():
                try:
                    while not self.stop.is_set():
                        self._put(batcher.feed(source.read_frames()))
                except DeviceDisconnected as gone:
                    self.connected[batcher.sensor_id] = False
                    self._put(batcher.feed(gone.frames))
                    source.close()
                    log.warning("%s; trying to reopen it for %.0f s", gone, self.reconnect_s)
                    source = None
                    deadline = time.monotonic() + self.reconnect_s
                    delay = self.RETRY_S
                    while source is None and time.monotonic() < deadline and not self.stop.wait(delay):
                        delay = min(2 * delay, self.MAX_RETRY_S)
                        try:
                            source = SerialSource.from_url(url, decoder=decoder).open()
                        except DeviceUnavailable:
                            continue
                    if source is None:
                        return
                    self.reconnects += 1
                    self.reconnects_by_sensor[batcher.sensor_id] += 1
                    self.connected[batcher.sensor_id] = True
                    log.warning("%s is back (reconnect %d)", url, self.reconnects)
        finally:
            self.connected[batcher.sensor_id] = False
            self._put(batcher.flush())
            if source is not None:
                source.close()

    def link(self, sensor_id: str) -> tuple[bool, int, float]:
        """(connected, reconnects, battery_pct): neither an x-IMU3 nor a TSND stream says its battery."""
        return self.connected.get(sensor_id, False), self.reconnects_by_sensor.get(sensor_id, 0), -1.0


def open_serial(request: OpenRequest) -> tuple[Session, Iterable[Any]]:
    """One serial device per sensor of the agent (the venue file says which sensor is where)."""
    for spec in request.specs:
        parse_serial_url(spec.url)
    session, _ = live_session(request, "serial sources")
    return session, SerialSources([(spec.sensor_id, spec.url) for spec in request.specs], request.agent_id,
                                  request.stop, request.reconnect_s)


SERIAL_FRAMES = 100  # inertial frames that are plenty to tell the protocol and the rate


def check_serial(request: CheckRequest) -> list[Finding]:
    """The port exists and opens; then a listen of up to `listen_s` for frames of the URL's protocol,
    their rate by the device clock against the venue file's."""
    url, listen_s, rate_hz = request.url, request.listen_s, request.rate_hz
    port, _, _ = parse_serial_url(url)
    if port.startswith("/") and not os.path.exists(port):
        return [Finding(Level.FAIL, f"{port} does not exist",
                        "plug the device in and power it; `ls /dev/serial/by-id/` lists the serial devices present")]
    if port.startswith("/") and not os.access(port, os.R_OK | os.W_OK):
        return [Finding(Level.FAIL, f"no permission to open {port}",
                        "add the user to the dialout group (`sudo usermod -aG dialout $USER`, then log in again)")]
    source = SerialSource.from_url(url)
    try:
        source.open()
    except DeviceError as error:
        return [Finding(Level.FAIL, str(error), "is another program (an edge) using the port?")]
    frames: list[Any] = []
    deadline = time.monotonic() + listen_s
    try:
        with source:
            while time.monotonic() < deadline and sum(isinstance(f, InertialFrame) for f in frames) < SERIAL_FRAMES:
                frames += source.read_frames()
    except DeviceError as error:
        return [Finding(Level.FAIL, f"opened, then lost: {error}", "check the cable or the Bluetooth link")]
    inertial = [f for f in frames if isinstance(f, InertialFrame)]
    rejected = sum(getattr(f, "reason", None) is not None for f in frames)
    if source.bytes_read == 0:
        return [Finding(Level.WARN, f"{port} opens, but sent nothing in {listen_s:g} s",
                        "is the device on and streaming? an x-IMU3 streams on its own; a TSND needs ?protocol=tsnd")]
    if not inertial:
        return [Finding(Level.FAIL, f"{source.bytes_read} bytes in {listen_s:g} s, no valid frame ({rejected} "
                        "rejected)", "wrong protocol or baud rate in the URL (?protocol=, ?baud=)")]
    span_s = (inertial[-1].timestamp_us - inertial[0].timestamp_us) * 1e-6
    measured = (len(inertial) - 1) / span_s if len(inertial) > 1 and span_s > 0 else None
    text = (f"{len(inertial)} inertial frames decoded from {source.bytes_read} bytes ({rejected} rejected)"
            + (f", {measured:.0f} Hz by the device clock" if measured else ""))
    if measured and rate_hz and abs(measured - rate_hz) > 0.1 * rate_hz:
        return [Finding(Level.WARN, f"{text}; the venue file says rate_hz {rate_hz:g}",
                        "set the device's rate, or rate_hz in the venue file, so that they agree")]
    return [Finding(Level.OK, text)]


SCHEME = Scheme("serial", "SENSOR=serial://PORT?baud=N[&protocol=tsnd&rate_hz=N]", open_serial, check_serial)

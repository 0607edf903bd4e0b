"""BLE sources for `reckon edge`, through bleak: Thingy:52 IMUs and one beacon scanner.

    sources = BleSources([("seat", "ble://F1:22:33:44:55:66"), ("rx", "ble://scan")], "chair1",
                         {"ibeacon:e2c56db5-dffb-48d2-b060-d0f5a71096e0:1:2": "goal_a"}, stop)
    for message in sources:  # ImuBatch and BeaconSighting messages
        ...

URLs: `ble://AA:BB:CC:DD:EE:FF` is a Thingy:52 (its raw motion characteristic is subscribed to and
decoded into ImuBatch messages); `ble://scan` scans for advertisements and turns every one from a
known beacon identity (edge.decoders.ble_adverts) into a BeaconSighting of the venue beacon's id.
Anything else fails with ConfigError. Every message is stamped with the host clock (`clock_ns`,
default time.time_ns): BLE notifications carry no device time.

One asyncio loop in one background thread runs all BLE work (bleak's callbacks arrive on that
loop). Messages go into one bounded queue that blocks the loop when full rather than dropping
(edge/sources/threaded.py); iterating the object yields them until `stop` is set and every source
has flushed, and re-raises an exception from the BLE thread. A device that cannot be reached or loses its link is retried
with exponential backoff until `stop`: one WARNING naming the address per retry, counts in
`stats`. Samples received before a link loss are flushed as a (short) batch at once.
Bluetooth missing or switched off before a source ever started is an error, not retried.
Registered as the `ble` scheme (edge/sources/registry.py), with the doctor's `check_ble`.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import re
import threading
import time
from collections.abc import Iterable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Awaitable, Callable, Mapping, Sequence

from bleak import BleakClient, BleakScanner
from bleak.exc import BleakBluetoothNotAvailableError, BleakError

from edge.decoders import ble_adverts
from edge.decoders.ble_adverts import THINGY_RAW_MOTION_UUID, ThingyMotionDecoder, beacon_identities, normalize_identity
from edge.decoders.samples import BatchSettings, ImuBatcher
from edge.decoders.ximu3 import Rejected
from edge.sources.registry import CheckRequest, Finding, Level, OpenRequest, Scheme, Spec, live_session
from edge.sources.threaded import ThreadedSource
from protocol import keys, messages
from protocol.errors import ConfigError
from protocol.session import Session

log = logging.getLogger(__name__)

SCAN = "scan"
_ADDRESS = re.compile(r"[0-9A-F]{2}(?::[0-9A-F]{2}){5}")
_EXPECTED = "expected ble://AA:BB:CC:DD:EE:FF (a Thingy:52 IMU) or ble://scan (beacons)"
# What a radio raises when a device is out of range, busy or gone: worth a retry. Anything else
# is a bug and ends the stream.
RADIO_ERRORS = (BleakError, TimeoutError, OSError)
STOP_POLL_S = 0.05  # how often the BLE loop looks at the `stop` threading.Event
DISCONNECT_TIMEOUT_S = 5.0  # a hang-up that takes longer is abandoned (BlueZ drops the link itself)
_REPORT_AT = frozenset(10**k for k in range(12))  # rejected-notification counts that get a WARNING


def parse_ble_url(url: str) -> str:
    """`ble://AA:BB:CC:DD:EE:FF` -> "AA:BB:CC:DD:EE:FF" (upper case); `ble://scan` -> SCAN."""
    if not isinstance(url, str) or not url.startswith("ble://"):
        raise ConfigError(f"{url!r}: {_EXPECTED}")
    rest = url[len("ble://"):]
    if rest == SCAN:
        return SCAN
    if _ADDRESS.fullmatch(rest.upper()):
        return rest.upper()
    raise ConfigError(f"{url!r}: {rest!r} is not a Bluetooth address (six hex pairs separated by ':'); {_EXPECTED}")


@dataclass(frozen=True)
class Retry:
    """Backoff between attempts to reach a device: first_s, doubling up to max_s. It restarts
    from first_s after a connection that worked, so a brief dropout is bridged quickly."""

    first_s: float = 0.5
    max_s: float = 10.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.first_s <= self.max_s <= 3600.0:
            raise ConfigError(f"retry: need 0 <= first_s ({self.first_s}) <= max_s ({self.max_s}) <= 3600")


@dataclass
class LinkStats:
    """Counts for one source (an IMU link, or the scanner). Written by the BLE thread."""

    url: str
    connects: int = 0  # connections made (scanner: scans started)
    link_losses: int = 0
    failed_attempts: int = 0
    messages: int = 0  # ImuBatch / BeaconSighting messages queued
    ignored_adverts: int = 0  # scanner: advertisements of no known beacon

    @property
    def reconnects(self) -> int:
        return max(0, self.connects - 1)


@dataclass
class _Imu:
    sensor_id: str
    address: str
    decoder: ThingyMotionDecoder
    batcher: ImuBatcher
    stats: LinkStats


class BleSources(ThreadedSource):
    """Iterable of protocol messages from BLE devices; see the module docstring."""

    def __init__(self, specs: Sequence[tuple[str, str]], agent_id: str, beacons_by_identity: Mapping[str, str],
                 stop: threading.Event, *, client_factory: Callable[..., Any] = BleakClient,
                 scanner_factory: Callable[..., Any] = BleakScanner, clock_ns: Callable[[], int] = time.time_ns,
                 retry: Retry = Retry(), batch_settings: BatchSettings | None = None, queue_size: int = 1000):
        super().__init__(stop, queue_size)
        self.agent_id = agent_id
        self._client_factory, self._scanner_factory, self._clock_ns = client_factory, scanner_factory, clock_ns
        self.retry = retry
        self.beacons = {normalize_identity(identity, f"beacon {beacon_id!r}"): beacon_id
                        for identity, beacon_id in beacons_by_identity.items()}
        self.imus: list[_Imu] = []
        self.scanner: tuple[str, LinkStats] | None = None  # (sensor_id, stats)
        self._add_specs(specs, batch_settings)
        self.stats = {imu.sensor_id: imu.stats for imu in self.imus}
        if self.scanner:
            self.stats[self.scanner[0]] = self.scanner[1]
        self.start(lambda: asyncio.run(self._main()), name="ble-sources")

    def _add_specs(self, specs: Sequence[tuple[str, str]], batch_settings: BatchSettings | None) -> None:
        if not specs:
            raise ConfigError(f"no BLE sources given; {_EXPECTED}")
        settings = batch_settings or BatchSettings()
        seen: dict[str, str] = {}
        for sensor_id, url in specs:
            address = parse_ble_url(url)
            if address in seen:
                raise ConfigError(f"{url!r}: also given for sensor {seen[address]!r} (one source per device, one scan)")
            seen[address] = sensor_id
            stats = LinkStats(f"ble://{address}")  # normalised, so logs name the address one way
            if address == SCAN:
                self.scanner = (sensor_id, stats)
                continue
            decoder = ThingyMotionDecoder(settings.mag_ut_per_au)  # the batcher converts a.u. back with it
            self.imus.append(_Imu(sensor_id, address, decoder, ImuBatcher(self.agent_id, sensor_id, settings), stats))
        if self.scanner and not self.beacons:
            log.warning("ble://scan: no venue beacon has an identity, every advertisement will be ignored")

    # -- consumer side (the edge loop's thread) ---------------------------------------------------

    @property
    def device_ranges(self) -> dict[str, tuple[float, float] | None]:
        """Full scales per IMU, for saturation (edge/health.py)."""
        return {imu.sensor_id: ble_adverts.DEVICE.full_scale for imu in self.imus}

    def link(self, sensor_id: str) -> tuple[bool, int, float]:
        """(connected, reconnects, battery_pct); the battery service is not read yet (-1)."""
        stats = self.stats.get(sensor_id)
        if stats is None:
            return False, 0, -1.0
        return stats.connects > stats.link_losses, stats.reconnects, -1.0

    def _put_all(self, items: list[Any], stats: LinkStats) -> None:
        for item in items:
            self.put(item)  # blocks while the queue is full: this stalls the BLE loop (back-pressure, not loss)
        stats.messages += len(items)

    async def _main(self) -> None:
        self._stopping = asyncio.Event()
        self._error: Exception | None = None
        tasks = [asyncio.create_task(self._supervise(imu.stats, functools.partial(self._stream, imu)))
                 for imu in self.imus]
        if self.scanner:
            tasks.append(asyncio.create_task(self._supervise(self.scanner[1], self._scan)))
        watcher = asyncio.create_task(self._watch_stop())
        try:
            await asyncio.gather(*tasks)
        finally:
            watcher.cancel()
            await asyncio.gather(watcher, return_exceptions=True)
        if self._error is not None:
            raise self._error

    async def _watch_stop(self) -> None:
        while not self.stop.is_set():
            await asyncio.sleep(STOP_POLL_S)
        self._stopping.set()

    def _fail(self, error: Exception) -> None:
        """End every source as if stopped (each flushes and hangs up), then raise `error`."""
        if self._error is None:
            self._error = error
        self._stopping.set()

    def _guarded(self, callback: Callable[..., None]) -> Callable[..., None]:
        """bleak only logs what a callback raises; here it ends the stream and reaches the consumer."""
        def call(*args: Any) -> None:
            try:
                callback(*args)
            except Exception as error:
                self._fail(error)
        return call

    async def _supervise(self, stats: LinkStats, session: Callable[[], Awaitable[None]]) -> None:
        try:
            await self._keep_up(stats, session)
        except Exception as error:
            self._fail(error)

    async def _unless_stopped(self, awaitable: Awaitable[Any]) -> bool:
        """Await `awaitable`, cancelling it if stop comes first. True if it completed."""
        work = asyncio.ensure_future(awaitable)
        stopping = asyncio.ensure_future(self._stopping.wait())
        try:
            await asyncio.wait((work, stopping), return_when=asyncio.FIRST_COMPLETED)
        finally:
            stopping.cancel()
            if not work.done():
                work.cancel()
                await asyncio.gather(work, return_exceptions=True)  # let bleak clean up
        if work.cancelled():
            return False
        work.result()  # raises what the work raised
        return True

    async def _keep_up(self, stats: LinkStats, session: Callable[[], Awaitable[None]]) -> None:
        """Run `session` again after each link loss or failure, with backoff, until stop."""
        delay = self.retry.first_s
        while not self._stopping.is_set():
            connects = stats.connects
            try:
                await session()
                why = "link lost"
            except RADIO_ERRORS as error:
                if isinstance(error, BleakBluetoothNotAvailableError) and not stats.connects:
                    raise  # no adapter, or it is off: a setup problem, not a dropout
                why = type(error).__name__ + (f": {error}" if str(error) else "")
            if self._stopping.is_set():
                return
            if stats.connects > connects:
                stats.link_losses += 1
                delay = self.retry.first_s
            else:
                stats.failed_attempts += 1
            log.warning("%s: %s; retrying in %.1f s (%d reconnects, %d failed attempts so far)",
                        stats.url, why, delay, stats.reconnects, stats.failed_attempts)
            with suppress(TimeoutError):
                await asyncio.wait_for(self._stopping.wait(), delay)
            delay = min(max(2 * delay, 0.1), self.retry.max_s)

    async def _stream(self, imu: _Imu) -> None:
        """One connection to a Thingy: returns when its link is lost or stop is set."""
        lost = asyncio.Event()
        # bleak calls this on a link loss, and also after our own disconnect().
        client = self._client_factory(imu.address, disconnected_callback=lambda _client: lost.set())
        if not await self._unless_stopped(client.connect()):
            return
        imu.stats.connects += 1
        if imu.stats.connects > 1:
            log.info("%s: reconnected (%d reconnects)", imu.stats.url, imu.stats.reconnects)
        try:
            await client.start_notify(THINGY_RAW_MOTION_UUID, self._guarded(functools.partial(self._on_motion, imu)))
            await self._unless_stopped(lost.wait())
        finally:
            self._put_all(imu.batcher.flush(), imu.stats)  # what arrived before a loss goes out now
            if not lost.is_set():  # stop (or start_notify failed): BlueZ keeps a link we do not close
                with suppress(*RADIO_ERRORS):
                    await asyncio.wait_for(client.disconnect(), DISCONNECT_TIMEOUT_S)

    def _on_motion(self, imu: _Imu, _sender: Any, data: bytearray) -> None:
        frames = imu.decoder.feed(data, self._clock_ns())
        rejected = imu.decoder.rejected_frames
        if frames and isinstance(frames[0], Rejected) and rejected in _REPORT_AT:
            log.warning("%s: %d rejected notifications so far (latest: %s)", imu.stats.url, rejected, frames[0].detail)
        self._put_all(imu.batcher.feed(frames), imu.stats)

    async def _scan(self) -> None:
        """One scanning run: returns when stop is set."""
        assert self.scanner is not None
        sensor_id, stats = self.scanner
        scanner = self._scanner_factory(detection_callback=self._guarded(
            functools.partial(self._on_advert, sensor_id, stats)))
        if not await self._unless_stopped(scanner.start()):
            return
        stats.connects += 1
        try:
            await self._stopping.wait()
        finally:
            with suppress(*RADIO_ERRORS):
                await asyncio.wait_for(scanner.stop(), DISCONNECT_TIMEOUT_S)

    def _on_advert(self, sensor_id: str, stats: LinkStats, _device: Any, advert: Any) -> None:
        now_ns = self._clock_ns()
        sightings = [messages.new("BeaconSighting", timestamp_ns=now_ns, agent_id=self.agent_id, sensor_id=sensor_id,
                                  beacon_id=self.beacons[identity], rssi_dbm=float(advert.rssi))
                     for identity in beacon_identities(advert.manufacturer_data, advert.service_data)
                     if identity in self.beacons]
        if not sightings:
            stats.ignored_adverts += 1
        self._put_all(sightings, stats)


def open_ble(request: OpenRequest) -> tuple[Session, Iterable[Any]]:
    """Thingy:52 IMUs, one per sensor, and at most one `RECEIVER=ble://scan` for the venue's beacons
    that have an `identity`. Everything is checked before any radio work starts."""
    imus: list[Spec] = []
    scans: list[Spec] = []
    for spec in request.specs:
        try:
            address = parse_ble_url(spec.url)
        except ConfigError as error:
            raise ConfigError(f"--source {spec.given!r}: {error}") from None
        if address != SCAN:
            imus.append(spec)
            continue
        keys.check_id(spec.sensor_id, f"--source {spec.given!r}: the receiver id")
        if scans:
            raise ConfigError(f"--source {spec.given!r}: one ble://scan per edge (already given as {scans[0].given!r})")
        scans.append(spec)
    session, _ = live_session(request, "BLE sources", sensors=imus)
    beacons_by_identity = {b.identity: b.id for b in session.venue.beacons if b.identity}
    if scans and not beacons_by_identity:
        raise ConfigError(f"--source {scans[0].given!r}: no beacon in {request.venue_toml} has an identity to listen "
                          "for (set identity = \"ibeacon:<uuid>:<major>:<minor>\" or \"eddystone:<namespace>:"
                          "<instance>\" in the beacon's [[venue.beacons]] table)")
    return session, BleSources([(spec.sensor_id, spec.url) for spec in imus + scans], request.agent_id,
                               beacons_by_identity, request.stop, **request.factories)


def check_ble(request: CheckRequest) -> list[Finding]:
    """bleak is importable (this module is), an adapter is listed, and a scan has identities to
    listen for. The device itself is not contacted."""
    address = parse_ble_url(request.url)
    sysfs: Path = request.bluetooth_sysfs
    adapters = sorted(p.name for p in sysfs.glob("hci*")) if sysfs.is_dir() else []
    if not adapters:
        return [Finding(Level.WARN, f"no Bluetooth adapter listed in {sysfs}",
                        "plug in a Bluetooth dongle or enable Bluetooth (`bluetoothctl list`); not checked off Linux")]
    session = request.session
    if address == SCAN and session is not None and not any(b.identity for b in session.venue.beacons):
        return [Finding(Level.FAIL, "no beacon in the venue file has an identity to listen for",
                        "set identity in each [[venue.beacons]] table")]
    return [Finding(Level.OK, f"bleak importable, adapter {', '.join(adapters)} (device not contacted)")]


SCHEME = Scheme("ble", "SENSOR=ble://AA:BB:CC:DD:EE:FF or RECEIVER=ble://scan", open_ble, check_ble,
                sensor=lambda url: url != f"ble://{SCAN}")

"""A fake Bluetooth radio where bleak 3.1 stands, and the bytes BLE beacons and a Thingy:52 send
(tests/edge/test_ble_source.py, where test_fakes_match_bleak checks the fakes against bleak;
tests/reckon/test_edge_app.py).

The fakes record what the code under test does and let a test push notifications, advertisements
and link losses into the BLE loop, waiting until each has been handled (no sleeps).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import queue
import struct
import uuid
from types import SimpleNamespace
from typing import Any

from bleak.backends.device import BLEDevice
from bleak.backends.scanner import AdvertisementData
from bleak.exc import BleakError

from edge.decoders.ble_adverts import THINGY_RAW_MOTION_UUID

WAIT_S = 5.0
BEACON_UUID = "e2c56db5-dffb-48d2-b060-d0f5a71096e0"
NAMESPACE = bytes(range(10))
INSTANCE = bytes.fromhex("a1b2c3d4e5f6")


def ibeacon_bytes(major: int, minor: int, tx_power: int = -59, beacon_uuid: str = BEACON_UUID) -> bytes:
    return b"\x02\x15" + uuid.UUID(beacon_uuid).bytes + struct.pack(">HHb", major, minor, tx_power)


def eddystone_bytes(frame: int = 0x00, tx_power: int = -18, reserved: bytes = b"\x00\x00") -> bytes:
    return bytes([frame]) + struct.pack("b", tx_power) + NAMESPACE + INSTANCE + reserved


def motion_bytes(accel: tuple[int, int, int], gyro: tuple[int, int, int], compass: tuple[int, int, int]) -> bytes:
    return struct.pack("<9h", *accel, *gyro, *compass)



class FakeRadio:
    """The Bluetooth adapter as the code under test sees it through bleak. `ready` receives every
    client once it has subscribed and every scanner once it has started."""

    def __init__(self) -> None:
        self.ready: queue.Queue[Any] = queue.Queue()
        self.made: list[Any] = []
        self.connect_errors: list[Exception] = []  # raised by the next connect() calls, in order
        self.start_errors: list[Exception] = []  # raised by the next scanner start() calls
        radio = self

        class Client(FakeBleakClient):
            def __init__(self, *args: Any, **kwargs: Any) -> None:
                super().__init__(*args, **kwargs)
                self.radio = radio
                radio.made.append(self)

        class Scanner(FakeBleakScanner):
            def __init__(self, *args: Any, **kwargs: Any) -> None:
                super().__init__(*args, **kwargs)
                self.radio = radio
                radio.made.append(self)

        self.Client, self.Scanner = Client, Scanner

    def next_ready(self) -> Any:
        return self.ready.get(timeout=WAIT_S)


class _InLoop:
    """Runs a call on the BLE loop (where bleak runs its callbacks) and waits until it is done."""

    loop: asyncio.AbstractEventLoop

    def _in_loop(self, call: Any, *args: Any) -> None:
        done: concurrent.futures.Future[None] = concurrent.futures.Future()

        def run() -> None:
            try:
                done.set_result(call(*args))
            except BaseException as error:
                done.set_exception(error)

        self.loop.call_soon_threadsafe(run)
        done.result(timeout=WAIT_S)


class FakeBleakClient(_InLoop):
    """bleak.BleakClient's constructor and the coroutines the source uses; see test_ble_source.test_fakes_match_bleak."""

    radio: FakeRadio

    def __init__(self, address_or_ble_device, disconnected_callback=None, services=None, *, timeout=30,
                 pair=False, bluez={}, winrt={}, backend=None, **kwargs):
        self.address = address_or_ble_device
        self.disconnected_callback = disconnected_callback
        self.connected = False
        self.notify_callbacks: dict[str, Any] = {}
        self.disconnect_calls = 0

    @property
    def is_connected(self) -> bool:
        return self.connected

    async def connect(self, **kwargs):
        self.loop = asyncio.get_running_loop()
        if self.radio.connect_errors:
            raise self.radio.connect_errors.pop(0)
        self.connected = True

    async def start_notify(self, char_specifier, callback, *, bluez={}, cb={}, **kwargs):
        if not self.connected:
            raise BleakError("Not connected")
        self.notify_callbacks[str(char_specifier).lower()] = callback
        self.radio.ready.put(self)

    async def disconnect(self):
        self.disconnect_calls += 1
        if not self.connected:
            raise BleakError("Not connected")
        self._link_down()

    # -- what the device and the air do (called from the test thread) --

    def notify(self, data: bytes) -> None:
        characteristic = SimpleNamespace(uuid=THINGY_RAW_MOTION_UUID)  # stands in for BleakGATTCharacteristic
        self._in_loop(self.notify_callbacks[THINGY_RAW_MOTION_UUID], characteristic, bytearray(data))

    def drop_link(self) -> None:
        self._in_loop(self._link_down)

    def _link_down(self) -> None:
        self.connected = False
        if self.disconnected_callback is not None:
            self.disconnected_callback(self)  # bleak passes the client


class FakeBleakScanner(_InLoop):
    """bleak.BleakScanner's constructor, start() and stop()."""

    radio: FakeRadio

    def __init__(self, detection_callback=None, service_uuids=None, scanning_mode="active", *, bluez={}, cb={},
                 backend=None, **kwargs):
        self.detection_callback = detection_callback
        self.scanning = False
        self.stop_calls = 0

    async def start(self):
        self.loop = asyncio.get_running_loop()
        if self.radio.start_errors:
            raise self.radio.start_errors.pop(0)
        self.scanning = True
        self.radio.ready.put(self)

    async def stop(self):
        self.stop_calls += 1
        self.scanning = False

    def advertise(self, address: str, rssi: int, manufacturer_data: dict | None = None,
                  service_data: dict | None = None) -> None:
        device = BLEDevice(address, None, None)
        advert = AdvertisementData(local_name=None, manufacturer_data=manufacturer_data or {},
                                   service_data=service_data or {}, service_uuids=list(service_data or {}),
                                   tx_power=None, rssi=rssi, platform_data=())
        self._in_loop(self.detection_callback, device, advert)

"""BLE payloads -> typed values. Pure: no radio, no clock, no logging.

Beacon advertisements (field-notes.md, "BLE"):
- iBeacon: manufacturer data under company id 0x004C (Apple) =
  `02 15 | UUID (16) | major (BE u16) | minor (BE u16) | tx power at 1 m (i8)`, 23 bytes.
- Eddystone-UID: service data under `0000feaa-0000-1000-8000-00805f9b34fb` =
  `00 | tx power at 0 m (i8) | namespace (10) | instance (6) | 00 00`. The two reserved bytes are
  optional here: some beacons leave them out and they carry nothing.

A beacon's identity string, the key a venue's beacon is matched by:
`ibeacon:<uuid, lower case 8-4-4-4-12>:<major>:<minor>` and
`eddystone:<namespace, 20 lower-case hex digits>:<instance, 12 lower-case hex digits>`.
Parsers return None for anything malformed and never raise: advertisements are untrusted radio.

Nordic Thingy:52 raw motion characteristic (`EF680406-...`): one notification = 18 bytes =
9 x int16 little-endian: accel xyz Q6.10 g, gyro xyz Q11.5 deg/s, compass xyz Q12.4 uT (the
firmware's m_motion.c shifts its 16Q16 values right by 6, 11 and 12 bits). Notifications carry no
device time, so `ThingyMotionDecoder` stamps each with the host receive time it is given.
"""

from __future__ import annotations

import struct
import uuid
from dataclasses import dataclass
from typing import Any, Mapping

from edge.decoders.devices import DeviceDecoder
from edge.decoders.ximu3 import MAG_UT_PER_AU, Frame, InertialFrame, MagnetometerFrame, Rejected, RejectReason
from protocol.errors import ConfigError
from protocol.session import beacon_identity

APPLE_COMPANY_ID = 0x004C
IBEACON_PREFIX = b"\x02\x15"  # iBeacon type, then the length of what follows (21 bytes)
IBEACON = struct.Struct(">2s16sHHb")  # 23 bytes
EDDYSTONE_SERVICE_UUID = "0000feaa-0000-1000-8000-00805f9b34fb"
EDDYSTONE_UID_FRAME = 0x00
EDDYSTONE_UID_LENGTHS = (18, 20)  # without / with the two reserved bytes
THINGY_RAW_MOTION_UUID = "ef680406-9b35-4933-9b10-52ffa9740042"
THINGY_RAW_MOTION = struct.Struct("<9h")  # 18 bytes
ACCEL_G_PER_LSB = 1.0 / (1 << 10)  # Q6.10
GYRO_DPS_PER_LSB = 1.0 / (1 << 5)  # Q11.5
COMPASS_UT_PER_LSB = 1.0 / (1 << 4)  # Q12.4
# Notifications that reach the host within the same microsecond, or a host clock stepped back a
# little, would look like repeated samples to ImuBatcher (which then closes a batch early). Up to
# this far back, a time is moved to 1 us after the previous one instead; a larger step is kept.
MAX_NUDGE_US = 1_000_000

@dataclass(frozen=True, slots=True)
class IBeacon:
    uuid: str  # lower case, 8-4-4-4-12
    major: int
    minor: int
    tx_power_dbm: int  # calibrated RSSI at 1 m

    @property
    def identity(self) -> str:
        return f"ibeacon:{self.uuid}:{self.major}:{self.minor}"


@dataclass(frozen=True, slots=True)
class EddystoneUid:
    namespace: bytes  # 10 bytes
    instance: bytes  # 6 bytes
    tx_power_dbm: int  # calibrated RSSI at 0 m (about 41 dB above the 1 m figure)

    @property
    def identity(self) -> str:
        return f"eddystone:{self.namespace.hex()}:{self.instance.hex()}"


def _as_bytes(value: Any) -> bytes | None:
    return bytes(value) if isinstance(value, (bytes, bytearray, memoryview)) else None


def parse_ibeacon(manufacturer_data: Mapping[int, bytes]) -> IBeacon | None:
    """The iBeacon in an advertisement's manufacturer data, or None."""
    try:
        data = _as_bytes(manufacturer_data.get(APPLE_COMPANY_ID))
    except (AttributeError, TypeError):
        return None
    # Apple sends other records under 0x004C too (Nearby, Find My): only 02 15 is an iBeacon.
    if data is None or len(data) != IBEACON.size or not data.startswith(IBEACON_PREFIX):
        return None
    _, uuid_bytes, major, minor, tx_power = IBEACON.unpack(data)
    return IBeacon(str(uuid.UUID(bytes=uuid_bytes)), major, minor, tx_power)


def parse_eddystone_uid(service_data: Mapping[str, bytes]) -> EddystoneUid | None:
    """The Eddystone-UID frame in an advertisement's service data, or None."""
    try:
        # bleak gives 128-bit keys; their case differs between backends.
        data = next((_as_bytes(v) for k, v in service_data.items()
                     if isinstance(k, str) and k.lower() == EDDYSTONE_SERVICE_UUID), None)
    except (AttributeError, TypeError):
        return None
    if data is None or len(data) not in EDDYSTONE_UID_LENGTHS or data[0] != EDDYSTONE_UID_FRAME:
        return None
    tx_power = int.from_bytes(data[1:2], "little", signed=True)
    return EddystoneUid(data[2:12], data[12:18], tx_power)


def beacon_identities(manufacturer_data: Mapping[int, bytes], service_data: Mapping[str, bytes]) -> list[str]:
    """Identities of every beacon frame in one advertisement (none, one, or both kinds)."""
    found = (parse_ibeacon(manufacturer_data), parse_eddystone_uid(service_data))
    return [beacon.identity for beacon in found if beacon is not None]


def normalize_identity(text: str, where: str = "beacon identity") -> str:
    """A venue file's identity string in the canonical form above (the venue file's own rule)."""
    return beacon_identity(text, where)


class ThingyMotionDecoder:
    """Thingy:52 raw motion notifications -> frames for ImuBatcher, push style.

    `feed(data, receive_ns)` returns a MagnetometerFrame then an InertialFrame with the same time
    (the magnetometer first, so ImuBatcher pairs the sample with this reading), or one Rejected
    (BAD_LENGTH) for a notification that is not 18 bytes. Never raises on notification content.

    ImuBatcher takes magnetometer frames in x-IMU3 a.u. and converts them with its
    `BatchSettings.mag_ut_per_au`; `mag_ut_per_au` here must be the same figure (both default to
    MAG_UT_PER_AU), so the batch carries gauss = uT / 100.
    """

    def __init__(self, mag_ut_per_au: float = MAG_UT_PER_AU):
        if not 0.0 < mag_ut_per_au < 1e4:
            raise ConfigError(f"mag_ut_per_au: {mag_ut_per_au} is outside (0, 10000)")
        self._au_per_lsb = COMPASS_UT_PER_LSB / mag_ut_per_au
        self._offset = 0  # bytes fed so far: a Rejected's stream position
        self._last_us: int | None = None
        self.notifications = 0
        self.nudged = 0  # times moved forward to keep samples strictly increasing
        self.rejected_frames = 0
        self.rejected_by_reason: dict[str, int] = {}

    def feed(self, data: bytes | bytearray, receive_ns: int) -> list[Frame]:
        raw = bytes(data)
        offset, self._offset = self._offset, self._offset + len(raw)
        self.notifications += 1
        if len(raw) != THINGY_RAW_MOTION.size:
            reason = RejectReason.BAD_LENGTH
            self.rejected_frames += 1
            self.rejected_by_reason[reason.value] = self.rejected_by_reason.get(reason.value, 0) + 1
            return [Rejected(raw, reason, offset, f"raw motion notification is {len(raw)} bytes, "
                                                  f"expected {THINGY_RAW_MOTION.size}")]
        v = THINGY_RAW_MOTION.unpack(raw)
        time_us = self._stamp(receive_ns // 1000)
        a, g, m = ACCEL_G_PER_LSB, GYRO_DPS_PER_LSB, self._au_per_lsb
        return [MagnetometerFrame(time_us, (v[6] * m, v[7] * m, v[8] * m), raw),
                InertialFrame(time_us, (v[3] * g, v[4] * g, v[5] * g), (v[0] * a, v[1] * a, v[2] * a), raw)]

    def reset(self) -> list[Frame]:
        """Nothing is ever partial in a notification stream; kept for the Decoder protocol."""
        return []

    def _stamp(self, time_us: int) -> int:
        last = self._last_us
        if last is not None and 0 <= last - time_us < MAX_NUDGE_US:
            time_us = last + 1
            self.nudged += 1
        self._last_us = time_us
        return time_us


# A Thingy:52's raw motion: the limits of its int16 Q6.10 / Q11.5 wire format (the MPU-9250's range
# set by the firmware is not reported, so only the wire's clipping is certain). Notifications are
# datagrams, not a byte stream: `reckon fuzz --decoder ble` fuzzes them with the advertisement parsers.
DEVICE = DeviceDecoder("thingy52", full_scale=(32768 * ACCEL_G_PER_LSB, 32768 * GYRO_DPS_PER_LSB))

"""Device byte streams -> typed frames -> ImuBatch messages. Pure: no ports, no clock, no logging.

`ximu3` decodes x-io x-IMU3 data messages (ASCII and binary) push-style, `tsnd` the ATR TSND121/151's,
`ble_adverts` BLE advertisements and IMU notifications, `phone/` what a phone sends; `samples` groups one
device's frames into fixed-size `ImuBatch` messages. The I/O adapters that read ports live in
`edge.sources`.
"""

from edge.decoders.samples import BatchSettings, ImuBatcher
from edge.decoders.ximu3 import (
    DecoderCounters,
    Frame,
    InertialFrame,
    MagnetometerFrame,
    RejectReason,
    Rejected,
    Ximu3Decoder,
    mag_au_to_gauss,
)

__all__ = [
    "BatchSettings",
    "DecoderCounters",
    "Frame",
    "ImuBatcher",
    "InertialFrame",
    "MagnetometerFrame",
    "RejectReason",
    "Rejected",
    "Ximu3Decoder",
    "mag_au_to_gauss",
]

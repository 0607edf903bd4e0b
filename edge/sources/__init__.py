"""I/O adapters that read devices and hand bytes to the pure decoders of `edge.decoders`.

Sources are context managers opened from URLs (`serial:///dev/ttyUSB0?baud=115200`); every byte
read goes to an optional `record_raw` callback before it is decoded.
"""

from edge.sources.serial import (
    DeviceDisconnected,
    DeviceError,
    DeviceUnavailable,
    SerialSource,
    parse_serial_url,
)

__all__ = ["DeviceDisconnected", "DeviceError", "DeviceUnavailable", "SerialSource", "parse_serial_url"]

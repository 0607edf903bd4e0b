"""I/O adapters that read devices and hand bytes to the pure decoders of `edge.decoders`.

One module per URL scheme (`serial`, `ble`, `phone/`, `mcap`), each declaring its `SCHEME`;
`registry` finds a source by the scheme of its URL (`serial:///dev/ttyUSB0?baud=115200`) and opens
it, so adding a device is a decoder plus a source (docs/adding-a-device.md). Every byte read goes to
an optional `record_raw` callback before it is decoded.
"""

from typing import Any

__all__ = ["DeviceDisconnected", "DeviceError", "DeviceUnavailable", "SerialSource", "parse_serial_url"]


def __getattr__(name: str) -> Any:
    """The serial source's names, imported on first use: the hub's court view and the doctor use
    this package's other modules, and a hub has no pyserial (pyproject.toml's [edge] extra)."""
    if name in __all__:
        from edge.sources import serial

        return getattr(serial, name)
    raise AttributeError(f"module 'edge.sources' has no attribute {name!r}")

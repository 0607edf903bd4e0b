"""What each device decoder declares about its device, for the rest of the system.

    from edge.decoders.ximu3 import DEVICE
    DEVICE.full_scale      # (16.0, 2000.0): accel g, gyro deg/s, for saturation (edge/health.py)

Each decoder module holds one `DEVICE = DeviceDecoder(...)`; `DECODER_MODULES` lists them, so
that `reckon fuzz` finds every stream decoder without a table of its own. Pure: no I/O.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable

DECODER_MODULES = ("edge.decoders.tsnd", "edge.decoders.ximu3", "edge.decoders.ble_adverts")


@dataclass(frozen=True)
class DeviceDecoder:
    """`name`: the device's name (a serial URL's `protocol`, `reckon fuzz --decoder`).
    `full_scale`: (accel g, gyro deg/s) the device clips at, None if unknown (saturation is then
    not checked). `new_decoder`: a fresh push-style byte-stream decoder (`feed(bytes)`, `reset()`),
    None for a device whose data are not a byte stream. For `reckon fuzz`: `sync_bytes` start a
    frame (sprinkled into garbage to start false frames) and `fuzz_frames` names the simulated
    device's encoder hook, "module:function" with `(rng, start_ms, count) -> [frame bytes]`:
    intact frames with random in-range values, 1 ms apart (a name, not an import: the encoder in
    sim_devices imports this decoder)."""

    name: str
    full_scale: tuple[float, float] | None
    new_decoder: Callable[[], Any] | None = None
    sync_bytes: bytes = b""
    fuzz_frames: str = ""


def device_decoders() -> dict[str, DeviceDecoder]:
    """Every declared decoder by name, in DECODER_MODULES order."""
    found = [importlib.import_module(name).DEVICE for name in DECODER_MODULES]
    return {device.name: device for device in found}

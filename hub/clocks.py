"""Each device's clock offset against the venue clock, from when its batches arrive.

A batch's last sample cannot arrive before it was taken, so (arrival - sample time) is the clock
offset plus a latency that is never negative: its running minimum tracks the offset plus the
link's smallest latency (a few ms over BLE), the lower-envelope estimate NTP also uses. The
minimum is taken over a sliding window (two half-windows) so clock drift (20-50 ppm, about
1-3 ms a minute) and a re-synchronised device are followed. Fixed memory per device, and at most
`max_devices` devices (the first seen forgotten first): a stream of made-up sensor ids cannot grow it.
"""

from __future__ import annotations

from dataclasses import dataclass

WINDOW_S = 60.0
MAX_DEVICES = 65536  # a venue has hundreds; each envelope ~200 bytes


@dataclass
class _Envelope:
    bucket_start_ns: int
    current_ns: int  # minimum over the current half-window
    previous_ns: int  # minimum over the half-window before


class ClockOffsets:
    """`observe(sensor, sample_ns, received_ns)`; `offset_ns(sensor)`; `to_venue(sensor, t)`."""

    def __init__(self, window_s: float = WINDOW_S, max_devices: int = MAX_DEVICES):
        if max_devices < 1:
            raise ValueError(f"clock offsets max_devices {max_devices} must be at least 1")
        self.half_ns = int(window_s * 0.5e9)
        self.max_devices = max_devices
        self.envelopes: dict[str, _Envelope] = {}
        self.forgotten = 0  # devices dropped to stay within max_devices

    def observe(self, sensor_id: str, sample_ns: int, received_ns: int) -> None:
        if received_ns <= 0:  # the receiver did not stamp it
            return
        delta = received_ns - sample_ns
        envelope = self.envelopes.get(sensor_id)
        if envelope is None:
            if len(self.envelopes) >= self.max_devices:
                del self.envelopes[next(iter(self.envelopes))]  # the device seen first: dicts keep insertion order
                self.forgotten += 1
            self.envelopes[sensor_id] = _Envelope(received_ns, delta, delta)
            return
        if received_ns - envelope.bucket_start_ns >= self.half_ns:
            envelope.bucket_start_ns, envelope.previous_ns, envelope.current_ns = received_ns, envelope.current_ns, delta
        else:
            envelope.current_ns = min(envelope.current_ns, delta)

    def offset_ns(self, sensor_id: str) -> int:
        """Venue time minus device time (0 for a device never seen with arrival stamps)."""
        envelope = self.envelopes.get(sensor_id)
        return 0 if envelope is None else min(envelope.current_ns, envelope.previous_ns)

    def to_venue(self, sensor_id: str, device_ns: int) -> int:
        return device_ns + self.offset_ns(sensor_id)

"""A chair's three IMUs -> `ChairSample`s for the estimator: push-style, bounded memory.

Each sensor's samples arrive in its own time order (as `ImuBatch` messages or arrays), with any
interleaving between sensors. Each wheel's forward spin is integrated (trapezoid) into a running
rotation; every seat sample becomes a `ChairSample` that carries how far each wheel turned since
the previous seat sample, interpolated at the seat sample's time. So a lost wheel or seat packet
loses no distance: the next increment spans it. The three devices keep three clocks: each wheel is
read at the seat's time plus its clock's offset from the seat's, learned from the chair's yaw that
both see (`edge/chair/wheel_clock.py`; offsets of tens of ms bridge a pivot's turn wrongly).

Each wheel also integrates the chair's yaw as its axle IMU sees it. The wheel's gyro reads the
chair's yaw projected on the wheel plane, rotating with the wheel; its size is |yaw| cos(camber)
and its sign that of its dot product with the in-plane specific force (gravity's reaction points
up; the product is rotation- and mounting-invariant). Unlike the wheels' differential rotation it
is untouched by scrub and skid. Where the seat went silent for more than `BRIDGE_AFTER_NS`, the
merger emits bridge samples every `BRIDGE_STEP_NS` between its samples where a wheel was heard,
with the wheels' increments and no seat reading (`yaw_rate_dps` NaN), so the estimator follows the
path through a lost burst of seat packets instead of taking it as one straight step (a device
silent altogether still gets one step across its silence).

A seat sample waits until both wheels have reported past its time, but never more than
`max_wait_s` behind the newest seat sample: then a silent wheel is extrapolated at its last rate
(counted in `extrapolated`), and its rotation catches up when it reports again. The default
wait (2 s) outlasts the simulator's bursts of lost packets (0.3 s on average, docs/simulator.md),
so catch-ups are rare; the price is latency only while a wheel is silent. Samples not after their sensor's previous one are dropped and
counted (`out_of_order`). Pending seat samples and each wheel's recent history are bounded: a
seat stream more than `HISTORY` wheel samples (5 s) behind the wheels gets the oldest rotation
kept, counted in `wheel_overrun` (live streams share one clock and never drift that far apart).

This is the readable reference: the edge runs its compiled twin (edge/chair/merge_kernel.py, on the
packed state of edge/chair/merge_layout.py), which tests/edge/test_chair_merge_kernel.py holds to the
same bits. Change the merger here first, then there.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from edge.chair.state import ChairSample
from edge.chair.wheel_clock import WheelClock
from protocol.session import Agent, Mount

_INDEX = {"x": 0, "y": 1, "z": 2}
HISTORY = 1024  # wheel points kept: 5 s at 200 Hz, more than max_wait_s needs
BRIDGE_AFTER_NS = 50_000_000  # a seat silent this long (10 samples at 200 Hz) is bridged by the wheels
BRIDGE_STEP_NS = 10_000_000  # at this spacing: a 500 deg/s pivot turns 5 deg per step
WHEEL_SILENT_NS = 20_000_000  # a wheel's own samples further apart than this: its yaw there is a straight line
SEAT_STEP_MAX_NS = 7_500_000  # consecutive seat samples (200 Hz) for the clocks' yaw rates
NAN3 = (math.nan, math.nan, math.nan)


def sensor_axis(axis: str) -> tuple[int, float]:
    return _INDEX[axis[1]], (-1.0 if axis[0] == "-" else 1.0)


def up_axis(forward: str, left: str) -> tuple[int, float]:
    """The sensor axis (index, sign) along forward x left, for axis-aligned mountings."""
    f, l = [0.0] * 3, [0.0] * 3
    fi, fs = sensor_axis(forward)
    li, ls = sensor_axis(left)
    f[fi], l[li] = fs, ls
    up = (f[1] * l[2] - f[2] * l[1], f[2] * l[0] - f[0] * l[2], f[0] * l[1] - f[1] * l[0])
    index = max(range(3), key=lambda i: abs(up[i]))
    return index, up[index]


class WheelIntegrator:
    """Running rotation (deg) of one wheel and the chair's yaw (deg) it saw, with a bounded history to interpolate in."""

    def __init__(self) -> None:
        self.times: deque[int] = deque(maxlen=HISTORY)
        self.rotations: deque[float] = deque(maxlen=HISTORY)
        self.yaws: deque[float] = deque(maxlen=HISTORY)
        self.rate_dps = 0.0
        self.yaw_rate_dps = 0.0
        self.out_of_order = 0
        self.overrun = 0  # lookups older than the history: the seat fell > HISTORY samples behind

    @property
    def newest_ns(self) -> int | None:
        return self.times[-1] if self.times else None

    def push(self, time_ns: int, spin_dps: float, yaw_dps: float) -> None:
        if self.times and time_ns <= self.times[-1]:
            self.out_of_order += 1
            return
        rotation = yaw = 0.0
        if self.times:
            dt = (time_ns - self.times[-1]) * 1e-9
            rotation = self.rotations[-1] + 0.5 * (self.rate_dps + spin_dps) * dt
            yaw = self.yaws[-1] + 0.5 * (self.yaw_rate_dps + yaw_dps) * dt
        self.times.append(time_ns)
        self.rotations.append(rotation)
        self.yaws.append(yaw)
        self.rate_dps, self.yaw_rate_dps = spin_dps, yaw_dps

    def at(self, time_ns: int) -> tuple[float, float, bool]:
        """(rotation, yaw, seen) at `time_ns`: interpolated inside the history, extrapolated past its
        ends; `seen` is False where the wheel itself was silent for more than `WHEEL_SILENT_NS`."""
        if not self.times:
            return 0.0, 0.0, False
        if time_ns >= self.times[-1]:
            ahead = time_ns - self.times[-1]
            return (self.rotations[-1] + self.rate_dps * ahead * 1e-9, self.yaws[-1] + self.yaw_rate_dps * ahead * 1e-9,
                    ahead <= WHEEL_SILENT_NS)
        i = bisect.bisect_right(self.times, time_ns)
        if i == 0:  # before the wheel's first sample, or (history full) before what is kept
            self.overrun += len(self.times) == self.times.maxlen
            return self.rotations[0], self.yaws[0], False
        t0, t1 = self.times[i - 1], self.times[i]
        w = (time_ns - t0) / (t1 - t0)
        return (self.rotations[i - 1] + (self.rotations[i] - self.rotations[i - 1]) * w,
                self.yaws[i - 1] + (self.yaws[i] - self.yaws[i - 1]) * w, t1 - t0 <= WHEEL_SILENT_NS)


def plane_yaw_dps(gyro: tuple, accel: tuple, plane: tuple[int, int]) -> float:
    """The chair's yaw rate as a wheel IMU sees it, times cos(camber): the in-plane gyro's size, signed by
    its dot product with the in-plane specific force (positive for a left turn, whatever the mounting).
    The size, not the projection on that force: in a pivot the hub's centripetal acceleration tilts the
    force by tens of degrees (measured: the projection reads 2/3 of the turn). The in-plane biases and
    the spin leaking in through a misaligned mounting add to the size; a fit of them on the spin was
    tried and made turns worse (the yaw part does not average out over the wheel's angle in pivots)."""
    a, b = plane  # the two sensor axes across the spin axis
    size = math.sqrt(gyro[a] * gyro[a] + gyro[b] * gyro[b])  # not hypot: the compiled merger's libm rounds it otherwise
    return size if gyro[a] * accel[a] + gyro[b] * accel[b] >= 0.0 else -size


@dataclass
class MergerCounters:
    samples: int = 0
    extrapolated: int = 0  # seat samples emitted before a wheel had reported past them
    wheel_overrun: int = 0  # seat samples older than a wheel's kept history
    seat_out_of_order: int = 0
    bridged: int = 0  # bridge samples emitted in silences of the seat (included in `samples`)
    wheel_out_of_order: dict[str, int] = field(default_factory=dict)


class ChairMerger:
    """`push_batch(msg)` / `push(sensor_id, ...)` -> ready ChairSamples; `flush()` at the end."""

    def __init__(self, agent: Agent, max_wait_s: float = 2.0):
        self.max_wait_ns = int(max_wait_s * 1e9)
        seat, left, right = (agent.sensor(m) for m in (Mount.SEAT, Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL))
        if seat is None or left is None or right is None:
            raise ValueError(f"agent {agent.id}: needs seat, left_wheel and right_wheel sensors")
        self.seat_id = seat.id
        self.wheel_ids = {left.id: "left", right.id: "right"}
        self.spin = {left.id: sensor_axis(left.spin_axis), right.id: sensor_axis(right.spin_axis)}
        self.plane = {sensor: tuple(k for k in range(3) if k != index) for sensor, (index, _) in self.spin.items()}
        self.seat_axes = (sensor_axis(seat.forward_axis), sensor_axis(seat.left_axis),
                          up_axis(seat.forward_axis, seat.left_axis))
        self.wheels = {"left": WheelIntegrator(), "right": WheelIntegrator()}
        self.clocks = {"left": WheelClock(), "right": WheelClock()}  # each wheel's clock minus the seat's
        self.last_offsets = {"left": 0, "right": 0}
        self.last_yaw = math.nan
        self.pending: deque[tuple[int, float, tuple[float, float, float], tuple[float, float, float] | None]] = deque()
        self.last_seat_ns: int | None = None
        self.last_rotation = {"left": (0.0, 0.0), "right": (0.0, 0.0)}
        self.counters = MergerCounters()

    def push_batch(self, batch: Any) -> list[ChairSample]:
        """One ImuBatch message of any of the chair's sensors (others are ignored)."""
        out: list[ChairSample] = []
        n = len(batch.sample_offset_ns)
        has_mag = len(batch.mag_gauss) == 3 * n
        for i in range(n):
            accel = tuple(batch.accel_g[3 * i:3 * i + 3])
            gyro = tuple(batch.gyro_dps[3 * i:3 * i + 3])
            mag = tuple(batch.mag_gauss[3 * i:3 * i + 3]) if has_mag else None
            out += self.push(batch.sensor_id, batch.timestamp_ns + batch.sample_offset_ns[i], accel, gyro, mag)
        return out

    def push(self, sensor_id: str, time_ns: int, accel_g: tuple, gyro_dps: tuple, mag_gauss: tuple | None) -> list[ChairSample]:
        """One sample of one sensor (sensor frame)."""
        wheel = self.wheel_ids.get(sensor_id)
        if wheel is not None:
            index, sign = self.spin[sensor_id]
            before = self.wheels[wheel].out_of_order
            self.wheels[wheel].push(time_ns, sign * gyro_dps[index], plane_yaw_dps(gyro_dps, accel_g, self.plane[sensor_id]))
            if self.wheels[wheel].out_of_order != before:
                self.counters.wheel_out_of_order[sensor_id] = self.wheels[wheel].out_of_order
        elif sensor_id == self.seat_id:
            newest = self.pending[-1][0] if self.pending else self.last_seat_ns
            if newest is not None and time_ns <= newest:
                self.counters.seat_out_of_order += 1
            else:
                self.pending.append((time_ns, self._chair(gyro_dps)[2], self._chair(accel_g),
                                     None if mag_gauss is None else self._chair(mag_gauss)))
        return self._ready(flush=False)

    def flush(self) -> list[ChairSample]:
        return self._ready(flush=True)

    def _chair(self, vector: tuple) -> tuple[float, float, float]:
        (fi, fs), (li, ls), (ui, us) = self.seat_axes
        return (fs * vector[fi], ls * vector[li], us * vector[ui])

    def _ready(self, flush: bool) -> list[ChairSample]:
        out = []
        while self.pending:
            time_ns, yaw, accel, mag = self.pending[0]
            covered = all(w.newest_ns is not None and w.newest_ns >= time_ns + self.clocks[name].offset_ns
                          for name, w in self.wheels.items())
            overdue = self.pending[-1][0] - time_ns > self.max_wait_ns
            if not (covered or overdue or flush):
                break
            self.pending.popleft()
            if not covered:
                self.counters.extrapolated += 1
            if self.last_seat_ns is not None and time_ns - self.last_seat_ns > BRIDGE_AFTER_NS:
                for bridge_ns in range(self.last_seat_ns + BRIDGE_STEP_NS, time_ns - BRIDGE_STEP_NS // 2, BRIDGE_STEP_NS):
                    now = self._wheels_at(bridge_ns)
                    if any(seen for _, _, seen in now.values()):  # where a wheel was heard
                        out.append(self._sample(bridge_ns, math.nan, NAN3, None, now))
                        self.counters.bridged += 1
            out.append(self._sample(time_ns, yaw, accel, mag, self._wheels_at(time_ns)))
        return out

    def _wheels_at(self, time_ns: int) -> dict[str, tuple[float, float, bool]]:
        now = {name: w.at(time_ns + self.clocks[name].offset_ns) for name, w in self.wheels.items()}
        self.counters.wheel_overrun = sum(w.overrun for w in self.wheels.values())
        return now

    def _sample(self, time_ns: int, yaw: float, accel: tuple, mag: tuple | None,
                now: dict[str, tuple[float, float, bool]]) -> ChairSample:
        """The sample at `time_ns` with the wheels' increments since the previous one (`now`: `_wheels_at`)."""
        if self.last_seat_ns is None:  # the first sample only anchors the wheel integrals
            turned = {"left": (0.0, 0.0), "right": (0.0, 0.0)}
        else:
            turned = {name: (now[name][0] - self.last_rotation[name][0], now[name][1] - self.last_rotation[name][1])
                      for name in now}
            self._align(time_ns - self.last_seat_ns, yaw, now, turned)
        self.last_rotation, self.last_seat_ns, self.last_yaw = now, time_ns, yaw
        self.counters.samples += 1
        seen = [name for name in now if now[name][2]]
        # a wheel that was silent here knows nothing of the turn: the other one tells it alone
        wheel_yaw = sum(turned[name][1] for name in seen or now) / len(seen or now)
        return ChairSample(time_ns, yaw, turned["left"][0], turned["right"][0], accel, mag, wheel_yaw)

    def _align(self, dt_ns: int, yaw: float, now: dict[str, tuple[float, float, bool]],
               turned: dict[str, tuple[float, float]]) -> None:
        """Each wheel clock learns its offset from the seat's yaw and its own over consecutive seat samples."""
        consecutive = math.isfinite(yaw) and math.isfinite(self.last_yaw) and dt_ns <= SEAT_STEP_MAX_NS
        for name, clock in self.clocks.items():
            if not consecutive or not now[name][2] or clock.offset_ns != self.last_offsets[name]:
                clock.restart()  # a move of the offset, a gap, a silent wheel: the next three start afresh
            else:
                dt = dt_ns * 1e-9
                clock.add(0.5 * (self.last_yaw + yaw), turned[name][1] / dt, dt)
            self.last_offsets[name] = clock.offset_ns

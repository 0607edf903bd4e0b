"""A chair's three IMUs -> `ChairSample`s for the estimator: push-style, bounded memory.

Each sensor's samples arrive in its own time order (as `ImuBatch` messages or arrays), with any
interleaving between sensors. Each wheel's forward spin is integrated (trapezoid) into a running
rotation; every seat sample becomes a `ChairSample` that carries how far each wheel turned since
the previous seat sample, interpolated at the seat sample's time (device clocks, as the paper
uses them). So a lost wheel or seat packet loses no distance: the next increment spans it.

A seat sample waits until both wheels have reported past its time, but never more than
`max_wait_s` behind the newest seat sample: then a silent wheel is extrapolated at its last rate
(counted in `extrapolated`), and its rotation catches up when it reports again. The default
wait (2 s) outlasts the simulator's bursts of lost packets (0.3 s on average, docs/simulator.md),
so catch-ups are rare; the price is latency only while a wheel is silent. Samples not after their sensor's previous one are dropped and
counted (`out_of_order`). Pending seat samples and each wheel's recent history are bounded: a
seat stream more than `HISTORY` wheel samples (5 s) behind the wheels gets the oldest rotation
kept, counted in `wheel_overrun` (live streams share one clock and never drift that far apart).
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from edge.chair.estimator import ChairSample
from protocol.session import Agent, Mount

_INDEX = {"x": 0, "y": 1, "z": 2}
HISTORY = 1024  # wheel points kept: 5 s at 200 Hz, more than max_wait_s needs


def _axis(axis: str) -> tuple[int, float]:
    return _INDEX[axis[1]], (-1.0 if axis[0] == "-" else 1.0)


def _up_axis(forward: str, left: str) -> tuple[int, float]:
    """The sensor axis (index, sign) along forward x left, for axis-aligned mountings."""
    f, l = [0.0] * 3, [0.0] * 3
    fi, fs = _axis(forward)
    li, ls = _axis(left)
    f[fi], l[li] = fs, ls
    up = (f[1] * l[2] - f[2] * l[1], f[2] * l[0] - f[0] * l[2], f[0] * l[1] - f[1] * l[0])
    index = max(range(3), key=lambda i: abs(up[i]))
    return index, up[index]


class WheelIntegrator:
    """Running rotation (deg) of one wheel, with a bounded history to interpolate in."""

    def __init__(self) -> None:
        self.times: deque[int] = deque(maxlen=HISTORY)
        self.rotations: deque[float] = deque(maxlen=HISTORY)
        self.rate_dps = 0.0
        self.out_of_order = 0
        self.overrun = 0  # lookups older than the history: the seat fell > HISTORY samples behind

    @property
    def newest_ns(self) -> int | None:
        return self.times[-1] if self.times else None

    def push(self, time_ns: int, spin_dps: float) -> None:
        if self.times and time_ns <= self.times[-1]:
            self.out_of_order += 1
            return
        rotation = 0.0
        if self.times:
            rotation = self.rotations[-1] + 0.5 * (self.rate_dps + spin_dps) * (time_ns - self.times[-1]) * 1e-9
        self.times.append(time_ns)
        self.rotations.append(rotation)
        self.rate_dps = spin_dps

    def at(self, time_ns: int) -> float:
        """Rotation at `time_ns`: interpolated inside the history, extrapolated past its ends."""
        if not self.times:
            return 0.0
        if time_ns >= self.times[-1]:
            return self.rotations[-1] + self.rate_dps * (time_ns - self.times[-1]) * 1e-9
        i = bisect.bisect_right(self.times, time_ns)
        if i == 0:  # before the wheel's first sample, or (history full) before what is kept
            self.overrun += len(self.times) == self.times.maxlen
            return self.rotations[0]
        t0, t1 = self.times[i - 1], self.times[i]
        r0, r1 = self.rotations[i - 1], self.rotations[i]
        return r0 + (r1 - r0) * (time_ns - t0) / (t1 - t0)


@dataclass
class MergerCounters:
    samples: int = 0
    extrapolated: int = 0  # seat samples emitted before a wheel had reported past them
    wheel_overrun: int = 0  # seat samples older than a wheel's kept history
    seat_out_of_order: int = 0
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
        self.spin = {left.id: _axis(left.spin_axis), right.id: _axis(right.spin_axis)}
        self.seat_axes = (_axis(seat.forward_axis), _axis(seat.left_axis), _up_axis(seat.forward_axis, seat.left_axis))
        self.wheels = {"left": WheelIntegrator(), "right": WheelIntegrator()}
        self.pending: deque[tuple[int, float, tuple[float, float, float], tuple[float, float, float] | None]] = deque()
        self.last_seat_ns: int | None = None
        self.last_rotation = {"left": 0.0, "right": 0.0}
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
            self.wheels[wheel].push(time_ns, sign * gyro_dps[index])
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
            newest = [w.newest_ns for w in self.wheels.values()]
            covered = all(t is not None and t >= time_ns for t in newest)
            overdue = self.pending[-1][0] - time_ns > self.max_wait_ns
            if not (covered or overdue or flush):
                break
            self.pending.popleft()
            if not covered:
                self.counters.extrapolated += 1
            rotation = {name: w.at(time_ns) for name, w in self.wheels.items()}
            self.counters.wheel_overrun = sum(w.overrun for w in self.wheels.values())
            if self.last_seat_ns is None:  # the first sample only anchors the wheel integrals
                increments = {"left": 0.0, "right": 0.0}
            else:
                increments = {name: rotation[name] - self.last_rotation[name] for name in rotation}
            self.last_rotation, self.last_seat_ns = rotation, time_ns
            self.counters.samples += 1
            out.append(ChairSample(time_ns, yaw, increments["left"], increments["right"], accel, mag))
        return out

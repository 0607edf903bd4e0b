"""The chair merger's packed form: edge/chair/merger.py's state in two flat arrays, for the compiled
`merge_batch` (edge/chair/merge_kernel.py), and `PackedMerger`, which feeds it whole ImuBatch messages.

Why: the Python merger costs ~13 us per chair sample, two thirds of the edge's push path; the
compiled one, the messages' fields read into arrays included, 2.2 us (`reckon bench`,
docs/benchmarks.md), which took the whole push path from 0.17 to 0.87 M raw samples/s. merger.py stays the readable reference (change it first, then the kernel);
tests/edge/test_chair_merge_kernel.py holds the two to the same bits.

State: `ints` (int64: each wheel's history of times, ring head and count, counters, its clock's
offset; the pending seat samples' times; the merger's counters) and `floats` (float64: each wheel's
rotations, yaws, rates and clock sums; the pending seat samples' yaw, accel, mag). Both fixed size.
The pending seat samples are a ring of `PENDING` (10 s at 200 Hz, five times `max_wait_s`): a seat
sample that would overflow it releases the oldest as overdue, where the Python merger's queue would
grow (never in a stream whose seat runs at its rate: a sample waits at most `max_wait_s`).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from edge.chair.merger import HISTORY, MergerCounters, sensor_axis, up_axis
from protocol.session import Agent, Mount

PENDING = 2048
SEAT, LEFT, RIGHT = 0, 1, 2  # a sample's sensor; wheel w (0 left, 1 right) is role w + 1

# --- ints: per wheel a block of WHEEL_INTS, then the merger's own --------------------------
I_W_TIMES = 0  # HISTORY values, a ring
I_W_HEAD = HISTORY  # ring index of the oldest
I_W_COUNT = I_W_HEAD + 1
I_W_OUT_OF_ORDER = I_W_COUNT + 1
I_W_OVERRUN = I_W_OUT_OF_ORDER + 1
I_W_OFFSET = I_W_OVERRUN + 1  # WheelClock.offset_ns
I_W_LAST_OFFSET = I_W_OFFSET + 1  # ChairMerger.last_offsets
I_W_CLOCK_COUNT = I_W_LAST_OFFSET + 1
I_W_CLOCK_UPDATES = I_W_CLOCK_COUNT + 1
WHEEL_INTS = I_W_CLOCK_UPDATES + 1
I_PEND_TIMES = 2 * WHEEL_INTS  # PENDING values, a ring
I_PEND_HEAD = I_PEND_TIMES + PENDING
I_PEND_COUNT = I_PEND_HEAD + 1
I_LAST_SEAT = I_PEND_COUNT + 1
I_HAS_LAST_SEAT = I_LAST_SEAT + 1  # 0 until the first sample is out
I_SAMPLES = I_HAS_LAST_SEAT + 1  # MergerCounters, in order
I_EXTRAPOLATED = I_SAMPLES + 1
I_WHEEL_OVERRUN = I_EXTRAPOLATED + 1
I_SEAT_OUT_OF_ORDER = I_WHEEL_OVERRUN + 1
I_BRIDGED = I_SEAT_OUT_OF_ORDER + 1
I_MAX_WAIT = I_BRIDGED + 1
INTS_SIZE = I_MAX_WAIT + 1

# --- floats: per wheel a block of WHEEL_FLOATS, then the merger's own -----------------------
F_W_ROTATIONS = 0  # HISTORY values, the ring of I_W_TIMES
F_W_YAWS = HISTORY
F_W_RATE = 2 * HISTORY
F_W_YAW_RATE = F_W_RATE + 1
F_W_PREVIOUS = F_W_YAW_RATE + 1  # 3 values: WheelClock._previous
F_W_SUMS = F_W_PREVIOUS + 3  # 6 values: WheelClock._sums
F_W_SPAN = F_W_SUMS + 6
F_W_LAST_ROTATION = F_W_SPAN + 1  # ChairMerger.last_rotation: rotation, yaw
F_W_LAST_YAW = F_W_LAST_ROTATION + 1
WHEEL_FLOATS = F_W_LAST_YAW + 1
F_PEND_YAW = 2 * WHEEL_FLOATS  # PENDING values each, the ring of I_PEND_TIMES
F_PEND_ACCEL = F_PEND_YAW + PENDING  # 3 per sample
F_PEND_MAG = F_PEND_ACCEL + 3 * PENDING  # 3 per sample, NaN without
F_PEND_HAS_MAG = F_PEND_MAG + 3 * PENDING
F_LAST_YAW = F_PEND_HAS_MAG + PENDING
FLOATS_SIZE = F_LAST_YAW + 1

# --- config (float64): the mountings ----------------------------------------------------------
C_SPIN_INDEX, C_SPIN_SIGN, C_PLANE_A, C_PLANE_B = 0, 2, 4, 6  # 2 values each: left, right
C_SEAT = 8  # forward index, sign, left index, sign, up index, sign
CONFIG_SIZE = C_SEAT + 6

MergeBatch = Callable[..., tuple[np.ndarray, np.ndarray]]  # edge.chair.merge_kernel.merge_batch


class PackedMerger:
    """ChairMerger's behaviour on packed arrays: `push_batch(msg)` / `flush()` -> (times int64 (m,),
    values float64 (m, SAMPLE_WIDTH)), the rows edge/chair/layout.py's `pack_samples` would make of
    the same ChairSamples. `merge_batch` is the compiled step (ahead of time: reckon/kernels.py)."""

    def __init__(self, agent: Agent, merge_batch: MergeBatch, max_wait_s: float = 2.0):
        seat, left, right = (agent.sensor(m) for m in (Mount.SEAT, Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL))
        if seat is None or left is None or right is None:
            raise ValueError(f"agent {agent.id}: needs seat, left_wheel and right_wheel sensors")
        self.merge_batch = merge_batch
        self.seat_id = seat.id
        self.roles = {seat.id: SEAT, left.id: LEFT, right.id: RIGHT}
        self.wheel_sensors = (left.id, right.id)
        self.config = np.zeros(CONFIG_SIZE)
        for w, sensor in enumerate((left, right)):
            index, sign = sensor_axis(sensor.spin_axis)
            a, b = (k for k in range(3) if k != index)
            self.config[[C_SPIN_INDEX + w, C_SPIN_SIGN + w, C_PLANE_A + w, C_PLANE_B + w]] = index, sign, a, b
        for k, (index, sign) in enumerate((sensor_axis(seat.forward_axis), sensor_axis(seat.left_axis),
                                           up_axis(seat.forward_axis, seat.left_axis))):
            self.config[C_SEAT + 2 * k:C_SEAT + 2 * k + 2] = index, sign
        self.ints = np.zeros(INTS_SIZE, dtype=np.int64)
        self.ints[I_MAX_WAIT] = int(max_wait_s * 1e9)
        self.floats = np.zeros(FLOATS_SIZE)
        for w in range(2):
            base = w * WHEEL_FLOATS
            self.floats[base + F_W_PREVIOUS:base + F_W_PREVIOUS + 3] = np.nan
        self.floats[F_LAST_YAW] = np.nan
        self._none, self._no_times = np.zeros((0, 3)), np.zeros(0, dtype=np.int64)

    def push_batch(self, batch: Any) -> tuple[np.ndarray, np.ndarray]:
        """One ImuBatch message of any of the chair's sensors (others, and None, give nothing)."""
        return self.merge_batch(*self.arguments(batch))

    def flush(self) -> tuple[np.ndarray, np.ndarray]:
        """Every seat sample still waiting, its wheels extrapolated where they have not reported."""
        return self.merge_batch(*self.arguments(None, flush=True))

    def arguments(self, batch: Any, flush: bool = False) -> tuple:
        """`merge_batch`'s arguments for one ImuBatch (None, or another agent's sensor: no samples)."""
        role = None if batch is None else self.roles.get(batch.sensor_id)
        field_offsets = None if role is None else batch.sample_offset_ns
        n = 0 if field_offsets is None else len(field_offsets)
        if not n:
            # the merger settles after every sample, so no samples release nothing more (the kernel is
            # called all the same: a just-in-time one compiles on ChairEdge's first call, not on a stream's)
            return self.config, self.ints, self.floats, SEAT, 0, self._no_times, self._none, self._none, self._none, \
                int(flush)
        field_accel, field_gyro = batch.accel_g, batch.gyro_dps
        if len(field_accel) != 3 * n or len(field_gyro) != 3 * n:  # edge/health.py drops these first
            raise ValueError(f"ImuBatch of {batch.sensor_id} (sequence {batch.sequence}): {len(field_accel)} accel "
                             f"and {len(field_gyro)} gyro values for {n} samples, not 3 each")
        offsets = np.fromiter(field_offsets, np.int64, n)  # twice as fast as asarray on a repeated field
        accel = np.asarray(field_accel, dtype=np.float64).reshape(n, 3)
        gyro = np.asarray(field_gyro, dtype=np.float64).reshape(n, 3)
        # only the seat's magnetometer is read (the wheels' spin through theirs)
        mag = self._none
        if role == SEAT:
            field_mag = batch.mag_gauss
            if len(field_mag) == 3 * n:
                mag = np.asarray(field_mag, dtype=np.float64).reshape(n, 3)
        return self.config, self.ints, self.floats, role, batch.timestamp_ns, offsets, accel, gyro, mag, int(flush)

    @property
    def counters(self) -> MergerCounters:
        i = self.ints
        out_of_order = {sensor: int(i[w * WHEEL_INTS + I_W_OUT_OF_ORDER]) for w, sensor in enumerate(self.wheel_sensors)}
        return MergerCounters(int(i[I_SAMPLES]), int(i[I_EXTRAPOLATED]), int(i[I_WHEEL_OVERRUN]),
                              int(i[I_SEAT_OUT_OF_ORDER]), int(i[I_BRIDGED]),
                              {sensor: n for sensor, n in out_of_order.items() if n})

    @property
    def clock_offsets_ns(self) -> tuple[int, int]:
        """Each wheel's clock minus the seat's, as learned (left, right)."""
        return int(self.ints[I_W_OFFSET]), int(self.ints[WHEEL_INTS + I_W_OFFSET])

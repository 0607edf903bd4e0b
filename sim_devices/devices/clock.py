"""A simulated device's clock: the timestamps it puts on samples taken at true instants.

device time = (1 + drift) x true time + offset, plus a small per-sample jitter clipped so samples
never swap order; stamped in integer ns from the session epoch. Samples are taken at the
simulation's true instants; only their stamps carry the clock error. A clock drawn with zero SDs
(or `DeviceClock(epoch_ns)`) stamps true time.

A phone stamps on the truth's own clock (as a phone's own recording does), each stamp jittered in
ns and then kept strictly increasing: `jittered_stamps_ns`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

JITTER_CLIP_SD = 3.0  # a stamp's jitter is clipped at this many SD
JITTER_CLIP_PERIODS = 0.45  # and at this share of the sample period, under half: neighbours keep their order


@dataclass(frozen=True)
class DeviceClock:
    """device time = (1 + drift) x true time + offset, stamped in ns from the session epoch."""

    epoch_ns: int
    offset_s: float = 0.0
    drift: float = 0.0  # rate error, 1 (20 ppm = 2e-5)
    jitter_s: float = 0.0  # SD of each stamp's jitter

    @classmethod
    def draw(cls, rng: np.random.Generator, *, start_unix_s: int, offset_ms: float, drift_ppm: float,
             jitter_ms: float = 0.0) -> "DeviceClock":
        """A clock with epoch `start_unix_s` whose offset and drift are drawn with these SDs (offset
        first, then drift); `jitter_ms`: the SD of each stamp's jitter, drawn when stamping."""
        return cls(start_unix_s * 1_000_000_000, float(rng.normal(0.0, offset_ms * 1e-3)),
                   float(rng.normal(0.0, drift_ppm * 1e-6)), jitter_ms * 1e-3)

    def stamp_ns(self, true_s: np.ndarray, rng: np.random.Generator | None = None,
                 period_s: float = math.inf) -> np.ndarray:
        """Device timestamps (int64 ns) of events at true times `true_s` (s from the epoch).

        With `rng`, each stamp gets jitter clipped at 3 SD and at 0.45 `period_s`, so samples
        `period_s` apart keep their order; without it (or with no jitter) no draw is made.
        """
        device_s = (1.0 + self.drift) * np.asarray(true_s, dtype=np.float64) + self.offset_s
        if rng is not None and self.jitter_s > 0:
            limit = min(JITTER_CLIP_SD * self.jitter_s, JITTER_CLIP_PERIODS * period_s)
            device_s = device_s + np.clip(rng.normal(0.0, self.jitter_s, device_s.shape), -limit, limit)
        return self.epoch_ns + np.round(device_s * 1e9).astype(np.int64)


def jittered_stamps_ns(true_ns: np.ndarray, jitter_ms: float, rng: np.random.Generator) -> np.ndarray:
    """Stamps on the truth's clock: the true instants (int64 ns) plus Gaussian jitter (SD `jitter_ms`),
    then kept strictly increasing (a stamp that would not pass its predecessor is 1 ns after it)."""
    jitter = np.round(rng.normal(0.0, jitter_ms * 1e6, len(true_ns))).astype(np.int64)
    stamps = true_ns + jitter
    floor = np.maximum.accumulate(stamps - np.arange(len(stamps)))  # strictly increasing by at least 1 ns
    return floor + np.arange(len(stamps))

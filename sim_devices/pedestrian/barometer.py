"""The phone's barometer: the air pressure at the phone's height, as a BMP280 / BMP388-class sensor reports it.

True pressure (hPa) at the phone, height z above floor 0's level, session time t:
    p(z, t) = (ground_hpa + trend t + building(t)) exp(-z / H),  H = R_d T / g   (hypsometric, eq. 1)
with R_d = 287.05 J/(kg K) (dry air), T the indoor air temperature in kelvin and g = 9.80665 m/s^2:
H = 8,640 m at 22 deg C, so dp/dz = 0.117 hPa/m at 1008 hPa (about 0.12 hPa/m near sea level). `trend` is the session's weather
trend (drawn once, SD `weather_trend_hpa_per_h`); `building(t)` is a sum of jumps (ventilation,
doors against the building's over-pressure) at Poisson times, each taken over `hvac_rise_s`. Both
are the world: every phone in the session sees them. Per phone: a constant offset (SD
`offset_hpa`, the sensor's absolute accuracy) and white noise (`noise_hpa` RMS per sample).
Samples at `rate_hz` on the phone's motion (the nearest IMU sample), stamped like the IMU
samples (the session clock with `sensors.timestamp_jitter_ms` of jitter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_devices.devices.clock import jittered_stamps_ns
from sim_devices.pedestrian.params import BarometerParams

DRY_AIR_J_PER_KG_K = 287.05
STANDARD_GRAVITY = 9.80665


def scale_height_m(air_temperature_c: float) -> float:
    """H = R_d T / g (m): pressure falls by a factor e over this height."""
    return DRY_AIR_J_PER_KG_K * (air_temperature_c + 273.15) / STANDARD_GRAVITY


@dataclass(frozen=True)
class Atmosphere:
    """The session's air: ground pressure, its weather trend and the building's jumps (session clock)."""

    ground_hpa: float
    trend_hpa_per_s: float
    jump_times_s: np.ndarray  # from the session epoch
    jump_hpa: np.ndarray
    rise_s: float
    scale_height_m: float

    @classmethod
    def draw(cls, barometer: BarometerParams, span_s: float, rng: np.random.Generator) -> "Atmosphere":
        trend = float(rng.normal(0.0, barometer.weather_trend_hpa_per_h)) / 3600.0
        count = int(rng.poisson(barometer.hvac_jumps_per_min * span_s / 60.0))
        times = np.sort(rng.uniform(0.0, span_s, count))
        jumps = rng.normal(0.0, barometer.hvac_jump_hpa, count)
        return cls(barometer.ground_hpa, trend, times, jumps, barometer.hvac_rise_s,
                   scale_height_m(barometer.air_temperature_c))

    def pressure_hpa(self, session_s: np.ndarray, height_m: np.ndarray) -> np.ndarray:
        """True pressure at heights above floor 0 (m) and session times (s)."""
        base = self.ground_hpa + self.trend_hpa_per_s * session_s
        for start, jump in zip(self.jump_times_s.tolist(), self.jump_hpa.tolist()):
            share = np.clip((session_s - start) / self.rise_s, 0.0, 1.0)
            base = base + jump * share * share * (3.0 - 2.0 * share)
        return base * np.exp(-height_m / self.scale_height_m)  # eq. 1

    def record(self) -> dict[str, object]:
        return {"ground_hpa": self.ground_hpa, "trend_hpa_per_h": self.trend_hpa_per_s * 3600.0,
                "jumps": [{"time_s": t, "hpa": j} for t, j in zip(self.jump_times_s.tolist(), self.jump_hpa.tolist())],
                "scale_height_m": self.scale_height_m}


@dataclass(frozen=True)
class PressureStream:
    sensor_id: str
    time_ns: np.ndarray  # (n,) int64 stamps, session clock with jitter
    pressure_hpa: np.ndarray  # (n,) float64 reported
    true_hpa: np.ndarray  # (n,) at the sampled instant, no sensor error
    offset_hpa: float


def barometer_stream(sensor_id: str, walker_time_s: np.ndarray, position_m: np.ndarray, start_ns: int,
                     epoch_ns: int, atmosphere: Atmosphere, barometer: BarometerParams, jitter_ms: float,
                     rng: np.random.Generator) -> PressureStream:
    """One phone's Pressure samples at `barometer.rate_hz` over its walk (motion at the IMU rate)."""
    imu_rate = 1.0 / float(walker_time_s[1] - walker_time_s[0]) if len(walker_time_s) > 1 else barometer.rate_hz
    times = np.arange(0.0, float(walker_time_s[-1]) + 1e-9, 1.0 / barometer.rate_hz)
    rows = np.minimum(np.round(times * imu_rate).astype(np.int64), len(walker_time_s) - 1)
    session_s = (start_ns - epoch_ns) * 1e-9 + times
    true = atmosphere.pressure_hpa(session_s, position_m[rows, 2])
    offset = float(rng.normal(0.0, barometer.offset_hpa))
    reported = true + offset + rng.normal(0.0, barometer.noise_hpa, len(times))
    true_ns = start_ns + np.round(times * 1e9).astype(np.int64)
    return PressureStream(sensor_id, jittered_stamps_ns(true_ns, jitter_ms, rng), reported, true, offset)

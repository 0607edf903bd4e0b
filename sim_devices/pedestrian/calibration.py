"""The simulator against the paper's own results, measured on generated walks (nothing is fitted).

- `speed_check`: the paper's speed experiment (sec. 3.1, table 2): walkers of 1.69, 1.74 and 1.79 m
  walk 86 m straight, 5 trials each; the paper's method estimates the distance: walking frequency
  = the peak of the FFT of the last 5 s of acceleration magnitude (50 Hz, 250 samples, 0.2 Hz
  bins, no padding), speed = (0.001 f)^2 + 0.37 H f (its eq. 2), summed over the walk. Also the
  same model with the walker's true mean cadence, which isolates the step-length model's error.
- `heading_check`: the paper's heading experiment (sec. 3.3, table 3): calibrate on a stand, walk
  40 m straight, turn 90 deg, 10 runs; heading from the gyro integrated from the stand's pose with
  roll and pitch corrected towards gravity (the paper's eqs. 5-6, here as a rotation-matrix
  complementary filter), no gyro-bias estimation; error = mean phone heading over the 3 s after
  the turn's end minus the walking direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.session import Mount, Stand
from sim_devices.pedestrian.params import PedestrianParams
from sim_devices.pedestrian.person import PAPER_HEIGHTS_M, Person, draw_person, model_step_length_m
from sim_devices.pedestrian.phone import flat_rotation
from sim_devices.pedestrian.sensors import MagneticField
from sim_devices.pedestrian.simulate import WalkerRun, simulate_walker
from sim_devices.pedestrian.venues import Layout, Route

FFT_WINDOW_S = 5.0  # the paper: 5 s of 50 Hz data
WALK_BAND_HZ = (0.5, 3.5)
TILT_GAIN = 0.02  # per sample: the accelerometer's pull on roll and pitch (complementary filter)


@dataclass(frozen=True)
class SpeedResult:
    height_m: float
    cadence_hz: float
    true_m: float
    fft_m: tuple[float, ...]  # per trial, the paper's FFT cadence
    cadence_model_m: tuple[float, ...]  # per trial, the true mean cadence

    @property
    def fft_error_percent(self) -> float:
        return 100.0 * (float(np.mean(self.fft_m)) - self.true_m) / self.true_m

    @property
    def cadence_error_percent(self) -> float:
        return 100.0 * (float(np.mean(self.cadence_model_m)) - self.true_m) / self.true_m


def _layout(points: tuple[tuple[float, float], ...]) -> Layout:
    route = Route(tuple(f"n{i}" for i in range(len(points))), points)
    heading = math.degrees(math.atan2(points[1][1] - points[0][1], points[1][0] - points[0][0]))
    stand = Stand("start", points[0][0], points[0][1], heading_deg=heading)
    return Layout("calibration", "calibration", (), (), (stand,), (route,), (100.0, 100.0))


def _walk(plan: Layout, person: Person | None, trial: int, params: PedestrianParams, seed: int) -> WalkerRun:
    venue_seed, walker_seed = np.random.SeedSequence([seed, trial]).spawn(2)
    field = MagneticField.draw(params.magnetic, np.random.default_rng(venue_seed))
    return simulate_walker(plan, 0, (Mount.HAND,), params, walker_seed, field, 0, person=person)


def walking_interval(run: WalkerRun) -> tuple[int, int]:
    """Sample rows from the pick-up at the start stand to the end of the walk's motion."""
    start = int(np.searchsorted(run.timeline.time_s, run.phones[0].motion.windows[0].done_s))
    moving = np.flatnonzero(run.timeline.speed_mps > 0.0)
    return start, int(moving[-1]) + 1


def fft_cadence(accel_g: np.ndarray, rate_hz: float) -> np.ndarray:
    """Per sample, the paper's walking frequency from the trailing 5 s window (hop 1 s; before the
    first full window, the first window's)."""
    size = int(round(FFT_WINDOW_S * rate_hz))
    magnitude = np.linalg.norm(accel_g, axis=1)
    frequencies = np.fft.rfftfreq(size, 1.0 / rate_hz)
    band = (frequencies >= WALK_BAND_HZ[0]) & (frequencies <= WALK_BAND_HZ[1])
    out = np.empty(len(magnitude))
    hop = int(round(rate_hz))
    last = None
    for end in range(size, len(magnitude) + hop, hop):
        window = magnitude[max(0, min(end, len(magnitude)) - size): min(end, len(magnitude))]
        spectrum = np.abs(np.fft.rfft(window - window.mean(), n=size))
        value = float(frequencies[band][np.argmax(spectrum[band])])
        out[max(0, end - hop) if last is not None else 0: min(end, len(magnitude))] = value
        last = value
    return out


def speed_check(seed: int = 1, trials: int = 5, params: PedestrianParams | None = None,
                distance_m: float = 86.0) -> list[SpeedResult]:
    params = params or PedestrianParams()
    plan = _layout(((0.0, 0.0), (distance_m, 0.0)))
    rng = np.random.default_rng(seed)
    results = []
    for index, height in enumerate(PAPER_HEIGHTS_M):
        person = draw_person(index, params.people, params.gait, rng)
        fft_m, cadence_m = [], []
        true_m = 0.0
        for trial in range(trials):
            run = _walk(plan, person, 100 * index + trial, params, seed)
            start, end = walking_interval(run)
            rate = params.sensors.rate_hz
            accel = run.phones[0].accel_g[start:end].astype(float)
            frequency = fft_cadence(accel, rate)
            speed = (0.001 * frequency) ** 2 + 0.37 * height * frequency  # the paper's eq. 2
            fft_m.append(float(np.sum(speed) / rate))
            steps = run.timeline.phase[end - 1] - run.timeline.phase[start]
            mean_cadence = steps / (run.timeline.time_s[end - 1] - run.timeline.time_s[start])
            cadence_m.append(float((0.001 * mean_cadence) ** 2 + 0.37 * height * mean_cadence)
                             * float(run.timeline.time_s[end - 1] - run.timeline.time_s[start]))
            true_m = float(run.timeline.s_m[end - 1] - run.timeline.s_m[start])
        results.append(SpeedResult(height, person.cadence_hz, true_m, tuple(fft_m), tuple(cadence_m)))
    return results


def _tilt_corrected_heading(run: WalkerRun, stand: Stand, rate_hz: float) -> np.ndarray:
    """Heading (rad, unwrapped) of the phone's top edge from the gyro, starting at the stand's pose."""
    phone = run.phones[0]
    rotation = flat_rotation(np.array([math.radians(stand.heading_deg)]), np.array([math.radians(stand.tilt_deg)]),
                             np.zeros(1))[0]
    still = phone.motion.windows[0].still_s
    begin = int(np.searchsorted(run.timeline.time_s, still))
    out = np.zeros(len(phone.gyro_dps))
    gyro = np.radians(phone.gyro_dps.astype(float)) / rate_hz
    accel = phone.accel_g.astype(float)
    for row in range(begin, len(gyro)):
        angle = gyro[row]
        theta = float(np.linalg.norm(angle))
        if theta > 1e-12:
            k = angle / theta
            cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            rotation = rotation @ (np.eye(3) + math.sin(theta) * cross + (1 - math.cos(theta)) * cross @ cross)
        measured = accel[row] / max(np.linalg.norm(accel[row]), 1e-9)
        predicted = rotation.T @ np.array([0.0, 0.0, 1.0])
        axis = np.cross(measured, predicted)  # R (I + [axis]x) moves the predicted up towards the measured
        if 0.9 < np.linalg.norm(accel[row]) < 1.1:  # the paper's eq. 6 holds when only gravity acts
            rotation = rotation @ (np.eye(3) + TILT_GAIN * np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]],
                                                                    [-axis[1], axis[0], 0]]))
            u, _, vt = np.linalg.svd(rotation)
            rotation = u @ vt
        out[row] = math.atan2(rotation[1, 1], rotation[0, 1])
    return np.unwrap(out)


def heading_check(seed: int = 1, runs: int = 10, params: PedestrianParams | None = None) -> list[float]:
    """Heading errors (deg) after 40 m straight and a 90 deg left turn, one per run."""
    params = params or PedestrianParams()
    plan = _layout(((0.0, 0.0), (40.0, 0.0), (40.0, 20.0)))
    errors = []
    for run_index in range(runs):
        person = draw_person(run_index % 3, params.people, params.gait, np.random.default_rng([seed, run_index]))
        run = _walk(plan, person, 1000 + run_index, params, seed)
        heading = _tilt_corrected_heading(run, plan.stands[0], params.sensors.rate_hz)
        corner = run.path.corners[0]
        after = float(np.searchsorted(np.maximum.accumulate(run.timeline.s_m), corner.end_m))
        rows = slice(int(after), int(after + 3 * params.sensors.rate_hz))
        error = np.degrees(np.mean(heading[rows]) - corner.heading_after_rad)
        errors.append(float((error + 180.0) % 360.0 - 180.0))
    return errors


def step_model_speed_mps(height_m: float, cadence_hz: float, params: PedestrianParams | None = None) -> float:
    """The simulator's cruise speed for a stature and cadence before the person's own factor."""
    params = params or PedestrianParams()
    return cadence_hz * model_step_length_m(height_m, cadence_hz, params.gait)

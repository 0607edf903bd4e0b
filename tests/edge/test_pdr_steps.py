"""Step detection (edge/pedestrian/steps.py): crafted signals, and the Oxford step-counter recordings
(../shared/data/steps/oxford, CC BY 4.0: phones in hand and pocket, counted steps), skipped
cleanly when absent."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from edge.pedestrian import steps as pdr_steps
from edge.pedestrian.steps import StepSettings, StepState

OXFORD = Path(__file__).resolve().parents[3] / "shared" / "data" / "steps" / "oxford"
GOAL_PCT = 3.0  # the goal for step counting


def count_steps(time_ns: np.ndarray, accel_ms2: np.ndarray) -> StepState:
    state, settings = StepState(), StepSettings()
    for t, a in zip(time_ns, accel_ms2):
        state, _ = pdr_steps.step(settings, state, int(t), (float(a[0]), float(a[1]), float(a[2])))
    return state


def oxford_recordings() -> list[tuple[str, np.ndarray, np.ndarray, int]]:
    """(name, time ns, accel m/s^2, true steps): the optimisation walk (its count in stats.csv)
    and the validation walks (the ground-truth column's last value)."""
    out = []
    folder = OXFORD / "optimisation_Pixel_Jamie_Hard_InHand_1"
    if folder.is_dir():
        stats = {line.split(",")[0].strip(): int(line.split(",")[-1]) for line in
                 (OXFORD / "stats.csv").read_text().splitlines() if line and not line.startswith("#")}
        rows = np.loadtxt(folder / "accelerometer.csv", delimiter=",")
        out.append((folder.name, rows[:, 0], rows[:, 2:5], stats["Pixel_Jamie_Hard_InHand_1"]))
    for path in sorted((OXFORD / "validation").glob("*.csv")) if OXFORD.is_dir() else []:
        rows = np.loadtxt(path, delimiter=",")
        out.append((path.stem, rows[:, 0], rows[:, 1:4], int(rows[-1, 5])))
    return out


def test_a_steady_walk_gives_one_step_per_bounce_and_its_amplitude():
    rate_hz, cadence_hz, seconds = 100.0, 1.9, 20.0
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    accel = np.zeros((len(t), 3))
    accel[:, 2] = 9.81 + 3.0 * np.sin(2 * math.pi * cadence_hz * t)
    state = count_steps((t * 1e9).astype(np.int64) + 10**18, accel)
    assert abs(state.count - cadence_hz * seconds) <= 1


def test_standing_still_and_fidgeting_count_no_steps():
    rng = np.random.default_rng(3)
    t = np.arange(3000) / 100.0
    accel = np.column_stack([rng.normal(0, 0.1, len(t)), rng.normal(0, 0.1, len(t)),
                             9.81 + 0.3 * np.sin(2 * math.pi * 0.7 * t)])
    assert count_steps((t * 1e9).astype(np.int64), accel).count == 0


def test_gaps_and_backwards_times_are_counted_not_raised():
    settings, state = StepSettings(), StepState()
    for t_ns in (0, 10_000_000, 20_000_000, 15_000_000, 900_000_000, 910_000_000):
        state, _ = pdr_steps.step(settings, state, t_ns, (0.0, 0.0, 9.81))
    assert state.backwards == 1 and state.gaps == 1


@pytest.mark.skipif(not OXFORD.is_dir(), reason=f"shared Oxford step-counter data not found at {OXFORD}")
@pytest.mark.parametrize("index", range(4))
def test_oxford_step_counts_within_the_goal(index):
    recordings = oxford_recordings()
    if index >= len(recordings):
        pytest.skip("recording not present")
    name, time_ns, accel, truth = recordings[index]
    counted = count_steps(time_ns, accel).count
    assert abs(counted - truth) <= GOAL_PCT / 100.0 * truth, (name, counted, truth)

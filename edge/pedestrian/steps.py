"""Streaming step detection from a phone's accelerometer, orientation independent.

Only the magnitude |a| is used, so the phone may be in the hand, swinging or in a pocket:
    1. |a| (m/s^2, gravity included) through two cascaded first-order low-passes (`cutoff_hz`):
       -12 dB/octave above the cutoff removes the heel-strike ringing, keeps the 1.5-2.5 Hz steps;
    2. a step is a local maximum of the filtered |a| that stands at least `min_rise_ms2` and
       `rise_fraction` of the recent steps' typical rise above the valley before it (an adaptive
       threshold: strides in a pocket rise 10 m/s^2, a phone held flat 2-4), and comes at least
       `refractory_s` after the previous step (a second peak inside one step is the toe-off);
    3. per step: the Weinberg amplitude (a_max - a_min)^(1/4) over the step (Weinberg 2002,
       Analog Devices AN-602; step length = K * amplitude) and the step's duration.

Settings were tuned on the Oxford step-counter set's optimisation recording (Pixel, in hand;
Oxford-step-counter/DataSet, CC BY 4.0, shared/data/steps/oxford) and checked on its three
validation recordings (docs/pdr-estimator.md). `step(settings, state, time_ns, accel_ms2)` is pure;
the state is a few floats. dt comes from the timestamps: a gap longer than `gap_s` restarts the
filters (counted in `gaps`), a timestamp that does not advance is ignored (counted in `backwards`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace


@dataclass(frozen=True)
class StepSettings:
    cutoff_hz: float = 3.0  # low-pass of |a|: above brisk walking (2.5 steps/s), below heel-strike ringing
    refractory_s: float = 0.3  # no two steps closer than this (running tops out near 3.3 steps/s)
    min_rise_ms2: float = 1.0  # a peak must rise this far above its valley (standing, fidgeting: < 0.5)
    rise_fraction: float = 0.4  # ... and this fraction of the typical rise of recent steps
    rise_memory_steps: float = 8.0  # the typical rise follows the last few steps (a change of grip)
    max_step_s: float = 1.2  # a longer interval is a pause: the next step's duration is capped here
    gap_s: float = 0.25  # a sampling gap longer than this restarts the filters


@dataclass(frozen=True)
class StepEvent:
    time_ns: int  # the peak's sample time
    duration_s: float  # since the previous step, at most max_step_s
    amplitude_ms2: float  # a_max - a_min of the filtered |a| over the step
    weinberg: float  # amplitude ** 0.25 (m^0.25 s^-0.5); step length = K * weinberg
    count: int  # steps so far, this one included


@dataclass(frozen=True)
class StepState:
    time_ns: int = -1  # last sample accepted; -1 before the first
    fast_ms2: float = 0.0  # first low-pass stage of |a|
    filtered_ms2: float = 0.0  # second stage: the signal peaks are found in
    rising: bool = False  # filtered |a| rose on the last sample
    peak_time_ns: int = 0  # the previous sample (the peak candidate when the signal turns down)
    valley_ms2: float = math.inf  # lowest filtered |a| since the last step
    step_max_ms2: float = -math.inf  # highest since the last step (the step's a_max)
    typical_rise_ms2: float = 0.0  # running mean of accepted rises; 0 until the first step
    last_step_ns: int | None = None
    count: int = 0
    gaps: int = 0
    backwards: int = 0


def step(settings: StepSettings, state: StepState, time_ns: int,
         accel_ms2: tuple[float, float, float]) -> tuple[StepState, StepEvent | None]:
    """Feed one accelerometer sample (m/s^2, any orientation); returns the new state and the step
    completed at the previous sample, if any (steps are known one sample after their peak)."""
    magnitude = math.sqrt(accel_ms2[0] ** 2 + accel_ms2[1] ** 2 + accel_ms2[2] ** 2)
    if state.time_ns < 0 or time_ns - state.time_ns > settings.gap_s * 1e9:
        return replace(state, time_ns=time_ns, fast_ms2=magnitude, filtered_ms2=magnitude, rising=False,
                       peak_time_ns=time_ns, valley_ms2=magnitude, step_max_ms2=magnitude,
                       gaps=state.gaps + (state.time_ns >= 0)), None
    if time_ns <= state.time_ns:
        return replace(state, backwards=state.backwards + 1), None
    dt_s = (time_ns - state.time_ns) * 1e-9
    alpha = 1.0 - math.exp(-2.0 * math.pi * settings.cutoff_hz * dt_s)
    fast = state.fast_ms2 + alpha * (magnitude - state.fast_ms2)
    filtered = state.filtered_ms2 + alpha * (fast - state.filtered_ms2)
    rising = filtered > state.filtered_ms2
    event = None
    valley, step_max, typical, last_step, count = (state.valley_ms2, max(state.step_max_ms2, state.filtered_ms2),
                                                   state.typical_rise_ms2, state.last_step_ns, state.count)
    if state.rising and not rising:  # the previous sample was a local maximum
        peak = state.filtered_ms2
        rise = peak - valley
        since_s = math.inf if last_step is None else (state.peak_time_ns - last_step) * 1e-9
        if (rise >= settings.min_rise_ms2 and rise >= settings.rise_fraction * typical
                and since_s >= settings.refractory_s):
            amplitude = step_max - valley
            count += 1
            event = StepEvent(state.peak_time_ns, min(since_s, settings.max_step_s), amplitude,
                              amplitude ** 0.25, count)
            weight = 1.0 / min(count, settings.rise_memory_steps)
            typical += weight * (rise - typical)
            last_step, valley, step_max = state.peak_time_ns, peak, -math.inf
    valley = min(valley, filtered)
    return replace(state, time_ns=time_ns, fast_ms2=fast, filtered_ms2=filtered, rising=rising,
                   peak_time_ns=state.time_ns, valley_ms2=valley, step_max_ms2=step_max,
                   typical_rise_ms2=typical, last_step_ns=last_step, count=count), event

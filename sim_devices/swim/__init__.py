"""Swimming-pool simulator: swimmers (five strokes, straight and diagonal routes, open turns) wearing
TSND121-class IMUs at the waist, upper back and back of the head, and kickboards, with truth per length.

`simulate_set(stroke, route, mounts, lengths, seed)` returns one agent's sensor streams and truth
(no file); `simulate_swim(output, seed)` writes a whole session log (MCAP). Every figure lives in
`SwimParams` with its source (docs/simulator-swim.md). Modules, in data-flow order: params, swimmer
-> path -> timeline -> attitude -> imu -> simulate -> session; calibration runs the paper's method
on simulated sets against the paper's own results.
"""

from sim_devices.swim.params import STROKES, SwimParams, describe, error_free, params_with_overrides
from sim_devices.swim.session import DEFAULT_STROKES, SwimSummary, simulate_swim
from sim_devices.swim.simulate import SensorStream, SetTruth, simulate_set

__all__ = ["DEFAULT_STROKES", "STROKES", "SensorStream", "SetTruth", "SwimParams", "SwimSummary", "describe",
           "error_free", "params_with_overrides", "simulate_set", "simulate_swim"]

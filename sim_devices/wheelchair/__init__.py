"""Wheelchair-basketball venue simulator: players' motion, contacts, three IMUs per chair, goal beacons.

`simulate(players, duration_s, seed, output)` writes a session log (MCAP) with raw sensor streams and
ground truth; every parameter lives in `SimParams` (docs/simulator.md). Modules, in data-flow order:
params, tactics -> steering -> motion, kinematics -> impacts -> magnetic, devices (errors and clocks from
`sim_devices.devices`), radio, session.
"""

from sim_devices.wheelchair.params import SimParams, describe, error_free, params_with_overrides
from sim_devices.wheelchair.session import SimSummary, simulate

__all__ = ["SimParams", "SimSummary", "describe", "error_free", "params_with_overrides", "simulate"]

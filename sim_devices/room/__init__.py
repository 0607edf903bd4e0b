"""The camera-identity paper's room as a simulated venue: people walking forwards, backwards and
sideways, standing, turning and sitting, each wearing a waist IMU, optionally filmed by the
simulated tracker (docs/simulator-room.md).

`simulate_room(output, seed, people, duration_s)` writes a session log (MCAP); `simulate_walk` gives
the motion alone; `calibration.session_fit` measures the paper's speed-to-vertical-acceleration
relation (r = 0.91) on a session. Modules, in data-flow order: params, person -> activities ->
gait -> walk, imu, session; calibration.
"""

from sim_devices.room.calibration import SpeedAccelFit, session_fit
from sim_devices.room.params import RoomParams, describe, error_free, params_with_overrides, room_size
from sim_devices.room.session import RoomSummary, simulate_room
from sim_devices.room.walk import Motion, simulate_walk

__all__ = ["Motion", "RoomParams", "RoomSummary", "SpeedAccelFit", "describe", "error_free", "params_with_overrides",
           "room_size", "session_fit", "simulate_room", "simulate_walk"]

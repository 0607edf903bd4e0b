"""Simulated external camera tracker: anonymous tracks over any set of true paths (docs/simulator-camera.md).

`simulate_tracks(people, area_m, params, rng)` turns true paths (`PersonPath`) into what a
tracker reports: noisy positions under anonymous ids that fragment, switch at crossings, merge,
split, and include false tracks; `camera_items` turns the result into CameraFrame and
TruthTrackLabel log items; `extra_people` adds walkers without sensors. Presets: `ROOM` (the
camera-identity paper's stereo head tracker, 3 m x 5.6 m, 20 fps) and `COURT` (a multi-camera
tracker over a 28 m x 15 m court, 25 fps). Modules: params -> paths -> identity -> tracker.
"""

from sim_devices.camera.params import COURT, PRESETS, ROOM, TrackerParams, describe, params_with_overrides
from sim_devices.camera.paths import SEATED_HEAD_HEIGHT_M, PersonPath, extra_people
from sim_devices.camera.tracker import CameraFrameData, CameraRecording, camera_items, simulate_tracks

__all__ = ["COURT", "PRESETS", "ROOM", "SEATED_HEAD_HEIGHT_M", "CameraFrameData", "CameraRecording", "PersonPath",
           "TrackerParams", "camera_items", "describe", "extra_people", "params_with_overrides", "simulate_tracks"]

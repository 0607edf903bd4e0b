"""Every figure of the simulated camera tracker, with unit, accepted range and source, in two presets.

`TrackerParams` nests one frozen dataclass per effect; a figure's dotted key is `<group>.<field>`
(`gaps.rate_per_min`, `merges.distance_m`). The field defaults are the COURT preset (a fixed
multi-camera tracker over a 28 m x 15 m wheelchair-basketball court) and their metadata hold
COURT's sources; ROOM (the camera-identity paper's stereo head tracker over a 3 m x 5.6 m floor,
../shared/seeds/004_85e02368941c3567.txt) differs where `ROOM_SOURCES` says why. "assumption"
marks a figure with no published number behind it; its reasoning follows. docs/simulator-camera.md
prints both presets from `describe`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from protocol.errors import ConfigError
from sim_devices.param_table import param, rows, with_overrides

_p = param

# Where a COURT figure's published anchor is stated once (docs/simulator-camera.md, References).
_TRACAB = ("TRACAB Gen4/Gen5 optical tracking: position RMSE 0.09 / 0.08 m against VICON (Linke, Link & Lames "
           "2020), i.e. about 0.06 m per axis")
_CALIBRATED = ("assumption, set so that the default 10-chair game breaks identities about 2.4 times per "
               "chair-minute, about half of ByteTrack's 4.5 ID switches per player-minute on SportsMOT "
               "(docs/simulator-camera.md)")


@dataclass(frozen=True)
class CameraParams:
    """Frames, clock and field of view."""

    frame_rate_hz: float = _p(25.0, "Hz", 1.0, 120.0, "SportVU (six cameras over an NBA court) reports positions 25 "
                              "times a second; SportsMOT's clips are 25 fps; issue: 10-25 fps")
    frame_jitter_ms: float = _p(2.0, "ms", 0.0, 50.0, "SD of a frame stamp around its true capture time (clipped to "
                                "+-45 % of a frame); assumption: genlocked cameras stamp within about 1 ms")
    clock_offset_ms: float = _p(60.0, "ms", -5000.0, 5000.0, "constant offset of the tracker clock (stamp = capture "
                                "+ offset); assumption: stamped after 1-2 frames of processing on an NTP host; the "
                                "hub estimates it (lag search +-0.5 s, algorithms.md)")
    frame_loss_rate: float = _p(0.001, "1", 0.0, 0.5, "share of frames lost whole (a gap in frame numbers); "
                                "assumption")
    fov_margin_m: float = _p(0.5, "m", -10.0, 10.0, "the view reaches this far beyond the area's edges (negative: "
                             "short of them); assumption: the calibrated volume ends 0.5 m outside the lines, chairs "
                             "roll up to 1 m out (docs/simulator.md)")
    reports_height: int = _p(0, "0/1", 0, 1, "SportVU reports players' and referees' x, y only")


@dataclass(frozen=True)
class NoiseParams:
    """Position error per axis: white per frame plus a slowly correlated part (Gauss-Markov) per person."""

    white_sd_m: float = _p(0.06, "m", 0.0, 2.0, _TRACAB + "; white part")
    correlated_sd_m: float = _p(0.06, "m", 0.0, 2.0, "the tracked point (head, trunk) of a seated player leans "
                                "0.1-0.2 m over the chair while pushing; assumption, makes the total 0.085 m per axis, "
                                "above TRACAB's")
    correlation_s: float = _p(2.0, "s", 0.01, 600.0, "time constant of the correlated part; assumption (a "
                              "push or a lean lasts 1-3 s)")
    height_sd_m: float = _p(0.05, "m", 0.0, 1.0, "SD of a reported head height; assumption (only with "
                            "camera.reports_height)")


@dataclass(frozen=True)
class GapParams:
    """Occlusion gaps: a person's track is lost and comes back with a new id."""

    rate_per_min: float = _p(0.4, "1/min", 0.0, 60.0, "hazard per person-minute in view; " + _CALIBRATED)
    occluded_rate_per_s: float = _p(0.04, "1/s", 0.0, 10.0, "extra hazard while another person is within "
                                    "gaps.occlusion_distance_m; " + _CALIBRATED)
    occlusion_distance_m: float = _p(1.2, "m", 0.0, 10.0, "a marking defender 1.2 m away (docs/simulator.md) "
                                     "hides part of the player in some views; assumption")
    still_rate_per_s: float = _p(0.0, "1/s", 0.0, 10.0, "extra hazard while the person stands still; 0: detectors "
                                 "of this class find still people")
    still_speed_mps: float = _p(0.15, "m/s", 0.0, 2.0, "below this speed a person counts as still")
    median_s: float = _p(0.8, "s", 0.05, 60.0, "median gap (lognormal); assumption: an occlusion lasts as long as "
                         "two chairs take to pass, about 1 s")
    spread: float = _p(0.8, "1", 0.0, 3.0, "sigma of the gap's log-duration; assumption")
    max_s: float = _p(10.0, "s", 0.05, 600.0, "longest gap; assumption")


@dataclass(frozen=True)
class SwitchParams:
    """Identity switches: two tracks exchange their people where two people pass close."""

    distance_m: float = _p(1.0, "m", 0.0, 10.0, "an encounter is a pass closer than this: two chairs this close "
                           "overlap in most views (they touch at 0.9 m); assumption")
    probability: float = _p(0.1, "1", 0.0, 1.0, "chance that an encounter swaps the two tracks at its closest "
                            "approach; " + _CALIBRATED)
    release_factor: float = _p(1.5, "1", 1.0, 10.0, "an encounter ends when the pair is this many times "
                               "switches.distance_m apart (hysteresis: one decision per pass)")


@dataclass(frozen=True)
class MergeParams:
    """Merges: people close together become one track at their centroid, labelled "a+b"."""

    distance_m: float = _p(0.95, "m", 0.0, 10.0, "chairs in contact are 0.9 m apart: only touching chairs fuse; "
                           "assumption")
    probability: float = _p(0.1, "1", 0.0, 1.0, "chance that an encounter closer than merges.distance_m fuses; "
                            "assumption (several views keep most touching chairs apart)")
    release_factor: float = _p(1.3, "1", 1.0, 10.0, "a merge ends when the pair is this many times "
                               "merges.distance_m apart; one of them keeps the merged id, the other gets a new one")


@dataclass(frozen=True)
class SplitParams:
    """Splits: one person briefly seen as two tracks."""

    rate_per_min: float = _p(0.2, "1/min", 0.0, 60.0, "per person-minute in view; assumption (a chair and its "
                             "player, or a raised arm, detected apart)")
    mean_s: float = _p(1.0, "s", 0.05, 60.0, "mean duration (exponential); assumption")
    offset_m: float = _p(0.4, "m", 0.0, 5.0, "distance of the second track from the person; assumption")
    takeover_probability: float = _p(0.5, "1", 0.0, 1.0, "chance that the second track lives on and the first "
                                     "ends (the split breaks the identity); assumption")


@dataclass(frozen=True)
class FalseTrackParams:
    """False tracks: short-lived tracks of nobody (label ""), random walks."""

    rate_per_min: float = _p(2.0, "1/min", 0.0, 600.0, "births per camera-minute; assumption (bench, ball, people "
                             "at the edge of the view)")
    mean_s: float = _p(1.0, "s", 0.04, 600.0, "mean lifetime (exponential, at least false_tracks.min_s); "
                       "assumption")
    min_s: float = _p(0.2, "s", 0.0, 60.0, "shortest lifetime; a tracker confirms a track after a few frames "
                      "(ByteTrack: 1-3)")
    walk_mps: float = _p(0.5, "m/sqrt(s)", 0.0, 10.0, "random-walk SD per sqrt(s); assumption")


@dataclass(frozen=True)
class ExtrasParams:
    """People without sensors (referees, coaches, bystanders): how many, and how they walk."""

    count: int = _p(2, "people", 0, 50, "the issue: two referees on court")
    speed_min_mps: float = _p(0.6, "m/s", 0.05, 5.0, "walking speed per leg drawn in [min, max]; comfortable adult "
                              "gait 1.27-1.46 m/s (Bohannon 1997), slower while watching play; assumption")
    speed_max_mps: float = _p(1.6, "m/s", 0.05, 5.0, "see extras.speed_min_mps")
    pause_max_s: float = _p(4.0, "s", 0.0, 60.0, "standing still at each waypoint for [0, max] s; assumption")
    margin_m: float = _p(1.0, "m", -10.0, 10.0, "waypoints lie in the area grown by this; assumption: referees work "
                         "along and just outside the lines")
    height_m: float = _p(1.75, "m", 0.5, 2.5, "head-top height = stature; adult men 1.70-1.80 m; assumption")


@dataclass(frozen=True)
class TrackerParams:
    """All tracker figures; the dotted key of a field is `<group>.<field>`."""

    camera: CameraParams = field(default_factory=CameraParams)
    noise: NoiseParams = field(default_factory=NoiseParams)
    gaps: GapParams = field(default_factory=GapParams)
    switches: SwitchParams = field(default_factory=SwitchParams)
    merges: MergeParams = field(default_factory=MergeParams)
    splits: SplitParams = field(default_factory=SplitParams)
    false_tracks: FalseTrackParams = field(default_factory=FalseTrackParams)
    extras: ExtrasParams = field(default_factory=ExtrasParams)


COURT = TrackerParams()

# ROOM: the paper's two Bumblebee2 stereo cameras 2.2 m up, heads tracked by frame differencing.
_ROOM_CHANGES: dict[str, tuple[Any, str]] = {
    "camera.frame_rate_hz": (20.0, "the paper: 20 fps"),
    "camera.frame_jitter_ms": (5.0, "assumption: FireWire cameras stamped by a 2010 PC"),
    "camera.clock_offset_ms": (150.0, "assumption: the paper aligned video and sensor logs afterwards; a few frames "
                                      "of offset"),
    "camera.frame_loss_rate": (0.005, "assumption: a PC grabbing two stereo streams drops a frame now and then"),
    "camera.fov_margin_m": (0.0, "the paper's sensing area (3 m x 5.6 m) is the view; people leave it (subjects B "
                                 "and C were outside for 58 s and 178 s of 297 s)"),
    "camera.reports_height": (1, "the paper: stereo gives the head top's 3-D position"),
    "noise.white_sd_m": (0.04, "stereo depth: StereoSORT 50 mm median depth error (Sensors 2025); Bumblebee2 "
                               "geometry (12 cm baseline, 0.2 px disparity) gives 2-9 cm at 3-6 m"),
    "noise.correlated_sd_m": (0.03, "the head top sways about the waist sensor while walking; assumption"),
    "noise.correlation_s": (1.0, "assumption: a step cycle and posture changes, about 1 s"),
    "noise.height_sd_m": (0.03, "stereo depth error along the vertical (cameras look down); assumption"),
    "gaps.rate_per_min": (0.6, "the paper's paths break where frame differencing fails (Fig. 4); assumption, "
                               "more than COURT's"),
    "gaps.occluded_rate_per_s": (0.1, "assumption: a closer person hides a head from a camera 2.2 m up"),
    "gaps.occlusion_distance_m": (0.7, "assumption: two people within an arm's length"),
    "gaps.still_rate_per_s": (0.1, "the paper tracks by frame differencing (sec. 3.2), which loses people who stand "
                                   "still; assumption: lost after about 10 s still (body sway keeps them a while), "
                                   "back when they move"),
    "gaps.median_s": (1.0, "assumption"),
    "switches.distance_m": (0.6, "assumption: heads within 0.6 m (shoulder to shoulder 0.45-0.5 m)"),
    "switches.probability": (0.0, "calibrated: the paper names fused close people and broken paths, not swapped "
                                  "ones (sec. 3.2, 4.2), and a fusion already hands its id to one of its people at "
                                  "random when it ends; with swaps of 0.1 per close pass even an ideal eq. 1 caps the "
                                  "paper's method at 79 % of the time (0.3: 64-73 %), below the 95-100 % it reports "
                                  "(docs/simulator-camera.md, ROOM against the paper)"),
    "merges.distance_m": (0.5, "the paper: people close together fuse into one object; assumption: heads within "
                               "0.5 m"),
    "merges.probability": (0.1, "calibrated: the paper's people close together are sometimes fused (sec. 4.2); "
                                "with the paper's method and an ideal eq. 1 (its reported 95-100 % is reachable "
                                "only if fusions are rare) the time correct is 97 % at 0, 92 % at 0.1, 85 % at "
                                "0.3 (297 s, seeds 1-5): its result allows about 0.05 or less; 0.1 is on the harsh side "
                                "(docs/simulator-camera.md, ROOM against the paper)"),
    "splits.rate_per_min": (0.5, "the paper: one person is sometimes several objects; assumption"),
    "splits.mean_s": (1.5, "assumption"),
    "splits.offset_m": (0.3, "assumption: a head and a shoulder or raised hand"),
    "false_tracks.rate_per_min": (1.0, "frame differencing picks up anything that moves (a chair, a door); "
                                       "assumption"),
    "false_tracks.mean_s": (1.5, "assumption"),
    "extras.count": (2, "the paper had people without sensors in the area (count not given); assumption"),
    "extras.margin_m": (0.5, "assumption: bystanders stray a little beyond the sensing area"),
}
ROOM_SOURCES: dict[str, str] = {key: source for key, (_, source) in _ROOM_CHANGES.items()}


def _with(params: TrackerParams, changes: dict[str, Any]) -> TrackerParams:
    groups: dict[str, dict[str, Any]] = {}
    for key, value in changes.items():
        group, _, name = key.partition(".")
        groups.setdefault(group, {})[name] = value
    return dataclasses.replace(params, **{g: dataclasses.replace(getattr(params, g), **v) for g, v in groups.items()})


ROOM = _with(COURT, {key: value for key, (value, _) in _ROOM_CHANGES.items()})
PRESETS: dict[str, TrackerParams] = {"room": ROOM, "court": COURT}


def describe(params: TrackerParams = COURT, preset: str = "court") -> list[tuple[str, Any, str, str]]:
    """(dotted key, value, unit, source) of every figure; sources as for `preset` ("room" or "court")."""
    if preset not in PRESETS:
        raise ConfigError(f"preset {preset!r} is not one of {', '.join(PRESETS)}")

    def source(group: str, item: dataclasses.Field[Any]) -> str:
        key = f"{group}.{item.name}"
        return ROOM_SOURCES.get(key, item.metadata["source"]) if preset == "room" else item.metadata["source"]

    return rows(params, source)


def params_with_overrides(overrides: dict[str, str], base: TrackerParams = COURT) -> TrackerParams:
    """Apply `--set key=value` overrides to `base`; ConfigError names an unknown key, a bad or
    out-of-range value, or a [min, max] pair left reversed."""
    result = with_overrides(base, overrides)
    check(result)
    return result


def check(params: TrackerParams) -> None:
    """ConfigError when a [min, max] pair is reversed."""
    extras = params.extras
    if extras.speed_min_mps > extras.speed_max_mps:
        raise ConfigError(f"extras.speed_min_mps = {extras.speed_min_mps} exceeds extras.speed_max_mps = "
                          f"{extras.speed_max_mps}")

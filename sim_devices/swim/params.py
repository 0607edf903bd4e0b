"""Every swimming-simulator figure with its unit, accepted range, default and where it comes from.

`SwimParams` nests one frozen dataclass per concern; a figure's dotted key is `<group>.<field>`
(e.g. `crawl.hip_roll_max_deg`, `sensors.accel_bias_g`). Each field's metadata holds its unit,
range and a one-line source, so `--set` validation and the tables of docs/simulator-swim.md come
from the same data. The five stroke groups share one dataclass (`StrokeParams`); their sources
differ, so those live in `STROKE_SOURCES`. "assumption" marks a figure with no published source;
the reasoning and a plausible range follow it. Figures drawn per swimmer are [min, max] pairs
(uniform draw); the references are listed in docs/simulator-swim.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from protocol.errors import ConfigError
from sim_devices.param_table import check_pairs_and_batches, param, rows, with_overrides, zeroed

STROKES = ("crawl", "breaststroke", "backstroke", "butterfly", "kick")


_p = param


@dataclass(frozen=True)
class PoolParams:
    """The pool (x along the lanes, y across, z up; origin at a corner, water surface z = 0)."""

    length_m: float = _p(25.0, "m", 5.0, 100.0, "the paper's pool, 25 m x 18 m")
    width_m: float = _p(18.0, "m", 2.0, 60.0, "the paper's pool")
    lane_width_m: float = _p(2.25, "m", 1.0, 5.0, "8 lanes across 18 m; FINA lanes are 2.5 m, club pools 2-2.5 m")
    side_margin_m: float = _p(1.5, "m", 0.3, 5.0, "closest approach of a diagonal's body centre to a side wall: the "
                              "swimmer aims at the corner but touches the end wall an arm's length from the side; "
                              "assumption, 1-2 m")


@dataclass(frozen=True)
class WallParams:
    """What happens at the walls: push-off, glide, finish, open turn, rest (all strokes)."""

    push_s: float = _p(0.35, "s", 0.1, 1.0, "feet extend on the wall; push-offs last 0.25-0.4 s (assumption from "
                       "turn-analysis literature)")
    push_speed_min_mps: float = _p(1.9, "m/s", 0.5, 4.0, "body-centre speed as the feet leave the wall, per swimmer "
                                   "[min, max]; elite 2.5-3 m/s, club swimmers in an open turn less; assumption")
    push_speed_max_mps: float = _p(2.4, "m/s", 0.5, 4.0, "see push_speed_min_mps")
    glide_min_s: float = _p(1.5, "s", 0.2, 6.0, "push-off end to the first stroke, per length [min, max]; breakout "
                            "at 3-6 m; assumption (FINA's 15 m limit is far)")
    glide_max_s: float = _p(2.5, "s", 0.2, 6.0, "see glide_min_s")
    glide_decay_s: float = _p(0.9, "s", 0.1, 5.0, "time constant of the glide's speed decay to swimming speed; "
                              "assumption (streamlined drag halves a 2.2 m/s glide in about 1 s)")
    stroke_ramp_s: float = _p(1.0, "s", 0.1, 3.0, "strokes build up to full amplitude after the breakout; assumption")
    finish_s: float = _p(0.5, "s", 0.1, 2.0, "the last reach: body-centre speed falls to 0 at the touch (the hand "
                         "absorbs it); assumption")
    depth_m: float = _p(0.15, "m", 0.0, 1.0, "body centre below the surface while swimming; assumption")
    glide_depth_m: float = _p(0.45, "m", 0.0, 2.0, "extra depth at the push-off, gone by the breakout; assumption")
    turn_min_s: float = _p(1.2, "s", 0.3, 10.0, "open turn, touch to push-off start, per turn [min, max]; club "
                           "swimmers 1.2-2 s; assumption")
    turn_max_s: float = _p(2.0, "s", 0.3, 10.0, "see turn_min_s")
    kick_turn_extra_s: float = _p(0.8, "s", 0.0, 10.0, "a turn holding a kickboard takes longer; assumption")
    turn_pitch_deg: float = _p(50.0, "deg", 0.0, 85.0, "trunk pitch (head up) in the tuck of an open turn; "
                               "assumption, 30-70")
    push_roll_deg: float = _p(80.0, "deg", 0.0, 90.0, "prone strokes push off on the side and roll prone during "
                              "the glide; assumption, 45-90")
    rest_min_s: float = _p(3.0, "s", 0.5, 60.0, "floating still at the wall before the first push-off (issue: 3-5 s)")
    rest_max_s: float = _p(5.0, "s", 0.5, 60.0, "see rest_min_s")
    rest_after_s: float = _p(4.0, "s", 0.0, 60.0, "holding the wall after the last touch; assumption")
    posture_change_s: float = _p(1.2, "s", 0.2, 5.0, "upright at the wall <-> horizontal, before the first push and "
                                 "after the last touch; assumption")
    rest_pitch_deg: float = _p(70.0, "deg", 0.0, 85.0, "body pitch holding the wall (near upright); assumption")
    rest_sway_deg: float = _p(0.3, "deg", 0.0, 10.0, "slow attitude sway at rest (0.2-0.4 Hz); assumption: holding "
                              "the wall, nearly still")
    rest_bob_m: float = _p(0.005, "m", 0.0, 0.2, "slow vertical bob at rest; assumption")


@dataclass(frozen=True)
class PathParams:
    """The body centre's path over a length: lateral wander (snaking) and the diagonal's turn."""

    wander_min_m: float = _p(0.08, "m", 0.0, 2.0, "RMS lateral wander of the body centre per length, per swimmer "
                             "[min, max]: the slow band (0-0.4 Hz, 'voluntary adjustments') of Gatta et al. 2015; "
                             "lane ropes 2.5 m apart bound it to about +-0.6 m; assumption")
    wander_max_m: float = _p(0.25, "m", 0.0, 2.0, "see wander_min_m")
    wander_modes: int = _p(4, "1", 1, 12, "half-sine heading modes per length (wavelengths 2L/k, k = 1..4: "
                           "50-12.5 m, i.e. 0.05-0.2 Hz at 1.2 m/s, inside the slow band)")
    kick_wander_factor: float = _p(0.6, "1", 0.0, 2.0, "kickboard lengths wander less (head up, eyes on the wall); "
                                   "assumption")
    turn_arc_min_m: float = _p(1.5, "m", 0.1, 10.0, "path over which the diagonal's 35.75 deg turn is made, per "
                               "length [min, max]: one or two strokes; assumption")
    turn_arc_max_m: float = _p(3.0, "m", 0.1, 10.0, "see turn_arc_min_m")
    speed_spread: float = _p(0.03, "1", 0.0, 0.3, "SD of a length's mean speed around the swimmer's (pacing, "
                             "fatigue); assumption")
    rate_jitter: float = _p(0.03, "1", 0.0, 0.3, "SD of cycle-to-cycle stroke-rate variation; assumption")
    amplitude_jitter: float = _p(0.1, "1", 0.0, 0.5, "SD of cycle-to-cycle variation of every oscillation "
                                 "amplitude (roll, yaw, pitch, surge); assumption")
    sighting_probability: float = _p(0.5, "1", 0.0, 1.0, "chance that a straight length has a sighting (face lifted "
                                     "to look ahead, as the paper saw); a diagonal always sights at its turn")
    sighting_pitch_deg: float = _p(30.0, "deg", 0.0, 80.0, "head pitch added by a sighting; assumption, 20-40")
    sighting_s: float = _p(0.8, "s", 0.1, 3.0, "duration of a sighting; assumption")


@dataclass(frozen=True)
class StrokeParams:
    """One stroke's motion figures ([min, max] are drawn per swimmer; sources in STROKE_SOURCES).

    Angles are amplitudes (each side of the mean) unless named otherwise. Roll is about the body's
    long axis, pitch positive head up, yaw positive to the left.
    """

    speed_min_mps: float = _p(1.0, "m/s", 0.1, 3.0)
    speed_max_mps: float = _p(1.4, "m/s", 0.1, 3.0)
    cycle_rate_min_per_min: float = _p(36.0, "1/min", 5.0, 120.0)
    cycle_rate_max_per_min: float = _p(46.0, "1/min", 5.0, 120.0)
    strokes_per_cycle: int = _p(2, "1", 1, 8)  # counted per length: arm strokes; kicks (beats) for "kick"
    ivv_min: float = _p(0.08, "1", 0.0, 0.7)  # coefficient of variation of the forward speed in a cycle
    ivv_max: float = _p(0.15, "1", 0.0, 0.7)
    hip_roll_min_deg: float = _p(18.0, "deg", 0.0, 90.0)
    hip_roll_max_deg: float = _p(25.0, "deg", 0.0, 90.0)
    shoulder_roll_min_deg: float = _p(45.0, "deg", 0.0, 90.0)
    shoulder_roll_max_deg: float = _p(55.0, "deg", 0.0, 90.0)
    breath_roll_deg: float = _p(10.0, "deg", 0.0, 45.0)  # extra trunk roll on a breathing stroke
    breath_every_min: int = _p(2, "strokes", 0, 6)  # 0: no breathing motion
    breath_every_max: int = _p(3, "strokes", 0, 6)
    head_breath_roll_deg: float = _p(90.0, "deg", 0.0, 135.0)  # head roll (world) at a crawl breath
    head_follow: float = _p(0.3, "1", 0.0, 1.0)  # share of the shoulder roll the head follows between breaths
    head_lift_deg: float = _p(0.0, "deg", 0.0, 60.0)  # head pitch added by a forward breath (breaststroke, fly)
    head_pitch_min_deg: float = _p(0.0, "deg", -30.0, 60.0)  # head on trunk between breaths (neck extension)
    head_pitch_max_deg: float = _p(15.0, "deg", -30.0, 60.0)
    inclination_min_deg: float = _p(3.0, "deg", -20.0, 45.0)  # mean trunk pitch, head up
    inclination_max_deg: float = _p(10.0, "deg", -20.0, 45.0)
    pelvis_pitch_deg: float = _p(1.5, "deg", 0.0, 45.0)  # pitch oscillation of the pelvis, per stroke
    trunk_pitch_deg: float = _p(2.0, "deg", 0.0, 45.0)  # of the upper trunk
    hip_yaw_min_deg: float = _p(2.0, "deg", 0.0, 30.0)  # yaw oscillation per cycle, drawn per swimmer
    hip_yaw_max_deg: float = _p(5.0, "deg", 0.0, 30.0)
    shoulder_yaw_min_deg: float = _p(2.0, "deg", 0.0, 30.0)
    shoulder_yaw_max_deg: float = _p(5.0, "deg", 0.0, 30.0)
    head_yaw_deg: float = _p(3.0, "deg", 0.0, 30.0)
    heave_m: float = _p(0.03, "m", 0.0, 0.5)  # vertical oscillation of the body centre, per stroke
    kick_beats_per_cycle: int = _p(6, "1", 0, 12)  # leg beats per cycle; pelvis oscillates at half of it
    kick_roll_deg: float = _p(1.5, "deg", 0.0, 20.0)  # pelvis roll from the legs' beat
    board_pitch_min_deg: float = _p(0.0, "deg", -10.0, 45.0)  # kickboard only: the board's nose-up pitch
    board_pitch_max_deg: float = _p(0.0, "deg", -10.0, 45.0)
    board_yaw_deg: float = _p(0.0, "deg", 0.0, 20.0)  # kickboard only: yaw and roll oscillations per kick cycle
    board_roll_deg: float = _p(0.0, "deg", 0.0, 20.0)


_CRAWL = StrokeParams()
_BACK = dataclasses.replace(
    _CRAWL, speed_min_mps=0.9, speed_max_mps=1.2, cycle_rate_min_per_min=32.0, cycle_rate_max_per_min=42.0,
    ivv_min=0.10, ivv_max=0.15, hip_roll_min_deg=15.0, hip_roll_max_deg=22.0, shoulder_roll_min_deg=40.0,
    shoulder_roll_max_deg=50.0, breath_roll_deg=0.0, breath_every_min=0, breath_every_max=0,
    head_breath_roll_deg=0.0, head_follow=0.1, head_pitch_min_deg=5.0, head_pitch_max_deg=20.0,
    inclination_min_deg=5.0, inclination_max_deg=12.0)
_BREAST = dataclasses.replace(
    _CRAWL, speed_min_mps=0.8, speed_max_mps=1.1, cycle_rate_min_per_min=30.0, cycle_rate_max_per_min=40.0,
    strokes_per_cycle=1, ivv_min=0.30, ivv_max=0.45, hip_roll_min_deg=0.0, hip_roll_max_deg=2.0,
    shoulder_roll_min_deg=0.0, shoulder_roll_max_deg=3.0, breath_roll_deg=0.0, breath_every_min=1, breath_every_max=1,
    head_breath_roll_deg=0.0, head_follow=1.0, head_lift_deg=25.0, head_pitch_min_deg=0.0, head_pitch_max_deg=15.0,
    inclination_min_deg=5.0, inclination_max_deg=12.0, pelvis_pitch_deg=4.0, trunk_pitch_deg=12.0, hip_yaw_min_deg=0.5,
    hip_yaw_max_deg=1.5, shoulder_yaw_min_deg=0.5, shoulder_yaw_max_deg=1.5, head_yaw_deg=1.0, heave_m=0.06, kick_beats_per_cycle=0, kick_roll_deg=0.0)
_FLY = dataclasses.replace(
    _BREAST, speed_min_mps=1.0, speed_max_mps=1.3, cycle_rate_min_per_min=40.0, cycle_rate_max_per_min=50.0,
    ivv_min=0.20, ivv_max=0.30, breath_every_min=1, breath_every_max=2, head_lift_deg=20.0,
    inclination_min_deg=3.0, inclination_max_deg=10.0, pelvis_pitch_deg=8.0, trunk_pitch_deg=12.0, heave_m=0.08)
_KICK = dataclasses.replace(
    _CRAWL, speed_min_mps=0.6, speed_max_mps=0.9, cycle_rate_min_per_min=60.0, cycle_rate_max_per_min=84.0,
    ivv_min=0.04, ivv_max=0.08, hip_roll_min_deg=3.0, hip_roll_max_deg=6.0, shoulder_roll_min_deg=2.0,
    shoulder_roll_max_deg=4.0, breath_roll_deg=0.0, breath_every_min=0, breath_every_max=0, head_breath_roll_deg=0.0,
    head_follow=1.0, head_pitch_min_deg=30.0, head_pitch_max_deg=45.0, inclination_min_deg=8.0,
    inclination_max_deg=15.0, pelvis_pitch_deg=2.0, trunk_pitch_deg=1.0, hip_yaw_min_deg=0.5, hip_yaw_max_deg=1.5,
    shoulder_yaw_min_deg=0.5, shoulder_yaw_max_deg=1.5, head_yaw_deg=1.0, heave_m=0.01, kick_beats_per_cycle=2, kick_roll_deg=0.0, board_pitch_min_deg=5.0,
    board_pitch_max_deg=15.0, board_yaw_deg=1.5, board_roll_deg=1.5)

# Where each stroke's figures come from (one line per field that differs in kind; "ivv" covers its pair).
_IVV = "CV of the forward speed within a cycle; "
STROKE_SOURCES: dict[str, dict[str, str]] = {
    "crawl": {
        "speed": "assumption: university swim-club members (the paper's subjects) at a moderate pace, 25 m in "
                 "about 18-25 s with the push-off",
        "cycle_rate": "moderate-pace front crawl 36-46 cycles/min (72-92 arm strokes); national-level swimmers "
                      "reach 0.95 Hz (57/min) at sprint (Andersen et al. 2020)",
        "ivv": _IVV + "front crawl about 0.1 (Figueiredo et al. 2012; Psycharakis et al. 2010), recreational "
                      "swimmers higher (Pinto et al. 2024); two surges per cycle, one per arm",
        "hip_roll": "hip roll range 36.8 deg (sprint) to 49.9 deg (400 m pace), i.e. +-18-25 deg (Andersen et "
                    "al. 2020); the shoulders roll more than the hips (Psycharakis & Sanders 2008)",
        "shoulder_roll": "shoulder roll range 97.7-101.6 deg, i.e. about +-50 deg (Andersen et al. 2020)",
        "breath_roll": "breathing adds about 7-12 deg of roll (Lopez-Contreras et al. 2022)",
        "breath_every": "breathing every 2 strokes (one side) or 3 (alternating); drawn per swimmer",
        "head_breath_roll": "assumption: the face turns to the side until the mouth clears the surface, about "
                            "90 deg in the world; the trunk gives 55-65 deg of it, the neck the rest",
        "head_follow": "assumption: between breaths the head stays still in good technique (the trunk rolls "
                       "under it); club swimmers let it follow the shoulders partly, 0-50 %",
        "head_pitch": "assumption: neck extension between breaths, eyes forward-down, 0-15 deg",
        "inclination": "assumption: trunk pitch head-up 3-10 deg (the legs sink: centre of mass caudal to the "
                       "centre of buoyancy; a kick lifts them; less at speed)",
        "pitch": "assumption: small pitch oscillation per arm stroke, 1-3 deg",
        "yaw": "assumption: yaw sway of hips and shoulders per cycle, 2-5 deg drawn per swimmer, head 3 deg "
               "(Gatta et al. 2015 see the head's lateral motion at 0.7-5 Hz; no angle published that we found)",
        "heave": "assumption: body-centre vertical oscillation 2-4 cm per arm stroke (vertical IVV of the centre "
                 "of mass, Figueiredo et al. 2012)",
        "kick": "six-beat kick: 6 leg beats per arm cycle; pelvis roll from the kick 1-2 deg, assumption",
    },
    "backstroke": {
        "speed": "assumption: 0.9-1.2 m/s, a little slower than the same swimmers' crawl",
        "cycle_rate": "assumption: 32-42 cycles/min",
        "ivv": _IVV + "backstroke 0.10-0.15 (Fernandes et al. 2022; two surges per cycle)",
        "hip_roll": "backstroke body roll of the same order as front crawl (Gonjo et al. 2021); assumption "
                    "+-15-22 deg hips, +-40-50 deg shoulders",
        "head": "no breathing motion: the head stays still looking up, following 10 % of the shoulder roll",
        "inclination": "assumption: supine trunk pitch head-up 5-12 deg (hips sit low)",
    },
    "breaststroke": {
        "speed": "assumption: 0.8-1.1 m/s",
        "cycle_rate": "assumption: 30-40 cycles/min (one arm stroke per cycle)",
        "ivv": _IVV + "breaststroke the largest of the strokes, 0.3-0.45 (Takagi et al. 2004; Leblanc et al. "
                      "2007); one big surge per cycle from the kick",
        "roll": "symmetric stroke: roll within +-3 deg, yaw sway 0.5-1.5 deg, assumption",
        "head_lift": "assumption: the head rises to breathe every cycle, 25 deg on the trunk",
        "pitch": "assumption: the upper trunk rises 12 deg at the insweep, the pelvis 4 deg",
        "heave": "assumption: body-centre vertical oscillation 6 cm per cycle",
    },
    "butterfly": {
        "speed": "assumption: 1.0-1.3 m/s",
        "cycle_rate": "assumption: 40-50 cycles/min (one arm stroke per cycle)",
        "ivv": _IVV + "butterfly 0.2-0.3 (Barbosa et al. 2005, 2008); two surges per cycle (kick, arm pull)",
        "head_lift": "assumption: the head lifts 20 deg to breathe every 1 or 2 cycles",
        "pitch": "assumption: body undulation, trunk 12 deg and pelvis 8 deg of pitch per cycle",
        "heave": "assumption: body-centre vertical oscillation 8 cm per cycle",
    },
    "kick": {
        "speed": "assumption: flutter kick with a kickboard, 0.6-0.9 m/s",
        "cycle_rate": "assumption: 60-84 kick cycles/min (2-2.8 beats per second); counted per beat",
        "ivv": _IVV + "assumption 0.04-0.08: legs alone give a steadier push than arm strokes",
        "roll": "assumption: pelvis roll +-3-6 deg per kick cycle; board held level",
        "head_pitch": "assumption: head up looking ahead over the board, 30-45 deg",
        "inclination": "assumption: trunk pitch 8-15 deg (chest on the arms, legs kicking below)",
        "board": "assumption: the board's nose rides up 5-15 deg; yaw and roll +-1.5 deg per kick cycle",
    },
}


@dataclass(frozen=True)
class MountParams:
    """One sensor placement: lever arm from the body centre (body frame) and how the sensor sits.

    `tilt_*`: pitch of the sensor's x axis relative to the segment's long axis (positive nose up),
    drawn per swimmer; `misalignment_deg`: SD per axis of a random rotation drawn per set (strap).
    """

    lever_forward_m: float = _p(0.05, "m", -1.0, 2.0)
    lever_up_m: float = _p(0.12, "m", -0.5, 0.5)
    tilt_min_deg: float = _p(-5.0, "deg", -60.0, 60.0)
    tilt_max_deg: float = _p(5.0, "deg", -60.0, 60.0)
    misalignment_deg: float = _p(2.0, "deg", 0.0, 20.0)


MOUNT_SOURCES: dict[str, str] = {
    "waist": "the paper's board in a phone pouch belted to the lower back: at the body centre's level, 0.12 m "
             "above it (half the trunk depth); the flat board bridges the lumbar curve, tilt -5..+5 deg; "
             "misalignment SD 2 deg (belt): assumptions",
    "back": "between the shoulder blades in a vest pocket (the paper: a CATAPULT PLAYR vest): 0.40 m towards the "
            "head, 0.13 m up; the upper thoracic curve (kyphosis) tilts the surface nose-down 0-10 deg; SD 2 deg: "
            "assumptions",
    "head": "back of the head under the goggle strap: 0.68 m towards the head, 0.09 m up; the occiput's "
            "curvature below the crown tilts the sensor nose-up 10-30 deg; SD 3 deg (strap and cap): assumptions",
    "kickboard": "on the board's top surface, held at arm's length: 1.15 m ahead of the body centre (0.35 m when "
                 "held close in a turn), 0.10 m up; flat on the board (tilt 0), SD 1 deg: assumptions",
}


@dataclass(frozen=True)
class SensorParams:
    """The IMU (ATR-Promotions TSND121: accelerometer + gyroscope at 1000 Hz); MEMS-class error figures.

    The TSND121 publishes no noise or bias figures: these are the InvenSense MPU-9250 datasheet's
    (PS-MPU-9250A-01), the class of part such loggers carry, as in the wheelchair simulator.
    """

    rate_hz: float = _p(1000.0, "Hz", 10.0, 2000.0, "the paper's sampling rate (TSND121, 1000 Hz)")
    batch_samples: int = _p(50, "samples", 1, 1000, "50 ms per ImuBatch (issue)")
    accel_range_g: float = _p(8.0, "g", 2.0, 16.0, "TSND121 settings +-2/4/8/16 g; +-8 g keeps push-off and "
                              "wall contact spikes unclipped")
    gyro_range_dps: float = _p(1000.0, "deg/s", 250.0, 2000.0, "TSND121 settings +-250/500/1000/2000 deg/s; head "
                               "rotations to breathe stay under about 600 deg/s")
    adc_bits: int = _p(16, "bits", 8, 24, "16-bit converter over the range (MPU-9250 class)")
    accel_unit_g: float = _p(1e-4, "g", 1e-6, 1e-2, "TSND121 reports acceleration in 0.1 mg (field-notes.md)")
    gyro_unit_dps: float = _p(0.01, "deg/s", 1e-4, 1.0, "TSND121 reports angular rate in 0.01 deg/s (field-notes.md)")
    accel_noise_g_per_sqrt_hz: float = _p(300e-6, "g/sqrt(Hz)", 0.0, 0.01, "MPU-9250 300 ug/sqrt(Hz)")
    gyro_noise_dps_per_sqrt_hz: float = _p(0.01, "deg/s/sqrt(Hz)", 0.0, 1.0, "MPU-9250 0.01 deg/s/sqrt(Hz)")
    accel_bias_g: float = _p(0.02, "g", 0.0, 0.5, "SD per axis of the turn-on bias: MPU-9250 zero-g tolerance "
                             "+-60 mg (x, y) taken as 3 SD")
    accel_bias_walk_g_per_sqrt_s: float = _p(2e-5, "g/sqrt(s)", 0.0, 0.01, "in-run bias random walk (0.3 mg over "
                                             "3 min); assumption, MEMS bias instability 0.05-0.5 mg")
    gyro_bias_dps: float = _p(0.5, "deg/s", 0.0, 20.0, "SD per axis of the turn-on bias: MPU-9250 +-5 deg/s "
                              "untrimmed; assumption 0.5 after the logger's trim (0.1-5)")
    gyro_bias_walk_dps_per_sqrt_s: float = _p(0.002, "deg/s/sqrt(s)", 0.0, 1.0, "in-run bias random walk; "
                                              "assumption, MEMS in-run instability 5-20 deg/h")
    accel_scale_error: float = _p(0.01, "1", 0.0, 0.2, "SD per axis; MPU-9250 sensitivity tolerance +-3 %")
    gyro_scale_error: float = _p(0.01, "1", 0.0, 0.2, "SD per axis; MPU-9250 sensitivity tolerance +-3 %")
    cross_axis: float = _p(0.007, "1", 0.0, 0.1, "SD of each off-diagonal sensitivity; MPU-9250 cross-axis "
                           "+-2 % taken as 3 SD")


@dataclass(frozen=True)
class LinkParams:
    """Delivery of ImuBatch messages (log time) and the device clock."""

    latency_ms: float = _p(30.0, "ms", 0.0, 5000.0, "fixed part of log_time - last sample: Bluetooth Classic SPP "
                           "(TSND121) polls every 10-30 ms + host; assumption")
    latency_jitter_ms: float = _p(15.0, "ms", 0.0, 5000.0, "mean of the exponential extra latency; assumption")
    start_unix_s: int = _p(1_704_067_200, "s", 0, 4_000_000_000, "true time of the session start "
                           "(2024-01-01T00:00Z); fixed, no wall clock")


@dataclass(frozen=True)
class SwimParams:
    """All swimming-simulator figures; the dotted key of a field is `<group>.<field>`."""

    pool: PoolParams = field(default_factory=PoolParams)
    walls: WallParams = field(default_factory=WallParams)
    path: PathParams = field(default_factory=PathParams)
    crawl: StrokeParams = field(default_factory=lambda: _CRAWL)
    breaststroke: StrokeParams = field(default_factory=lambda: _BREAST)
    backstroke: StrokeParams = field(default_factory=lambda: _BACK)
    butterfly: StrokeParams = field(default_factory=lambda: _FLY)
    kick: StrokeParams = field(default_factory=lambda: _KICK)
    waist: MountParams = field(default_factory=MountParams)
    back: MountParams = field(default_factory=lambda: MountParams(0.40, 0.13, -10.0, 0.0, 2.0))
    head: MountParams = field(default_factory=lambda: MountParams(0.68, 0.09, 10.0, 30.0, 3.0))
    kickboard: MountParams = field(default_factory=lambda: MountParams(1.15, 0.10, 0.0, 0.0, 1.0))
    sensors: SensorParams = field(default_factory=SensorParams)
    link: LinkParams = field(default_factory=LinkParams)

    def stroke(self, name: str) -> StrokeParams:
        """The figures of stroke `name` (one of STROKES); ConfigError otherwise."""
        if name not in STROKES:
            raise ConfigError(f"stroke {name!r} is not one of {', '.join(STROKES)}")
        return getattr(self, name)


# Sensor error fields an `error_free` run zeroes (motion, mounting tilt and lever arms stay: they are
# what happened, not measurement errors; the mounting misalignment goes).
_ERROR_FIELDS: dict[str, tuple[str, ...]] = {
    "sensors": ("accel_noise_g_per_sqrt_hz", "gyro_noise_dps_per_sqrt_hz", "accel_bias_g",
                "accel_bias_walk_g_per_sqrt_s", "gyro_bias_dps", "gyro_bias_walk_dps_per_sqrt_s",
                "accel_scale_error", "gyro_scale_error", "cross_axis"),
    "link": ("latency_jitter_ms",),
    **{mount: ("misalignment_deg",) for mount in ("waist", "back", "head", "kickboard")},
}


def error_free(params: SwimParams | None = None) -> SwimParams:
    """`params` (default SwimParams()) with every sensor error, misalignment and latency jitter zero.

    Quantisation and range stay (they are the device's format).
    """
    return zeroed(params or SwimParams(), _ERROR_FIELDS)


def _source(group: str, item: dataclasses.Field[Any]) -> str:
    if group in STROKE_SOURCES:
        return "STROKE_SOURCES[{!r}]".format(group)
    return MOUNT_SOURCES.get(group, item.metadata["source"])


def describe(params: SwimParams | None = None) -> list[tuple[str, Any, str, str]]:
    """(dotted key, value, unit, source) of every figure, in declaration order."""
    return rows(params or SwimParams(), _source)


def params_with_overrides(overrides: dict[str, str], base: SwimParams | None = None) -> SwimParams:
    """Apply `--set key=value` overrides (dotted keys, string values) to `base` (default SwimParams()).

    ConfigError names the key when it is unknown, not a number of the right type, outside its
    range, or leaves a [min, max] pair reversed.
    """
    result = with_overrides(base or SwimParams(), overrides)
    check(result)
    return result


def check(params: SwimParams) -> None:
    """ConfigError when a [min, max] pair is reversed or a batch would span more than 4 s."""
    check_pairs_and_batches(params)

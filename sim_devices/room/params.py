"""Every room-simulator figure with its unit, accepted range, default and where it comes from.

`RoomParams` nests one frozen dataclass per concern; a figure's dotted key is `<group>.<field>`
(e.g. `gait.pendulum_correction`, `sensors.accel_bias_g`). Each field's metadata holds its unit,
range and a one-line source, so `--set` validation and the tables of docs/simulator-room.md come
from the same data. "assumption" marks a figure with no published source; the reasoning and a
plausible range follow it. Figures drawn per person are [min, max] pairs (uniform) or a mean with
an SD; the references are listed in docs/simulator-room.md.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from protocol.errors import ConfigError
from sim_devices.param_table import check_pairs_and_batches, param, rows, with_overrides, zeroed

_p = param


@dataclass(frozen=True)
class RoomGeometry:
    """The sensing area (x along its length, y across, z up; origin at a corner) and its chairs."""

    length_m: float = _p(5.6, "m", 2.0, 100.0, "the paper's sensing area, 3 m x 5.6 m (sec. 4.2, Fig. 7)")
    width_m: float = _p(3.0, "m", 1.5, 100.0, "the paper's sensing area")
    reference_people: int = _p(3, "people", 1, 99, "the paper's 3 subjects with sensors; more people enlarge the "
                               "room to keep its area per wearer (room_size)")
    wall_margin_m: float = _p(0.35, "m", 0.1, 2.0, "closest approach of the pelvis centre to a wall: half a "
                              "body depth (~0.15 m) plus clearance; assumption, 0.25-0.5 m")
    chairs: int = _p(2, "chairs", 0, 50, "the paper: two chairs in the area (sec. 4.2); scaled with the area")
    seat_height_m: float = _p(0.45, "m", 0.3, 0.7, "standard office/classroom chair seat 0.42-0.46 m; assumption")


@dataclass(frozen=True)
class PeopleParams:
    """Body size and walking speeds, drawn per person."""

    female_share: float = _p(0.5, "1", 0.0, 1.0, "share of women among the wearers; assumption")
    male_height_m: float = _p(1.71, "m", 1.0, 2.2, "Japanese men aged 20-29, mean stature about 1.71 m (MHLW "
                              "National Health and Nutrition Survey)")
    female_height_m: float = _p(1.58, "m", 1.0, 2.2, "Japanese women aged 20-29, about 1.58 m (same survey)")
    height_sd_m: float = _p(0.055, "m", 0.0, 0.2, "SD of stature within sex, about 6 cm (same survey)")
    leg_length_ratio: float = _p(0.53, "1", 0.4, 0.6, "greater-trochanter height / stature 0.530 (Winter, "
                                 "Biomechanics and Motor Control of Human Movement, anthropometric table)")
    sensor_height_ratio: float = _p(0.58, "1", 0.4, 0.7, "waist-belt sensor (iliac crest level) height / stature; "
                                    "assumption, 0.55-0.62")
    forward_speed_min_mps: float = _p(0.6, "m/s", 0.1, 2.5, "cruise speed of a forward walk in the room, drawn per "
                                      "walk in [min, max] x the person's speed factor. Comfortable gait is "
                                      "1.2-1.4 m/s (Bohannon & Andrews 2011) on a long walkway; walks of 1-5 m "
                                      "spend most of their length starting and stopping (steady speed after 2-3 "
                                      "steps) and the subjects roam freely (paper sec. 4.2): assumption 0.6-1.1")
    forward_speed_max_mps: float = _p(1.1, "m/s", 0.1, 2.5, "see forward_speed_min_mps")
    backward_speed_min_mps: float = _p(0.4, "m/s", 0.1, 2.0, "backward walks are slower, same cadence with shorter "
                                       "strides (Laufer 2005, J Gerontol 60A:627); assumption 0.4-0.8")
    backward_speed_max_mps: float = _p(0.8, "m/s", 0.1, 2.0, "see backward_speed_min_mps")
    sideways_speed_min_mps: float = _p(0.3, "m/s", 0.1, 2.0, "side-stepping; assumption 0.3-0.7")
    sideways_speed_max_mps: float = _p(0.7, "m/s", 0.1, 2.0, "see sideways_speed_min_mps")
    speed_factor_sd: float = _p(0.12, "1", 0.0, 0.5, "SD of a person's speed factor (some people walk faster); "
                                "assumption from the 0.8-2.0 m/s spread of free walking (1987 video survey of Japanese "
                                "adults on a Fukuoka sidewalk: 49-119 m/min)")
    accel_mps2: float = _p(1.0, "m/s^2", 0.1, 5.0, "speeding up and slowing down; steady speed within ~1 s of "
                           "gait initiation; assumption 0.7-1.5")
    yaw_rate_max_dps: float = _p(150.0, "deg/s", 10.0, 720.0, "peak body yaw rate in turns; a 180 deg turn on the "
                                 "spot takes 1.5-2.5 s; assumption")
    yaw_gain_per_s: float = _p(3.0, "1/s", 0.1, 50.0, "heading approaches its target with this rate before the "
                               "limit (smooth turns); assumption")


@dataclass(frozen=True)
class ActivityParams:
    """What the people do (the paper's protocol: walk forwards, backwards, sideways, stand, sit; freely)."""

    walk_forward_weight: float = _p(0.34, "1", 0.0, 1.0, "relative chance of each next activity; the paper's "
                                    "subjects walk forwards, backwards and sideways, stand still and sit (sec. "
                                    "3.1, 4.2); assumption")
    walk_backward_weight: float = _p(0.13, "1", 0.0, 1.0, "see walk_forward_weight")
    walk_sideways_weight: float = _p(0.13, "1", 0.0, 1.0, "see walk_forward_weight")
    stand_weight: float = _p(0.18, "1", 0.0, 1.0, "see walk_forward_weight")
    turn_weight: float = _p(0.10, "1", 0.0, 1.0, "turn on the spot; see walk_forward_weight")
    sit_weight: float = _p(0.12, "1", 0.0, 1.0, "walk to a free chair, sit, stand up; see walk_forward_weight")
    walk_min_m: float = _p(1.0, "m", 0.2, 20.0, "forward walk length [min, max] (limited by the room); assumption")
    walk_max_m: float = _p(5.0, "m", 0.2, 50.0, "see walk_min_m")
    step_walk_min_m: float = _p(0.5, "m", 0.1, 10.0, "backward or sideways walk length [min, max]; assumption")
    step_walk_max_m: float = _p(2.0, "m", 0.1, 10.0, "see step_walk_min_m")
    stand_min_s: float = _p(1.0, "s", 0.1, 120.0, "standing still [min, max]; assumption")
    stand_max_s: float = _p(6.0, "s", 0.1, 300.0, "see stand_min_s")
    turn_min_deg: float = _p(45.0, "deg", 5.0, 360.0, "turn on the spot [min, max], either way; assumption")
    turn_max_deg: float = _p(180.0, "deg", 5.0, 360.0, "see turn_min_deg")
    sit_min_s: float = _p(5.0, "s", 0.5, 600.0, "seated [min, max]; the paper's subject A sat (Fig. 8); assumption")
    sit_max_s: float = _p(20.0, "s", 0.5, 600.0, "see sit_min_s")
    transition_min_s: float = _p(1.5, "s", 0.5, 10.0, "sit-down or stand-up duration [min, max]; healthy adults "
                                 "rise in about 1.5-2.5 s; assumption")
    transition_max_s: float = _p(2.5, "s", 0.5, 10.0, "see transition_min_s")
    give_up_s: float = _p(8.0, "s", 1.0, 120.0, "a walk blocked by others this long is abandoned; assumption")


@dataclass(frozen=True)
class GaitParams:
    """The waist's motion within steps: inverted-pendulum bounce, sway, pelvis rotation, heel strikes."""

    walk_ratio_m_per_spm: float = _p(0.0062, "m/(steps/min)", 0.003, 0.01,
                                     "step length / cadence (the walk ratio of Sekiya & Nagasaki), about 0.006 in "
                                     "healthy adults and constant over ordinary speeds; the constancy breaks below "
                                     "~62 m/min (J Phys Ther Sci 2017, PMC5430280)")
    walk_ratio_sd: float = _p(0.0005, "m/(steps/min)", 0.0, 0.003, "SD between people; assumption (~8 %)")
    backward_step_ratio: float = _p(0.75, "1", 0.2, 1.5, "step length backwards / forwards at one cadence "
                                    "(Laufer 2005: shorter strides, same cadence); assumption 0.6-0.9")
    sideways_step_ratio: float = _p(0.55, "1", 0.2, 1.5, "side step / forward step length at one cadence; "
                                    "assumption 0.4-0.7")
    min_step_frequency_hz: float = _p(1.2, "Hz", 0.5, 3.0, "cadence floor for short, slow walks (72 steps/min); "
                                      "assumption")
    max_step_frequency_hz: float = _p(2.4, "Hz", 1.0, 4.0, "cadence ceiling (144 steps/min); Japanese pedestrians "
                                      "95-160 steps/min (the same Fukuoka survey)")
    pendulum_correction: float = _p(1.25, "1", 1.0, 2.0, "step length = 2 K sqrt(2 l h - h^2), K = 1.25 "
                                    "(Zijlstra & Hof 2003, Gait Posture 18:1); sets the bounce h from the step")
    bounce_person_sd: float = _p(0.2, "1", 0.0, 1.0, "log-SD of a person's bounce amplitude around the pendulum "
                                 "figure; trunk RMS acceleration varies ~20 % between healthy adults at one speed "
                                 "(assumption from Kavanagh 2009, Menz et al. 2003)")
    step_time_cv: float = _p(0.025, "1", 0.0, 0.2, "step-to-step CV of step time, 2-3 % in healthy adults "
                             "(Hausdorff 2005)")
    step_amplitude_cv: float = _p(0.1, "1", 0.0, 0.5, "step-to-step CV of the bounce; assumption")
    second_harmonic: float = _p(0.3, "1", 0.0, 1.0, "2nd-harmonic share of the vertical bounce acceleration "
                                "(double-peaked loading); assumption 0.2-0.4")
    heel_strike_g_per_mps: float = _p(0.12, "g per m/s", 0.0, 2.0, "peak of the heel-strike transient at the waist "
                                      "per m/s of walking speed; assumption (0.1-0.2 g at 1.3 m/s)")
    heel_strike_ms: float = _p(25.0, "ms", 5.0, 100.0, "SD width of that transient; assumption")
    energy_recovery: float = _p(0.65, "1", 0.0, 1.0, "share of the bounce's potential energy exchanged with "
                                "forward kinetic energy (Cavagna et al. 1977: up to ~65 %); sets the "
                                "within-step forward speed swing")
    lateral_sway_m: float = _p(0.02, "m", 0.0, 0.1, "half-amplitude of side-to-side pelvis sway at stride "
                               "frequency; CoM lateral excursion 3-5 cm peak to peak; assumption")
    pelvic_rotation_deg: float = _p(4.0, "deg", 0.0, 20.0, "pelvic yaw, +-4 deg at ~1.3 m/s (Saunders, Inman & "
                                    "Eberhart 1953), scaled with speed")
    pelvic_list_deg: float = _p(4.0, "deg", 0.0, 20.0, "pelvic obliquity (list, roll), about 5 deg (Saunders et al. "
                                "1953), scaled with speed like the rotation")
    pelvic_tilt_deg: float = _p(2.0, "deg", 0.0, 20.0, "pelvic pitch at step frequency, +-2 deg; assumption")
    turn_step_lever_m: float = _p(0.2, "m", 0.0, 1.0, "turning on the spot steps like walking at yaw rate x this "
                                  "speed; assumption")
    sit_pitch_deg: float = _p(25.0, "deg", 0.0, 60.0, "peak forward pelvis/trunk pitch while sitting down or "
                              "rising; assumption, trunk flexion 30-45 deg")
    seated_pitch_deg: float = _p(-10.0, "deg", -40.0, 20.0, "pelvis pitch while seated (posterior tilt); assumption")
    seated_sensor_above_seat_m: float = _p(0.15, "m", 0.0, 0.4, "waist sensor height above the seat when seated; "
                                           "assumption")
    sit_back_m: float = _p(0.3, "m", 0.0, 1.0, "pelvis travel back from standing in front of the chair to the "
                           "seat; assumption")
    trunk_lean_share: float = _p(0.8, "1", 0.0, 1.0, "head top forward of the pelvis = this x (stature - sensor "
                                 "height) x sin(pitch) (the camera sees the head); assumption")


@dataclass(frozen=True)
class CrowdParams:
    """People avoiding each other (they still pass close: that makes identification hard)."""

    body_radius_m: float = _p(0.2, "m", 0.05, 0.5, "two pelvis centres never closer than twice this; shoulder "
                              "width ~0.4 m; assumption")
    avoid_range_m: float = _p(0.9, "m", 0.1, 5.0, "others closer than this bend a walker's path; assumption "
                              "(personal space of acquaintances 0.45-1.2 m, Hall 1966)")
    avoid_gain_mps: float = _p(0.5, "m/s", 0.0, 5.0, "sideways avoidance speed at contact distance; assumption")


@dataclass(frozen=True)
class SensorParams:
    """The waist IMU: ICM-20948-class consumer MEMS (accelerometer and gyroscope; no magnetometer)."""

    rate_hz: float = _p(100.0, "Hz", 10.0, 1000.0, "waist sensor sampling; assumption, 50-200 Hz typical")
    batch_samples: int = _p(10, "samples", 1, 1000, "0.1 s per ImuBatch, as the other simulators")
    accel_range_g: float = _p(8.0, "g", 2.0, 16.0, "ICM-20948 ranges +-2/4/8/16 g (datasheet DS-000189)")
    gyro_range_dps: float = _p(1000.0, "deg/s", 250.0, 2000.0, "ICM-20948 ranges +-250..2000 deg/s")
    adc_bits: int = _p(16, "bits", 8, 32, "ICM-20948 16-bit outputs")
    accel_noise_g_per_sqrt_hz: float = _p(0.00023, "g/sqrt(Hz)", 0.0, 0.01, "ICM-20948 230 ug/sqrt(Hz) "
                                          "(BMI160 180)")
    accel_bias_g: float = _p(0.015, "g", 0.0, 0.5, "SD per axis; ICM-20948 zero-g tolerance +-25 mg component, "
                             "+-50 mg board level")
    accel_scale_error: float = _p(0.005, "1", 0.0, 0.1, "SD per axis; ICM-20948 sensitivity tolerance +-0.5 %")
    gyro_noise_dps_per_sqrt_hz: float = _p(0.015, "deg/s/sqrt(Hz)", 0.0, 1.0, "ICM-20948 0.015 (BMI160 0.007)")
    gyro_bias_dps: float = _p(0.5, "deg/s", 0.0, 20.0, "SD per axis of the turn-on bias after factory trim; "
                              "untrimmed ZRO +-5 deg/s (ICM-20948); assumption 0.5")
    gyro_bias_walk_dps_per_sqrt_s: float = _p(0.002, "deg/s/sqrt(s)", 0.0, 1.0, "bias random walk; assumption, "
                                              "MEMS in-run instability 5-20 deg/h")
    gyro_scale_error: float = _p(0.01, "1", 0.0, 0.1, "SD per axis; ICM-20948 sensitivity tolerance +-1.5 %")
    misalignment_deg: float = _p(3.0, "deg", 0.0, 30.0, "SD per axis of the belt clip's misalignment on the body; "
                                 "assumption 1-5 deg")
    belt_pitch_deg: float = _p(8.0, "deg", 0.0, 45.0, "pitch of the belt sensor on the lumbar curve, drawn in "
                               "[-this, +this]; assumption")


@dataclass(frozen=True)
class LinkParams:
    """Device clocks and the wireless link to the logger."""

    start_unix_s: int = _p(1_704_067_200, "s", 0, 4_000_000_000,
                           "true time of the session start (2024-01-01T00:00Z); fixed, no wall clock")
    clock_offset_ms: float = _p(20.0, "ms", 0.0, 10_000.0, "SD of each sensor clock's offset after sync (BLE "
                                "connection-event sync: tens of ms); assumption")
    clock_drift_ppm: float = _p(20.0, "ppm", 0.0, 1000.0, "SD of each sensor clock's rate error; crystals "
                                "+-20-50 ppm")
    latency_ms: float = _p(20.0, "ms", 0.0, 5000.0, "fixed part of log time - last sample time (BLE interval "
                           "7.5-30 ms + host); assumption")
    latency_jitter_ms: float = _p(10.0, "ms", 0.0, 5000.0, "mean of the exponential extra latency; assumption")
    batch_loss_rate: float = _p(0.005, "1", 0.0, 0.9, "share of ImuBatch packets lost (independent); assumption "
                                "0.1-5 %")


@dataclass(frozen=True)
class ExtraParams:
    """People in the room without sensors (the paper had untracked people present, sec. 4.2)."""

    extra_per_wearer: float = _p(0.67, "1", 0.0, 5.0, "extra people = round(this x wearers): 2 with the paper's "
                                 "3 (the paper gives no count; two keep the room as crowded as a second group "
                                 "walking through); assumption")


@dataclass(frozen=True)
class AwayParams:
    """Wearers who leave the sensing area once and come back (the paper's subjects B and C, Table 2)."""

    leaver_share: float = _p(0.67, "1", 0.0, 1.0, "wearers who leave the sensing area once = round(this x wearers): "
                             "2 of the paper's 3 (B and C left it once, A never; Table 2, sec. 5.1)")
    min_share: float = _p(0.195, "1", 0.0, 0.9, "shortest absence, as a share of the session: B was outside 58 s "
                          "of 297 s (Table 2); the leavers' absences are spread evenly from min_share to "
                          "max_share (one leaver: their mean)")
    max_share: float = _p(0.606, "1", 0.0, 0.9, "longest absence: C was outside 180 s of 297 s (Table 2)")
    beyond_m: float = _p(1.0, "m", 0.3, 10.0, "how far outside the sensing area's edge a leaver waits (out of "
                         "the cameras' view; the paper's area lies inside a larger room); assumption")


@dataclass(frozen=True)
class RoomParams:
    """All room-simulator figures; the dotted key of a field is `<group>.<field>`."""

    room: RoomGeometry = field(default_factory=RoomGeometry)
    people: PeopleParams = field(default_factory=PeopleParams)
    activity: ActivityParams = field(default_factory=ActivityParams)
    gait: GaitParams = field(default_factory=GaitParams)
    crowd: CrowdParams = field(default_factory=CrowdParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    link: LinkParams = field(default_factory=LinkParams)
    extra: ExtraParams = field(default_factory=ExtraParams)
    away: AwayParams = field(default_factory=AwayParams)


def room_size(people: int, room: RoomGeometry) -> tuple[float, float]:
    """(length, width) in m of the room for `people` wearers: the paper's room up to
    `reference_people`, then both sides scaled by sqrt(people / reference_people), which keeps the
    paper's area per wearer (16.8 m^2 / 3 = 5.6 m^2) and its 5.6:3 shape."""
    scale = math.sqrt(max(people, room.reference_people) / room.reference_people)
    return room.length_m * scale, room.width_m * scale


def chair_count(people: int, room: RoomGeometry) -> int:
    """Chairs in the room: the paper's two, scaled with the room's area."""
    return int(round(room.chairs * max(people, room.reference_people) / room.reference_people))


def away_shares(people: int, away: AwayParams) -> list[float]:
    """Absence of each wearer who leaves, as a share of the session (round(leaver_share x people) of
    them), spread evenly from min_share to max_share: 58/297 and 180/297 for the paper's 3 wearers."""
    count = min(people, int(round(away.leaver_share * people)))
    if count == 0:
        return []
    if count == 1:
        return [0.5 * (away.min_share + away.max_share)]
    step = (away.max_share - away.min_share) / (count - 1)
    return [away.min_share + k * step for k in range(count)]


def extra_count(people: int, extra: ExtraParams) -> int:
    """People without sensors: round(extra_per_wearer x wearers) (2 with the paper's 3)."""
    return int(round(extra.extra_per_wearer * people))


_ERROR_FIELDS: dict[str, tuple[str, ...]] = {
    "sensors": ("accel_noise_g_per_sqrt_hz", "accel_bias_g", "accel_scale_error", "gyro_noise_dps_per_sqrt_hz",
                "gyro_bias_dps", "gyro_bias_walk_dps_per_sqrt_s", "gyro_scale_error", "misalignment_deg"),
    "link": ("clock_offset_ms", "clock_drift_ppm", "latency_jitter_ms", "batch_loss_rate"),
}


def error_free(params: RoomParams | None = None) -> RoomParams:
    """`params` (default RoomParams()) with every sensor, clock and link error zero.

    The motion, the belt pitch (how the sensor sits on the body) and the ADC's range and step stay.
    """
    return zeroed(params or RoomParams(), _ERROR_FIELDS)


def describe(params: RoomParams | None = None) -> list[tuple[str, Any, str, str]]:
    """(dotted key, value, unit, source) of every figure, in declaration order."""
    return rows(params or RoomParams())


def params_with_overrides(overrides: dict[str, str], base: RoomParams | None = None) -> RoomParams:
    """Apply `--set key=value` overrides (dotted keys, string values) to `base` (default RoomParams()).

    ConfigError names the key when it is unknown, not a number of the right type, outside its range,
    or leaves a [min, max] pair reversed.
    """
    result = with_overrides(base or RoomParams(), overrides)
    check(result)
    return result


def check(params: RoomParams) -> None:
    """ConfigError when a [min, max] pair is reversed, no activity has weight, or a batch spans > 4 s."""
    check_pairs_and_batches(params)
    if params.away.min_share > params.away.max_share:
        raise ConfigError(f"--set: away.min_share = {params.away.min_share} exceeds away.max_share = "
                          f"{params.away.max_share}")
    weights = [getattr(params.activity, f.name) for f in dataclasses.fields(params.activity) if f.name.endswith("_weight")]
    if sum(weights) <= 0:
        raise ConfigError("--set: activity.*_weight are all zero (nobody would do anything)")
    if 2.0 * params.room.wall_margin_m >= params.room.width_m:
        raise ConfigError(f"--set: room.wall_margin_m = {params.room.wall_margin_m} leaves no floor in a "
                          f"{params.room.width_m} m wide room")

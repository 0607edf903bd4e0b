"""Every simulator parameter with its unit, range, default and where the default comes from.

`SimParams` nests one frozen dataclass per concern; a parameter's dotted key is
`<group>.<field>` (e.g. `sensors.gyro_bias_dps`). Each field's metadata holds its unit, the
accepted range and a one-line source, so `--set` validation and the documentation table
(docs/simulator.md) are driven by the same data. "assumption" marks a figure with no
published source; its plausible range is given next to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from protocol.errors import ConfigError
from sim_devices.param_table import check_pairs_and_batches, param, rows, with_overrides, zeroed


_p = param


@dataclass(frozen=True)
class CourtParams:
    """Court geometry and the two goal beacons (court frame: origin at a corner, x along the length)."""

    length_m: float = _p(28.0, "m", 5.0, 100.0, "IWBF/FIBA court 28 m x 15 m")
    width_m: float = _p(15.0, "m", 5.0, 100.0, "IWBF/FIBA court")
    run_off_m: float = _p(1.0, "m", 0.0, 5.0, "players stay inside the court plus about 1 m (issue)")
    basket_inset_m: float = _p(1.575, "m", 0.5, 5.0, "FIBA: basket centre 1.575 m from the end line")
    beacon_height_m: float = _p(2.9, "m", 0.0, 10.0, "under the backboard, out of play (protocol.session.Beacon)")
    beacon_radius_m: float = _p(1.0, "m", 0.1, 10.0, "the paper's reception zone (its simulation, sec. 4.4.1)")
    beacon_tx_power_dbm: float = _p(-59.0, "dBm", -100.0, 10.0, "RSSI at 1 m, the iBeacon calibration figure")
    listed_height_error_m: float = _p(0.0, "m", -10.0, 10.0,
                                      "the venue file's beacon height minus the true one; a venue file copied "
                                      "from another hall (issue 21: beacons on the floor or hung at 2-4 m)")
    listed_tx_error_db: float = _p(0.0, "dB", -20.0, 20.0,
                                   "the venue file's tx power minus the true one; iBeacon calibration is off "
                                   "by up to +-6 dB between units and mountings (issue 21)")


@dataclass(frozen=True)
class MagneticParams:
    """Earth field at the venue, building disturbance, and the chair's own iron."""

    field_ut: float = _p(46.0, "uT", 0.0, 100.0, "Osaka total field about 46 uT (IGRF/WMM)")
    inclination_deg: float = _p(49.0, "deg", -90.0, 90.0, "Osaka inclination about 49 deg (IGRF/WMM)")
    court_azimuth_deg: float = _p(30.0, "deg", -360.0, 360.0,
                                  "azimuth of court +x, clockwise from magnetic north; assumption (any)")
    disturbance_ut: float = _p(5.0, "uT", 0.0, 50.0,
                               "RMS per axis of the building field; assumption, 1-10 uT (about 9 deg heading "
                               "RMS; 15 deg reproduces the paper's 5.3 m, algorithms.md)")
    disturbance_wavelength_m: float = _p(6.0, "m", 0.5, 100.0,
                                         "typical wavelength of the building field; assumption, 3-10 m")
    hard_iron_ut: float = _p(8.0, "uT", 0.0, 100.0, "SD per axis of the chair's hard iron; assumption, 2-20 uT")
    soft_iron: float = _p(0.03, "1", 0.0, 0.3, "SD of the soft-iron matrix off identity; assumption, 0.01-0.05")
    noise_ut: float = _p(0.4, "uT", 0.0, 10.0,
                         "RMS per sample; AK8963 resolution 0.15 uT/LSB, assumption a few LSB")
    range_gauss: float = _p(10.0, "gauss", 0.1, 100.0, "the paper's sensor, +-10 gauss (Table 1)")


@dataclass(frozen=True)
class ChairParams:
    """Chair geometry and the player's physical limits."""

    radius_m: float = _p(0.45, "m", 0.2, 1.0, "chair footprint as a disc (issue); contact at 0.9 m")
    track_m: float = _p(0.82, "m", 0.4, 1.2,
                        "wheel contact-point track width; assumption, 0.75-0.90 m for 15-20 deg camber")
    wheel_diameter_m: float = _p(0.61, "m", 0.3, 1.0, "the paper's chairs: 610 mm")
    large_wheel_diameter_m: float = _p(0.67, "m", 0.3, 1.0, "the paper's player 3: 670 mm")
    large_wheel_fraction: float = _p(0.17, "1", 0.0, 1.0, "the paper: 1 of 6 instrumented players")
    camber_min_deg: float = _p(15.0, "deg", 0.0, 30.0, "sports chairs 15-20 deg (algorithms.md)")
    camber_max_deg: float = _p(20.0, "deg", 0.0, 30.0, "sports chairs 15-20 deg (algorithms.md)")
    top_speed_min_mps: float = _p(3.9, "m/s", 0.5, 6.0, "per-player top speed drawn in [min, max]; issue: "
                                  "sprints to about 4.5 m/s")
    top_speed_max_mps: float = _p(4.4, "m/s", 0.5, 6.0, "see top_speed_min_mps (+ push ripple stays <= 4.6)")
    backward_speed_mps: float = _p(1.5, "m/s", 0.0, 3.0, "short backward pushes; assumption, 1-2 m/s")
    accel_mps2: float = _p(2.5, "m/s^2", 0.1, 10.0,
                           "acceleration from rest, falling to half at top speed; assumption, 1.5-3.5")
    brake_mps2: float = _p(4.0, "m/s^2", 0.1, 15.0, "braking with hands on the rims; assumption, 3-6")
    yaw_rate_max_dps: float = _p(400.0, "deg/s", 10.0, 1200.0, "pivots on the spot; issue: several hundred deg/s")
    yaw_accel_dps2: float = _p(2500.0, "deg/s^2", 10.0, 20000.0, "pivot to full rate in ~0.15 s; assumption")
    lateral_accel_mps2: float = _p(6.0, "m/s^2", 0.5, 15.0, "turning grip limit v*yaw_rate; assumption, "
                                   "tyre friction 0.6-0.8 g")
    push_frequency_hz: float = _p(1.3, "Hz", 0.1, 5.0, "push cadence; assumption, 1-2 Hz")
    push_ripple_mps: float = _p(0.1, "m/s", 0.0, 0.5, "speed ripple within a push cycle; assumption, 0.05-0.3")
    wheel_sensor_offset_m: float = _p(0.01, "m", 0.0, 0.2,
                                      "axle IMU centre off the wheel axis (adds spin centripetal); assumption")
    yaw_skid_decay_s: float = _p(0.1, "s", 0.01, 2.0, "time constant of yaw skid after a shove; assumption")


@dataclass(frozen=True)
class GameParams:
    """Team play: possessions, spots around the basket, marking, blocks, contacts."""

    possession_min_s: float = _p(10.0, "s", 1.0, 120.0, "possession length drawn in [min, max] (issue: 10-25 s)")
    possession_max_s: float = _p(25.0, "s", 1.0, 120.0, "see possession_min_s")
    parked_start: int = _p(1, "0/1", 0, 1, "1: the game starts from rest (a tip-off, every chair still for a "
                           "dead-ball length); 0: the edges start mid-play, as after a restart")
    stoppage_probability: float = _p(0.3, "1", 0.0, 1.0,
                                     "a dead ball (foul, out of bounds) after a possession; assumption")
    stoppage_min_s: float = _p(3.0, "s", 0.0, 60.0, "dead-ball length drawn in [min, max]; everyone "
                               "holds still (lets an estimator see still periods); assumption")
    stoppage_max_s: float = _p(8.0, "s", 0.0, 60.0, "see stoppage_min_s")
    spot_change_min_s: float = _p(2.0, "s", 0.2, 60.0, "attackers cut to a new spot every [min, max] s; assumption")
    spot_change_max_s: float = _p(6.0, "s", 0.2, 60.0, "see spot_change_min_s")
    post_fraction: float = _p(0.4, "1", 0.0, 1.0, "share of spots within 2 m of the basket (crowding); assumption")
    mark_distance_m: float = _p(1.2, "m", 0.5, 5.0,
                                "defender centre this far from its attacker, goal side (0.3 m between "
                                "chairs); assumption")
    block_rate_per_min: float = _p(2.0, "1/min", 0.0, 30.0,
                                   "per player: attempts to drive into an opponent (block, screen); assumption, "
                                   "sets the contact rate (docs/simulator.md)")
    block_timeout_s: float = _p(2.0, "s", 0.1, 10.0, "a block not landed by then is given up; assumption")
    contact_min_closing_mps: float = _p(0.3, "m/s", 0.0, 5.0,
                                        "slower touches are leaning, not recorded contacts; assumption")
    contact_refractory_s: float = _p(1.0, "s", 0.0, 10.0, "one pair counts at most one contact per this; assumption")
    restitution: float = _p(0.2, "1", 0.0, 1.0, "chair-to-chair coefficient of restitution; assumption, 0-0.4")
    lateral_friction_mps2: float = _p(6.0, "m/s^2", 0.5, 20.0, "sideways slide deceleration after a shove "
                                      "(tyre friction ~0.6 g); assumption")
    yaw_kick_dps_per_mps: float = _p(40.0, "deg/s per m/s", 0.0, 500.0,
                                     "SD of the yaw skid a contact adds per m/s of impulse; assumption")
    arrive_m: float = _p(0.25, "m", 0.05, 2.0, "a player stops when this close to the target")
    leave_m: float = _p(0.6, "m", 0.05, 5.0, "and starts again when the target is this far (hysteresis)")
    target_wander_m: float = _p(0.4, "m", 0.0, 3.0, "slow random drift of each target (fidgeting); assumption")


@dataclass(frozen=True)
class WheelParams:
    """Wheel reading vs ground travel."""

    diameter_bias: float = _p(-0.005, "1", -0.1, 0.1,
                              "effective rolling / measured diameter - 1 (tyre deflection); assumption, "
                              "-0.3..-1 %")
    diameter_spread: float = _p(0.003, "1", 0.0, 0.1, "SD of that ratio per wheel; assumption")
    slip_accel: float = _p(0.02, "1", 0.0, 0.5, "extra wheel rotation at full acceleration; assumption, 1-3 %")
    slip_brake: float = _p(0.03, "1", 0.0, 0.5, "missing wheel rotation at full braking; assumption, 1-5 %")
    slip_turn: float = _p(0.0, "1", 0.0, 0.5, "extra differential wheel rotation at the full yaw rate (tyre "
                          "scrub in pivots); assumption, 0-5 %")


@dataclass(frozen=True)
class SensorParams:
    """IMU sampling, ranges and error model (the paper's sensor; MPU-9250 class figures)."""

    rate_hz: float = _p(200.0, "Hz", 10.0, 2000.0, "the paper's sensors sample at 200 Hz")
    batch_samples: int = _p(20, "samples", 1, 1000, "0.1 s per ImuBatch (issue)")
    gyro_range_dps: float = _p(1500.0, "deg/s", 100.0, 5000.0, "the paper's sensor, +-1500 deg/s (Table 1)")
    accel_range_g: float = _p(16.0, "g", 2.0, 400.0, "the paper's sensor, +-16 g (Table 1)")
    adc_bits: int = _p(16, "bits", 8, 32, "MPU-9250 / ICM-20948 16-bit outputs")
    gyro_bias_dps: float = _p(0.5, "deg/s", 0.0, 20.0, "SD per axis of the turn-on bias; MPU-9250 initial "
                              "ZRO tolerance +-5 deg/s untrimmed, assumption 0.5 after factory trim (0.1-5)")
    gyro_bias_walk_dps_per_sqrt_s: float = _p(0.002, "deg/s/sqrt(s)", 0.0, 1.0,
                                              "bias random walk; assumption, MEMS in-run instability 5-20 deg/h")
    gyro_warmup_dps: float = _p(0.0, "deg/s", 0.0, 5.0,
                                "SD per axis of the bias change while the sensor warms up after power-on; "
                                "MPU-9250 ZRO over temperature +-30 deg/s over 125 degC (0.24 deg/s/degC), "
                                "a few degC of warming; assumption, 0-0.5")
    gyro_warmup_s: float = _p(300.0, "s", 1.0, 10_000.0, "time constant of that warm-up; assumption, 100-600 s")
    gyro_noise_dps_per_sqrt_hz: float = _p(0.01, "deg/s/sqrt(Hz)", 0.0, 1.0,
                                           "MPU-9250 rate noise density 0.01 (ICM-20948 0.015, BMI160 0.007)")
    gyro_scale_error: float = _p(0.01, "1", 0.0, 0.2, "SD per axis; MPU-9250 sensitivity tolerance +-3 %")
    accel_bias_g: float = _p(0.02, "g", 0.0, 1.0, "SD per axis; MPU-9250 zero-g tolerance +-60 mg (x, y), +-80 mg (z)")
    accel_noise_g_per_sqrt_hz: float = _p(0.0003, "g/sqrt(Hz)", 0.0, 0.1,
                                          "MPU-9250 300 ug/sqrt(Hz) (BMI160 180, ICM-20948 230)")
    accel_scale_error: float = _p(0.01, "1", 0.0, 0.2, "SD per axis; MPU-9250 sensitivity tolerance +-3 %")
    misalignment_deg: float = _p(1.0, "deg", 0.0, 20.0, "SD per axis of mounting misalignment (seat tilt, "
                                 "hub fit); assumption, 0.5-2 deg")
    vibration_g: float = _p(0.01, "g", 0.0, 2.0, "SD of frame vibration at rest (sitting player); assumption, "
                            "0.005-0.05 g")
    vibration_g_per_mps: float = _p(0.03, "g per m/s", 0.0, 2.0, "added vibration SD per m/s of speed (rolling "
                                    "on a sprung floor); assumption")


@dataclass(frozen=True)
class ImpactParams:
    """Seat-accelerometer spikes: chair-to-chair contacts and other jolts (bumps, ball, hard stops)."""

    pulse_ms: float = _p(10.0, "ms", 1.0, 100.0, "half-sine impact length; impacts last a few ms (algorithms.md)")
    ring_fraction: float = _p(0.3, "1", 0.0, 2.0, "frame ringing after a pulse, share of its peak; assumption")
    ring_hz: float = _p(30.0, "Hz", 1.0, 99.0, "frame ringing frequency; assumption")
    ring_decay_ms: float = _p(30.0, "ms", 1.0, 1000.0, "frame ringing decay time; assumption")
    contact_g_per_mps: float = _p(8.0, "g per m/s", 0.0, 50.0,
                                  "median contact pulse peak per m/s of closing speed; assumption shaped by "
                                  "the paper's Fig. 5 (recall falls as the threshold rises to 12 g)")
    contact_spread: float = _p(0.35, "1", 0.0, 2.0, "log-normal SD of the contact peak; assumption")
    noncontact_rate_per_min: float = _p(4.0, "1/min", 0.0, 120.0,
                                        "per player: bumps, ball hits, hard stops, caster landings; assumption")
    noncontact_median_g: float = _p(3.0, "g", 0.0, 50.0, "median peak of those jolts; assumption")
    noncontact_spread: float = _p(0.6, "1", 0.0, 2.0, "log-normal SD of their peak; assumption (tail gives "
                                  "false alarms at 4-8 g, Fig. 5's precision trend)")


@dataclass(frozen=True)
class RadioParams:
    """BLE: IMU batch streaming (loss, latency) and goal-beacon sightings."""

    batch_loss_rate: float = _p(0.01, "1", 0.0, 0.9, "share of ImuBatch packets lost; assumption, 0.1-5 %")
    loss_burst_batches: float = _p(3.0, "batches", 1.0, 1000.0,
                                   "mean length of a loss burst (Gilbert-Elliott); assumption")
    latency_ms: float = _p(20.0, "ms", 0.0, 5000.0, "fixed part of log_time - last sample time; assumption "
                           "(BLE connection interval 7.5-30 ms + host)")
    latency_jitter_ms: float = _p(10.0, "ms", 0.0, 5000.0, "mean of the exponential extra latency; assumption")
    advertising_interval_ms: float = _p(100.0, "ms", 20.0, 10240.0,
                                        "beacon advertising ~10 Hz (issue); BLE adds 0-10 ms advDelay")
    scan_efficiency: float = _p(0.7, "1", 0.0, 1.0,
                                "share of advertisements a scanning receiver hears; assumption, 0.3-0.95")
    path_loss_exponent: float = _p(2.2, "1", 1.0, 6.0, "log-distance model; 1.8-4.3 in one building (algorithms.md)")
    shadowing_db: float = _p(4.0, "dB", 0.0, 20.0, "SD of log-normal shadowing; assumption, 2-8 dB indoors")
    shadowing_time_s: float = _p(1.0, "s", 0.01, 100.0, "correlation time of the shadowing; assumption")
    fading_db: float = _p(2.0, "dB", 0.0, 20.0, "SD of per-packet fading; assumption")
    body_loss_db: float = _p(5.0, "dB", 0.0, 30.0, "attenuation when the beacon is behind the player (body, "
                             "backrest); the body absorbs 3-5 dB (algorithms.md)")
    sensitivity_dbm: float = _p(-95.0, "dBm", -130.0, -40.0, "receiver sensitivity; assumption (nRF52 -96 dBm)")
    receiver_height_m: float = _p(0.5, "m", 0.0, 3.0, "seat sensor height (issue)")


@dataclass(frozen=True)
class ClockParams:
    """Device clocks: sample times in the log are the device's clock, truth is the true clock."""

    start_unix_s: int = _p(1_704_067_200, "s", 0, 4_000_000_000,
                           "true time of the game start (2024-01-01T00:00Z); fixed, no wall clock")
    offset_ms: float = _p(10.0, "ms", 0.0, 10_000.0,
                          "SD of each device clock's offset after sync; assumption (well inside 0.5 s)")
    drift_ppm: float = _p(20.0, "ppm", 0.0, 1000.0, "SD of each device clock's rate error; crystals +-20-50 ppm")
    jitter_ms: float = _p(0.1, "ms", 0.0, 1.0, "SD of per-sample timestamp jitter (clipped at 3 SD); assumption")


@dataclass(frozen=True)
class SimParams:
    """All simulator parameters; the dotted key of a field is `<group>.<field>`."""

    court: CourtParams = field(default_factory=CourtParams)
    magnetic: MagneticParams = field(default_factory=MagneticParams)
    chair: ChairParams = field(default_factory=ChairParams)
    game: GameParams = field(default_factory=GameParams)
    wheels: WheelParams = field(default_factory=WheelParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    impacts: ImpactParams = field(default_factory=ImpactParams)
    radio: RadioParams = field(default_factory=RadioParams)
    clock: ClockParams = field(default_factory=ClockParams)


# Error sources an `error_free` run switches off (signal and motion stay as they are).
_ERROR_FIELDS: dict[str, tuple[str, ...]] = {
    "magnetic": ("disturbance_ut", "hard_iron_ut", "soft_iron", "noise_ut"),
    "court": ("listed_height_error_m", "listed_tx_error_db"),
    "wheels": ("diameter_bias", "diameter_spread", "slip_accel", "slip_brake", "slip_turn"),
    "sensors": ("gyro_bias_dps", "gyro_bias_walk_dps_per_sqrt_s", "gyro_warmup_dps", "gyro_noise_dps_per_sqrt_hz",
                "gyro_scale_error",
                "accel_bias_g", "accel_noise_g_per_sqrt_hz", "accel_scale_error", "misalignment_deg",
                "vibration_g", "vibration_g_per_mps"),
    "impacts": ("noncontact_rate_per_min",),
    "radio": ("batch_loss_rate", "latency_jitter_ms", "shadowing_db", "fading_db", "body_loss_db"),
    "clock": ("offset_ms", "drift_ppm", "jitter_ms"),
}


def error_free(params: SimParams | None = None) -> SimParams:
    """`params` (default SimParams()) with every sensor, wheel, radio and clock error set to zero.

    The motion (including contact shoves, which move a chair without turning its wheels) and the
    contact impact pulses are kept: they are what happened, not measurement errors.
    """
    return zeroed(params or SimParams(), _ERROR_FIELDS)


def describe(params: SimParams | None = None) -> list[tuple[str, Any, str, str]]:
    """(dotted key, value, unit, source) of every parameter, in declaration order."""
    return rows(params or SimParams())


def params_with_overrides(overrides: dict[str, str], base: SimParams | None = None) -> SimParams:
    """Apply `--set key=value` overrides (dotted keys, string values) to `base` (default SimParams()).

    ConfigError names the key when it is unknown, the value is not a number of the right type, or
    it lies outside the parameter's range; also when a [min, max] pair ends up reversed.
    """
    result = with_overrides(base or SimParams(), overrides)
    _check_pairs(result)
    return result


def _check_pairs(params: SimParams) -> None:
    check_pairs_and_batches(params)  # every *_min <= *_max, and the batch span
    if params.game.arrive_m > params.game.leave_m:
        raise ConfigError(f"--set: game.arrive_m = {params.game.arrive_m} exceeds game.leave_m = {params.game.leave_m}")

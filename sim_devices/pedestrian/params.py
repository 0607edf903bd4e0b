"""Every pedestrian-simulator figure with its unit, accepted range, default and where it comes from.

`PedestrianParams` nests one frozen dataclass per concern; a figure's dotted key is
`<group>.<field>` (e.g. `gait.cadence_min_hz`, `sensors.gyro_bias_dps`). Each field's metadata
holds its unit, range and a one-line source, so `--set` validation and the tables of
docs/simulator-pedestrian.md come from the same data. "assumption" marks a figure with no
published source; the reasoning and a plausible range follow it. "the paper" is the indoor
navigation paper (../shared/seeds/003, Nakagome, Saito, Mori; ../shared/methods.md §3).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from protocol.errors import ConfigError
from sim_devices.param_table import check_pairs_and_batches, param, rows, with_overrides, zeroed

_p = param


@dataclass(frozen=True)
class PeopleParams:
    """Who walks: statures beyond the paper's three, drawn per person."""

    height_mean_m: float = _p(1.71, "m", 1.0, 2.2, "Japanese men aged 20-29, mean stature about 1.71 m (MHLW "
                              "National Health and Nutrition Survey); the paper's 3 walkers: 1.69, 1.74, 1.79 m "
                              "(its tables 1-2), used as given for the first three people")
    height_sd_m: float = _p(0.06, "m", 0.0, 0.3, "SD of stature, about 6 cm (same survey)")
    hip_height_ratio: float = _p(0.53, "1", 0.4, 0.6, "greater-trochanter height / stature 0.530 (Winter, "
                                 "Biomechanics and Motor Control of Human Movement, anthropometric table)")
    hand_height_ratio: float = _p(0.62, "1", 0.4, 0.8, "phone held in front at about elbow height, 0.63 x "
                                  "stature (Winter's table); assumption 0.55-0.68")
    start_interval_s: float = _p(20.0, "s", 0.0, 600.0, "people start one after another from the start stand "
                                 "(the paper's runs were sequential); assumption")


@dataclass(frozen=True)
class GaitParams:
    """Steps: cadence, step length from stature and cadence, variation, turns and pauses."""

    cadence_min_hz: float = _p(1.6, "Hz", 0.8, 3.0, "preferred cadence drawn per person in [min, max]; adults "
                               "walk at about 100-125 steps/min at comfortable speed (e.g. Tudor-Locke et al. 2019, "
                               "CADENCE-Adults); the paper's Fig. 3 peak, 1.8 Hz, lies inside 1.6-2.1 Hz")
    cadence_max_hz: float = _p(2.1, "Hz", 0.8, 3.0, "see cadence_min_hz")
    step_height_ratio: float = _p(0.37, "1", 0.2, 0.6, "step length / stature at the reference cadence: the "
                                  "paper's eq. 2 (V = 0.37 H f, its ref. [5]) read as step length 0.37 H; the "
                                  "pedometer rule of thumb is 0.413-0.415 H at a brisker pace")
    step_reference_hz: float = _p(1.8, "Hz", 0.8, 3.0, "cadence at which step length = step_height_ratio x "
                                  "stature (the paper's Fig. 3 walking frequency)")
    step_cadence_exponent: float = _p(0.5, "1", 0.0, 2.0, "step length ~ (cadence / reference)^this across people; "
                                      "within one person step length grows about linearly with cadence (Grieve "
                                      "1968: stride ~ sqrt(speed)), across people the paper's eq. 2 held to "
                                      "-5..+1 % without a cadence term; assumption halfway")
    step_ratio_person_sd: float = _p(0.035, "1", 0.0, 0.2, "SD of a person's step length about the stature model "
                                     "(stature explains only part of step length; the paper's eq. 2 errors -5.0, "
                                     "+0.7, +0.9 % over 3 walkers); assumption 0.03-0.05")
    step_length_cv: float = _p(0.03, "1", 0.0, 0.3, "step-to-step CV of step length, about 2-4 % in healthy "
                               "adults (gait-variability literature, e.g. Hausdorff 2005, J NeuroEng Rehabil 2:19, "
                               "for the timing); assumption")
    step_time_cv: float = _p(0.025, "1", 0.0, 0.3, "step-to-step CV of step time; stride-time CV of healthy "
                             "adults 1-3 % (Hausdorff 2005)")
    acceleration_mps2: float = _p(0.8, "m/s^2", 0.1, 5.0, "speeding up from a stop and slowing down to one; "
                                  "steady speed within 2-3 steps of gait initiation (Breniere & Do 1986); "
                                  "assumption 0.6-1.2")
    turn_speed_ratio: float = _p(0.75, "1", 0.2, 1.0, "speed through a 90 deg corner / cruise speed, scaled with "
                                 "the turn angle; walkers shorten and slow their steps in turns (turning gait, e.g. "
                                 "Glaister et al. 2007, Gait Posture 25:289); assumption 0.7-0.9")
    turn_radius_m: float = _p(0.6, "m", 0.05, 5.0, "radius of the path through a corner (people cut corners); "
                              "a 90 deg turn of about 1 s at 0.9 m/s, peak yaw rate ~100 deg/s; assumption 0.4-1.0")
    turn_slow_distance_m: float = _p(1.5, "m", 0.0, 10.0, "slowing starts this far before a corner and ends this "
                                     "far after it (about two steps); assumption")
    bounce_m: float = _p(0.022, "m", 0.0, 0.1, "half-amplitude of the body's vertical bounce at step frequency "
                         "at cruise speed (centre-of-mass excursion 4-5 cm peak to peak, Gard, Miff & Kuo "
                         "2004, Hum Mov Sci 22:597); scaled with speed")
    surge_ratio: float = _p(0.12, "1", 0.0, 0.5, "forward speed swing within a step / mean speed (inverted "
                            "pendulum, slowest at mid-stance; trunk forward velocity varies +-10-15 %); assumption")
    lateral_sway_m: float = _p(0.02, "m", 0.0, 0.1, "half-amplitude of side-to-side body sway at stride frequency "
                               "(CoM lateral excursion 3-5 cm peak to peak); assumption")
    torso_yaw_deg: float = _p(3.0, "deg", 0.0, 20.0, "torso/shoulder yaw at stride frequency, +-3 deg at cruise "
                              "speed (thoracic rotation 3-6 deg, Stokes 1989); assumption")
    pause_chance: float = _p(0.1, "1", 0.0, 1.0, "chance to stop for a while at each corner (looking around); "
                             "assumption")
    pause_min_s: float = _p(2.0, "s", 0.1, 120.0, "pause length [min, max]; assumption")
    pause_max_s: float = _p(5.0, "s", 0.1, 300.0, "see pause_min_s")


@dataclass(frozen=True)
class HandParams:
    """The phone held flat in front (the paper's hold: on the palm, screen up, top forward)."""

    forward_m: float = _p(0.35, "m", 0.0, 1.0, "phone ahead of the body centre; assumption 0.25-0.45")
    right_m: float = _p(0.12, "m", -0.5, 0.5, "phone to the right of the body centre (right hand); assumption")
    yaw_offset_sd_deg: float = _p(3.0, "deg", 0.0, 45.0, "SD of the phone's yaw from the walking direction, drawn "
                                  "per grip: a phone read while walking points within a few degrees of the way; "
                                  "assumption 2-5")
    pitch_mean_deg: float = _p(8.0, "deg", -45.0, 60.0, "mean pitch, top edge up (held towards the eyes); the "
                               "paper's hold is nearly flat; assumption 0-20")
    attitude_sd_deg: float = _p(3.0, "deg", 0.0, 30.0, "SD of a grip's pitch and roll about that mean; "
                                "assumption")
    sway_deg: float = _p(1.5, "deg", 0.0, 20.0, "pitch/roll swing at step frequency from the arm; assumption")
    yaw_sway_deg: float = _p(2.0, "deg", 0.0, 20.0, "extra phone yaw swing at stride frequency (wrist); "
                             "assumption")
    bounce_ratio: float = _p(0.8, "1", 0.0, 1.5, "hand bounce / body bounce (the arm damps it); assumption "
                             "0.6-1.0")
    tremor_m: float = _p(0.005, "m", 0.0, 0.05, "SD of slow hand wander (0.2-2 Hz); assumption")
    tremor_deg: float = _p(0.5, "deg", 0.0, 10.0, "SD of slow attitude wander (0.2-2 Hz); assumption")
    grip_change_per_min: float = _p(1.0, "1/min", 0.0, 30.0, "rate of grip changes while walking (a new yaw "
                                    "offset, pitch and roll, taken over 0.6 s); assumption")


@dataclass(frozen=True)
class PocketParams:
    """The phone in a front trouser pocket, swinging with the thigh."""

    along_thigh_m: float = _p(0.18, "m", 0.0, 0.5, "phone centre below the hip joint along the thigh; front "
                              "pocket depth; assumption 0.12-0.25")
    lateral_m: float = _p(0.11, "m", 0.0, 0.3, "hip joint to the body centre line (half the hip width, Winter); "
                          "right pocket")
    thigh_swing_deg: float = _p(22.0, "deg", 0.0, 60.0, "half-amplitude of the thigh's flexion-extension at "
                                "cruise speed: hip range about 40-45 deg, +25 flexion to -15 extension (Perry, "
                                "Gait Analysis 1992); scaled with speed")
    thigh_mean_deg: float = _p(5.0, "deg", -30.0, 30.0, "mean thigh flexion while walking (same source)")
    pocket_angle_max_deg: float = _p(45.0, "deg", 0.0, 180.0, "rotation of the phone about the thigh axis, "
                                     "drawn in [-max, max] per insertion on top of the screen in/out and top "
                                     "up/down draws: the walking direction in the phone frame is unknown; "
                                     "assumption")
    tilt_sd_deg: float = _p(5.0, "deg", 0.0, 30.0, "SD of the phone's tilt within the pocket; assumption")


@dataclass(frozen=True)
class StandParams:
    """Placing the phone on a calibration stand, scanning, picking it up (the paper's stand, its Fig. 2)."""

    place_s: float = _p(1.5, "s", 0.2, 10.0, "moving the phone from the hand or pocket into the stand's corner; "
                        "assumption 1-2 s")
    still_s: float = _p(4.0, "s", 0.5, 60.0, "phone still on the stand while the app reads the QR code and "
                        "calibrates; the scan is written halfway; assumption 3-5 s")
    pick_s: float = _p(1.5, "s", 0.2, 10.0, "picking it up again; assumption")
    height_m: float = _p(1.0, "m", 0.3, 2.0, "height of the stand's plate; assumption (a counter-height stand)")
    placement_deg: float = _p(0.3, "deg", 0.0, 10.0, "SD of the phone's yaw in the stand's corner (the corner "
                              "holds it; the paper calls its residual 3 deg after 40 m 'the calibration error'); "
                              "assumption 0.2-0.5")
    offset_m: float = _p(1.0, "m", 0.0, 10.0, "a stand along the way stands this far into the corridor the "
                         "walker leaves the junction by; assumption")


@dataclass(frozen=True)
class SensorParams:
    """The phone's IMU (BMI160 / LSM6DS3-class) and magnetometer (AK09911-class), as Android reports them."""

    rate_hz: float = _p(50.0, "Hz", 10.0, 500.0, "the paper's rate: 50 samples/s (sec. 3.1); 100 Hz also usual")
    batch_samples: int = _p(20, "samples", 1, 1000, "samples per ImuBatch, as the ILC import writes them")
    timestamp_jitter_ms: float = _p(0.5, "ms", 0.0, 20.0, "SD of each sample's timestamp about the instant sampled "
                                    "(Android sensor events are stamped by the sensor hub; 0.1-1 ms typical, "
                                    "assumption)")
    accel_range_g: float = _p(8.0, "g", 2.0, 16.0, "BMI160 ranges +-2/4/8/16 g (datasheet BST-BMI160-DS000); "
                              "Android phones use +-8 g")
    gyro_range_dps: float = _p(2000.0, "deg/s", 125.0, 2000.0, "BMI160 +-125..2000 deg/s; Android +-2000")
    adc_bits: int = _p(16, "bits", 8, 32, "BMI160 16-bit outputs (0.24 mg, 0.061 deg/s at these ranges)")
    accel_noise_g_per_sqrt_hz: float = _p(0.00018, "g/sqrt(Hz)", 0.0, 0.01, "BMI160 180 ug/sqrt(Hz) (LSM6DS3 90 "
                                          "in high-performance mode)")
    accel_bias_g: float = _p(0.02, "g", 0.0, 0.5, "SD per axis; BMI160 zero-g offset +-40 mg typical, reduced "
                             "by the phone maker's calibration; assumption 0.01-0.04")
    accel_scale_error: float = _p(0.005, "1", 0.0, 0.1, "SD per axis; BMI160 sensitivity tolerance +-1 %")
    gyro_noise_dps_per_sqrt_hz: float = _p(0.007, "deg/s/sqrt(Hz)", 0.0, 1.0, "BMI160 and LSM6DS3 0.007 "
                                           "deg/s/sqrt(Hz)")
    gyro_bias_dps: float = _p(0.03, "deg/s", 0.0, 20.0, "SD per axis of the bias left after Android's runtime "
                              "gyro calibration (TYPE_GYROSCOPE is drift-compensated); raw BMI160 zero-rate "
                              "offset +-3 deg/s, drift 0.05 deg/s/K; calibrated on the paper's table 3 "
                              "(median 1.9 deg after 40 m); 0.1 is a worse phone")
    gyro_bias_walk_dps_per_sqrt_s: float = _p(0.002, "deg/s/sqrt(s)", 0.0, 1.0, "bias random walk; assumption, "
                                              "MEMS in-run instability 5-20 deg/h")
    gyro_scale_error: float = _p(0.01, "1", 0.0, 0.1, "SD per axis; BMI160 sensitivity tolerance +-1 % (LSM6DS3 "
                                 "+-2 %)")
    misalignment_deg: float = _p(0.5, "deg", 0.0, 10.0, "SD per axis of the IMU package's misalignment in the "
                                 "phone body (cross-axis sensitivity +-1 % ~ 0.6 deg, BMI160)")
    mag_noise_ut: float = _p(0.6, "uT", 0.0, 10.0, "SD of magnetometer noise per sample, about one LSB "
                             "(AK09911: 0.6 uT/LSB, 14-bit)")
    mag_step_ut: float = _p(0.6, "uT", 0.01, 10.0, "magnetometer quantisation step (AK09911 0.6 uT/LSB; "
                            "AK09916 0.15)")
    mag_range_ut: float = _p(4900.0, "uT", 100.0, 10000.0, "AK09911 range +-4900 uT")
    mag_bias_ut: float = _p(2.0, "uT", 0.0, 100.0, "SD per axis of the hard-iron offset left after Android's "
                            "magnetometer calibration (phone magnets give 10-100 uT raw); assumption 1-5")
    mag_scale_error: float = _p(0.02, "1", 0.0, 0.3, "SD per axis of soft-iron / sensitivity error (AK09911 "
                                "sensitivity tolerance about +-5 %, after calibration less); assumption")


@dataclass(frozen=True)
class MagneticParams:
    """The field a phone sees indoors: Earth's field, shielded by the building's steel by floor, plus local
    anomalies."""

    field_ut: float = _p(46.0, "uT", 20.0, 70.0, "total intensity in Tokyo about 46 uT (GSI magnetic chart, "
                         "epoch 2020)")
    inclination_deg: float = _p(49.0, "deg", -90.0, 90.0, "dip: the paper's 49 deg in Tokyo (sec. 3.2)")
    declination_deg: float = _p(-7.5, "deg", -30.0, 30.0, "magnetic north west of true north, Tokyo about "
                                "7.5 deg W (GSI)")
    north_deg: float = _p(90.0, "deg", -360.0, 360.0, "direction of true north in the venue frame, "
                          "counter-clockwise from +x; assumption (+y north)")
    floor: int = _p(1, "floor", 0, 200, "the storey walked on; the paper walked floor 1 of building 2 and "
                    "measured floors 1, 12, 20 of a 20-storey building")
    storeys: int = _p(20, "floors", 1, 200, "storeys of the building (the paper's: 20)")
    mid_floor_loss: float = _p(0.55, "1", 0.0, 0.95, "field factor = 1 - this x sin^2(pi x floor / storeys): "
                               "0.98 on floor 1, 0.50 on floor 12 and 1.0 on floor 20 of 20, the paper's "
                               "observation (field halved on 12F, normal on 1F and 20F, Figs. 6-8); the shape "
                               "between is an assumption")
    anomaly_ut: float = _p(5.0, "uT", 0.0, 50.0, "SD per component of the local anomaly from steel and wiring "
                           "(indoor magnetic maps show +-5-20 uT over metres; Li et al. 2012 IPIN); assumption")
    anomaly_min_m: float = _p(2.0, "m", 0.2, 50.0, "anomaly wavelengths drawn in [min, max]; assumption")
    anomaly_max_m: float = _p(10.0, "m", 0.2, 100.0, "see anomaly_min_m")


@dataclass(frozen=True)
class FloorParams:
    """The two-floor building (preset `floors`): storey height and the staircase between floors 0 and 1."""

    height_m: float = _p(4.0, "m", 2.5, 6.0, "floor-to-floor height (slab top to slab top); offices 3.5-4.5 m "
                         "(a 2.7-3 m ceiling plus the slab and services void); assumption")
    stair_up_vertical_mps: float = _p(0.3, "m/s", 0.1, 1.0, "vertical speed climbing the stair (one riser per "
                                      "step at 1.7-1.9 steps/s, risers 0.16-0.18 m: 0.27-0.34 m/s); horizontal "
                                      "speed = this x tread / riser, 0.5 m/s, inside Fruin's (1971) ascending "
                                      "0.45-0.7 m/s")
    stair_down_vertical_mps: float = _p(0.35, "m/s", 0.1, 1.0, "vertical speed descending (Fruin 1971: "
                                        "descending 0.6-0.8 m/s horizontal, a little faster than ascending); "
                                        "horizontal 0.59 m/s")
    stair_tread_m: float = _p(0.28, "m", 0.2, 0.4, "going of one step (tread depth): building codes 0.25-0.30 m "
                              "(e.g. UK Approved Document K: 0.28 m for public stairs); a step on the stair is one "
                              "tread, so the step rate there is horizontal speed / tread")


@dataclass(frozen=True)
class BarometerParams:
    """The phone's barometer (Bosch BMP280 / BMP388 / BMP390 class) and the air it measures."""

    rate_hz: float = _p(10.0, "Hz", 1.0, 50.0, "Pressure samples per second; Android phones deliver about 5-25 Hz "
                        "(SENSOR_DELAY_NORMAL ~5 Hz, faster on request); assumption 10")
    noise_hpa: float = _p(0.015, "hPa", 0.0, 1.0, "RMS noise per sample after the sensor's filtering: BMP280 1.3 Pa "
                          "at ultra-high resolution, BMP388/390 lower with the IIR filter; 0.01-0.02 hPa (about "
                          "0.1-0.2 m)")
    offset_hpa: float = _p(0.5, "hPa", 0.0, 5.0, "SD of a phone's constant offset: absolute accuracy +-1 hPa "
                           "(BMP280, 0-65 deg C; BMP388 +-0.5); relative accuracy +-0.06-0.12 hPa is then the "
                           "error of a pressure difference; assumption 0.3-1")
    ground_hpa: float = _p(1008.0, "hPa", 850.0, 1100.0, "true pressure at floor 0's level at the session start "
                           "(a low-lying site on a normal day); assumption")
    air_temperature_c: float = _p(22.0, "deg C", -20.0, 45.0, "indoor air temperature in the hypsometric relation "
                                  "p(z) = p0 exp(-g M z / (R T)): 0.117 hPa per metre at 1008 hPa and 22 deg C "
                                  "(about 0.12 hPa/m near sea level)")
    weather_trend_hpa_per_h: float = _p(0.2, "hPa/h", 0.0, 3.0, "SD of the session's linear weather trend, drawn "
                                        "once per session (every phone sees it): synoptic changes typically 0.1-0.3 "
                                        "hPa/h, up to about 1 hPa/h with a front or storm")
    hvac_jump_hpa: float = _p(0.05, "hPa", 0.0, 1.0, "SD of a building pressure jump (ventilation switching, doors "
                              "opening against the building's over-pressure); assumption 0.02-0.1 hPa")
    hvac_jumps_per_min: float = _p(0.5, "1/min", 0.0, 10.0, "rate of such jumps (Poisson, building-wide); "
                                   "assumption")
    hvac_rise_s: float = _p(2.0, "s", 0.1, 60.0, "time a jump takes (smoothstep); assumption 1-5 s")


@dataclass(frozen=True)
class BleParams:
    """BLE beacons and the phone's scanning: log-distance path loss with shadowing, body and floor losses."""

    advertising_interval_ms: float = _p(100.0, "ms", 20.0, 10240.0, "beacon advertising interval (iBeacon "
                                        "recommends 100 ms); each event is delayed a further 0-10 ms (the BLE "
                                        "spec's advDelay)")
    reception_chance: float = _p(0.2, "1", 0.01, 1.0, "share of advertisements reported by an Android scan "
                                 "(one of three channels heard at a time, scan window/interval, collisions): a "
                                 "100 ms beacon in range is heard about 2 times per second, with misses; "
                                 "Android reports of 1-5 per second (field notes); assumption 0.1-0.5")
    height_m: float = _p(2.6, "m", 0.3, 5.0, "beacon height above its floor (ceiling or high on a wall); "
                         "assumption")
    tx_power_error_db: float = _p(6.0, "dB", 0.0, 15.0, "each beacon's true RSSI at 1 m is the venue file's "
                                  "nominal -59 dBm plus a draw in [-this, +this] (uncalibrated beacons, mounting, "
                                  "battery); the brief's +-6 dB; the venue file keeps the nominal figure")
    path_loss_exponent_min: float = _p(1.8, "1", 1.0, 6.0, "path-loss exponent drawn once per venue in [min, max]; "
                                       "1.8-4.3 within one building (algorithms.md: BLE proximity)")
    path_loss_exponent_max: float = _p(4.3, "1", 1.0, 6.0, "see path_loss_exponent_min")
    shadowing_db: float = _p(6.0, "dB", 0.0, 15.0, "SD of log-normal shadowing (walls, furniture, the building), "
                             "a field over the phone's position per beacon and floor; indoor 4-8 dB")
    shadowing_distance_m: float = _p(3.0, "m", 0.2, 30.0, "correlation distance of the shadowing (Gaussian "
                                     "correlation exp(-d^2 / 2 L^2)); indoor decorrelation 1-5 m (Gudmundson-type "
                                     "models); assumption")
    fading_db: float = _p(3.0, "dB", 0.0, 15.0, "SD of the per-packet variation (multipath fading, the three "
                          "advertising channels differ by a few dB); assumption 2-5")
    body_loss_db: float = _p(6.0, "dB", 0.0, 20.0, "extra loss with the walker's body between phone and beacon "
                             "(scaled by how squarely it lies between); 3-5 dB (algorithms.md), 3-10 dB "
                             "measured at 2.4 GHz behind a torso")
    floor_loss_db: float = _p(20.0, "dB", 0.0, 50.0, "attenuation per floor slab between phone and beacon; ITU-R "
                              "P.1238 gives 15 dB for one floor at 1.8-2 GHz in offices, reinforced-concrete slabs "
                              "at 2.4 GHz 15-25 dB; the stairwell's opening is not modelled")
    phone_offset_db: float = _p(3.0, "dB", 0.0, 15.0, "SD of a phone's RSSI offset (Android devices differ by up "
                                "to about 10 dB for the same signal); assumption 2-5")
    sensitivity_dbm: float = _p(-100.0, "dBm", -120.0, -60.0, "weakest advertisement the phone reports (BLE 1M "
                                "receivers -95 to -100 dBm); RSSI is reported in whole dBm")


@dataclass(frozen=True)
class ClockParams:
    """Where the session sits in time."""

    start_unix_s: int = _p(1_704_067_200, "s", 0, 4_000_000_000,
                           "true time of the session start (2024-01-01T00:00Z); fixed, no wall clock")


@dataclass(frozen=True)
class PedestrianParams:
    """All pedestrian-simulator figures; the dotted key of a field is `<group>.<field>`."""

    people: PeopleParams = field(default_factory=PeopleParams)
    gait: GaitParams = field(default_factory=GaitParams)
    hand: HandParams = field(default_factory=HandParams)
    pocket: PocketParams = field(default_factory=PocketParams)
    stand: StandParams = field(default_factory=StandParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    magnetic: MagneticParams = field(default_factory=MagneticParams)
    floors: FloorParams = field(default_factory=FloorParams)
    barometer: BarometerParams = field(default_factory=BarometerParams)
    ble: BleParams = field(default_factory=BleParams)
    clock: ClockParams = field(default_factory=ClockParams)


_ERROR_FIELDS: dict[str, tuple[str, ...]] = {
    "sensors": ("timestamp_jitter_ms", "accel_noise_g_per_sqrt_hz", "accel_bias_g", "accel_scale_error",
                "gyro_noise_dps_per_sqrt_hz", "gyro_bias_dps", "gyro_bias_walk_dps_per_sqrt_s", "gyro_scale_error",
                "misalignment_deg", "mag_noise_ut", "mag_bias_ut", "mag_scale_error"),
    "stand": ("placement_deg",),
    "barometer": ("noise_hpa", "offset_hpa"),
    "ble": ("phone_offset_db",),
}


def error_free(params: PedestrianParams | None = None) -> PedestrianParams:
    """`params` (default PedestrianParams()) with every sensor error and the stand placement error zero.
    The motion, the hold, the magnetic field and the ADC's range and steps stay; so do the weather,
    the building's pressure jumps, the radio world (path loss, shadowing, fading, body and floor
    losses) and the beacons' own tx power errors (the world, not the phone)."""
    return zeroed(params or PedestrianParams(), _ERROR_FIELDS)


def describe(params: PedestrianParams | None = None) -> list[tuple[str, Any, str, str]]:
    """(dotted key, value, unit, source) of every figure, in declaration order."""
    return rows(params or PedestrianParams())


def params_with_overrides(overrides: dict[str, str], base: PedestrianParams | None = None) -> PedestrianParams:
    """Apply `--set key=value` overrides (dotted keys, string values) to `base` (default PedestrianParams()).
    ConfigError names the key when it is unknown, not a number of the right type, outside its range,
    or leaves a [min, max] pair reversed."""
    result = with_overrides(base or PedestrianParams(), overrides)
    check(result)
    return result


def check(params: PedestrianParams) -> None:
    """ConfigError when a [min, max] pair is reversed, a batch spans > 4 s, the floor is above the roof,
    or the barometer samples faster than the IMU."""
    check_pairs_and_batches(params)
    if params.magnetic.floor > params.magnetic.storeys:
        raise ConfigError(f"--set: magnetic.floor = {params.magnetic.floor} exceeds magnetic.storeys = "
                          f"{params.magnetic.storeys}")
    if params.barometer.rate_hz > params.sensors.rate_hz:
        raise ConfigError(f"--set: barometer.rate_hz = {params.barometer.rate_hz:g} exceeds sensors.rate_hz = "
                          f"{params.sensors.rate_hz:g} (pressure is sampled on the IMU's motion)")

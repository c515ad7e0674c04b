"""The navigation filter's parameters: its own model of its sensors, gates and checks
(never the plant's numbers; docs/estimation.md)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from tuavdefs.paramspec import Params, quantity

#: What the vehicle may fly on (EstimatorParams.kind).
ESTIMATOR_KINDS = ("ekf", "truth")
#: How the magnetometer is fused (EstimatorParams.mag_fusion): its three axes against the
#: Earth field with a bias state per axis (EKF2's 3-axis fusion, EKF3's MAG_CAL), or its
#: heading alone.
MAG_FUSIONS = ("3d", "heading")


class MagFusion(Enum):
    """How the magnetometer is fused (:data:`MAG_FUSIONS`, ``EstimatorParams.mag_fusion``)."""

    AXES_3D = "3d"
    """The field's three axes, with the magnetometer's bias estimated."""
    HEADING = "heading"
    """The heading alone."""



@dataclass(frozen=True)
class TetherLineParams(Params):
    """The winch's raw tether reading fused tightly, with the line's states
    (``[estimator.drag.tether_line]``: it needs the wind states the drag fusion makes
    observable; docs/estimation.md §11)."""

    enabled: bool = quantity(
        False, "", "fuse the winch's raw tether reading (length, tension, exit angles: "
        "DEBUG_FLOAT_ARRAY TETHER) against the line's model in the filter's wind states, "
        "with the line's weight and drag per metre and the guide arm's biases as states "
        "(tightly coupled; docs/estimation.md §11). The ground station's fix stays for the "
        "alignment, the line on the ground, and a flight that has not learnt the line's "
        "states with GNSS yet")
    gate_sigma: float = quantity(
        5.0, "1", "its gate: the innovation's Mahalanobis distance [standard deviations]",
        gt=0)
    weight_sigma_fraction: float = quantity(
        0.03, "1", "prior standard deviation of the line's weight per metre, as a fraction "
        "of the belief (the tether's linear density, as the winder's estimate would hold "
        "it)", gt=0, le=1)
    drag_sigma_fraction: float = quantity(
        0.25, "1", "prior standard deviation of the line's drag per metre, as a fraction of "
        "the belief (a cylinder's normal drag coefficient is 1.0-1.3)", gt=0, le=1)
    angle_bias_sigma_rad: float = quantity(
        3e-3, "rad", "prior standard deviation of each guide-arm angle's bias (the "
        "mounting's zero)", gt=0)
    length_noise_m: float = quantity(
        0.02, "m", "the paid-out length's noise (drum layers, the encoder)", ge=0)
    tension_noise_n: float = quantity(
        0.05, "N", "the load cell's tension noise (and the line's axial waves)", ge=0)
    tension_noise_fraction: float = quantity(
        0.02, "1", "the load cell's scale error", ge=0)
    angle_noise_rad: float = quantity(
        1.5e-3, "rad", "each exit angle's white noise (the arm's play, the encoder)", ge=0)
    model_sigma_m: float = quantity(
        0.2, "m", "the line model's error (a static shape for a line that sways and "
        "carries axial waves, the wind's profile), per axis, added to the reading's "
        "noise", gt=0)
    gust_sigma_m_s: float = quantity(
        2.0, "m/s", "how far the wind the line feels (along its length, through its own "
        "dynamics) may differ from the wind states (the vehicle's, from its drag): taken "
        "through the wind's columns into the reading's noise, per axis", ge=0)
    max_age_s: float = quantity(
        0.3, "s", "readings older than this on arrival are not fused", gt=0, le=1.0)
    min_tension_n: float = quantity(
        0.05, "N", "a reading of less tension says nothing of where the line ends (a "
        "slack line)", ge=0)
    ground_elevation_rad: float = quantity(
        0.03, "rad", "a line leaving the exit below this lies on the ground there: the "
        "ground station's fix covers it", ge=0)
    learn_time_s: float = quantity(
        3.0, "s", "without GNSS the reading is fused only after the line's states have "
        "been learnt with GNSS in the air this long (before that the ground station's "
        "fix, whose weight is the winder's estimate)", ge=0)
    wind_sigma_max_m_s: float = quantity(
        1.5, "m/s", "the line's states are learnt only while the wind states are known to "
        "this (each axis's standard deviation): the drag's bend has no slope at calm air, "
        "so a wind not yet learnt would pass into the line's weight", gt=0)
    learn_drag: bool = quantity(
        False, "", "learn the line's drag factor too (in at least drag_learn_wind_m_s of "
        "wind); false: it is considered, its prior's uncertainty in the noise. On the "
        "lumped truth in 6 m/s of moderate turbulence learning it took it to 0.6 and the "
        "60 s GNSS-loss hold from 0.55 m to 1.24 m: the wind states follow the gusts at "
        "the vehicle, the line the wind along it")
    drag_learn_wind_m_s: float = quantity(
        3.0, "m/s", "the line's drag factor is learnt only while the wind states say at "
        "least this much wind (c U^2 too small to tell below)", ge=0)
    steps: int = quantity(
        16, "1", "Runge-Kutta steps along the line in wind", ge=1, le=400)
    winder_weight: bool = quantity(
        False, "", "the line's weight belief (k_w's centre) is the winder's estimate each "
        "reading carries (DEBUG_FLOAT_ARRAY TETHER data[4]) once one came, moving with it "
        "while GNSS is fused; false: the parameter file's. On a line twice as heavy as "
        "believed it holds a GNSS loss in 6 m/s within 0.5 m instead of 2.1 m, but on a "
        "line as believed its 10-15 % error (the winder's estimate is made on the "
        "reported height, calm) doubles the loss's drift (docs/estimation.md §11)")


@dataclass(frozen=True)
class DragFusionParams(Params):
    """The drag's specific-force fusion and the wind states it makes observable
    (``[estimator.drag]``; docs/estimation.md §11)."""

    enabled: bool = quantity(
        True, "", "fuse the accelerometer's body x and y against the vehicle's drag (its "
        "ballistic and momentum-drag coefficients from the companion's vehicle model, as "
        "EKF3's EK3_DRAG_BCOEF_X/Y and EK3_DRAG_MCOEF) and the tether's pull, and estimate "
        "the horizontal wind as two states (EKF3's drag fusion; docs/estimation.md §11), "
        "fused into those states alone (nothing else moves): WIND is then the filter's")
    noise_m_s2: float = quantity(
        0.5, "m/s^2", "drag fusion: noise of the specific force's body x and y against the "
        "drag model (vibration, gusts, the model's and the tether pull's error; EKF3's "
        "EK3_DRAG_M_NSE)", gt=0)
    model_error_fraction: float = quantity(
        0.2, "1", "drag fusion: the drag model's error as a fraction of the drag it "
        "predicts (one standard deviation, added to the noise): its coefficients and mass "
        "are the companion's vehicle's, a real vehicle's differ (its mass +-20 % in "
        "robustness-gnss)", ge=0)
    pull_error_fraction: float = quantity(
        0.2, "1", "drag fusion: the tether pull's error as a fraction of the pull the "
        "line's model gives (one standard deviation, added to the noise): the line's "
        "weight and shape, the vehicle's mass it is divided by", ge=0)
    interval_s: float = quantity(
        0.1, "s", "drag fusion: the specific force averaged over this long, fused once per "
        "interval", gt=0, le=1.0)
    gate_sigma: float = quantity(
        5.0, "1", "drag fusion: innovation gate [standard deviations] (the two axes as one)",
        gt=0)
    correct_navigation: bool = quantity(
        False, "", "drag fusion: correct the velocity, attitude and accelerometer bias too "
        "(every column of its Jacobian) instead of the wind states alone: the drag is then "
        "a velocity aid in dead reckoning (hover-gnss-loss-windy's tight fusion holds its "
        "GNSS loss with it), but where the model is off (the truth's mass, the line's pull) "
        "it pulls the attitude (circle-gnss 0.0038 -> 0.0095 rad)")
    reset_s: float = quantity(
        1.0, "s", "drag fusion: rejected without a break this long, the wind states are "
        "reset to the wind the measurement says (the drag model inverted at the current "
        "attitude, velocity and pull; their prior's variance): the linearisation at a wind "
        "far off (0 at the start in 10 m/s) makes the innovation's variance too small to "
        "pass the gate", gt=0)
    wind_walk_m_s_sqrt_s: float = quantity(
        0.1, "m/s/sqrt(s)", "random walk of each horizontal wind state (the mean wind's "
        "drift; EKF3's EK3_WIND_P_NSE, as a density)", gt=0)
    wind_walk_height_rate_scale: float = quantity(
        1.0, "s/m", "the wind's walk grows by this times the vertical speed (the wind "
        "changes with height; EKF3's EK3_WIND_PSCALE)", ge=0)
    tether_wind_shear: float = quantity(
        1.0 / 7.0, "1", "drag fusion: the tether's pull from the winch's raw reading (length, "
        "tension, exit angles) is the line's model in the wind states taken at the vehicle's "
        "height and sheared below it with this power law (the ground station's belief, "
        "open terrain)", ge=0, le=1)
    tether_max_age_s: float = quantity(
        0.3, "s", "drag fusion: a raw tether reading older than this is not used (the "
        "windless tether model's pull instead)", gt=0)
    wind_sigma_m_s: float = quantity(
        5.0, "m/s", "prior standard deviation of each wind state when drag fusion starts "
        "(the wind starts at 0)", gt=0)
    tether_line: TetherLineParams = quantity(
        TetherLineParams(), "", "the winch's raw tether reading fused tightly against the "
        "line's model in these wind states, with the line's own states "
        "([estimator.drag.tether_line]; docs/estimation.md §11)")


@dataclass(frozen=True)
class TetherCheckParams(Params):
    """The tether fix checked against the GNSS (``[estimator.tether_fix.gnss_check]``): the
    slow error its covariance misses, measured against the receiver and taken off, the rest
    counted in its covariance (:mod:`companion.ekf.tether_check`; docs/estimation.md §10)."""

    enabled: bool = quantity(
        True, "", "compare each tether fix with the GNSS fix of its time and take the slow "
        "error the running mean of their difference reveals beyond the claims off the fix, "
        "what is left of it counted in its covariance (false: the fix as the ground station "
        "sends it)")
    bias_tau_s: float = quantity(
        20.0, "s", "time constant of the running mean of the fix's difference from the "
        "GNSS (its slow error: the line's weight, the wind's drag, the model's shape)", gt=0)
    dead_band_sigma: float = quantity(
        1.0, "1", "a mean difference within this many standard deviations of one "
        "difference's claimed spread (the fix's covariance and the receiver's accuracy) "
        "counts as consistent (the fix left as it is); beyond twice this it is taken off "
        "in full", gt=0)
    release_s: float = quantity(
        30.0, "s", "once the fix's slow error is taken off, the weight it is taken off with "
        "falls from 1 to 0 over this at the fastest (a receiver wandering towards the fix "
        "must not let the error back in)", gt=0)
    correlation_s: float = quantity(
        10.0, "s", "the fix's slow error is taken correlated over this: its excess is added "
        "as many times as fixes come within it (fused as white, n fixes of one error must "
        "not count as n independent ones)", gt=0)
    gnss_max_offset_s: float = quantity(
        0.3, "s", "a tether fix is compared with the GNSS fix nearest in measurement time, "
        "if within this", gt=0)
    gnss_hold_s: float = quantity(
        2.0, "s", "no GNSS fix compared within this: the slow error last measured is still "
        "taken off, its spread counted once (the fix is then the only position there is)",
        gt=0)


@dataclass(frozen=True)
class TetherFixParams(Params):
    """The ground station's tether fix as the filter takes it (``[estimator.tether_fix]``;
    docs/estimation.md §10)."""

    align_vel_sigma_m_s: float = quantity(
        0.5, "m/s", "velocity standard deviation when the filter aligns on a tether fix "
        "(no GNSS velocity): the vehicle is taken to be near rest", gt=0)
    gnss_check: TetherCheckParams = quantity(
        TetherCheckParams(), "", "the fix checked against the GNSS: the slow error its "
        "covariance misses taken off, the rest counted ([estimator.tether_fix.gnss_check])")


@dataclass(frozen=True)
class EstimatorParams(Params):
    """The navigation filter's own model of its sensors, its gates and its health checks
    (docs/estimation.md). Noise densities are of continuous white noise; random walks are
    the rate at which a bias wanders."""

    kind: str = quantity(
        "ekf", "", "what the vehicle flies on: ekf (this filter, on the sensors) or truth "
        "(the simulator's state as HIL_STATE_QUATERNION sends it: for comparison, and the "
        "paper's experiments, which feed the state back; ArduPilot's AHRS_EKF_TYPE 10)",
        choices=ESTIMATOR_KINDS)
    earth_field_ned_gauss: tuple[float, ...] = quantity(
        (0.2, 0.0, 0.45), "gauss", "the Earth's magnetic field at home (north, east, down), "
        "as a world magnetic model gives it", length=3)
    accel_offsets_m_s2: tuple[float, ...] = quantity(
        (0.0, 0.0, 0.0), "m/s^2", "the accelerometer's offsets (body FLU) its calibration "
        "found, taken off every reading (ArduPilot's INS_ACCOFFS_X/Y/Z)", length=3)
    imu_rate_hz: float = quantity(
        250.0, "Hz", "nominal IMU rate: sizes the delay buffer; a gap longer than 5 "
        "periods is integrated as 5 periods", gt=0, le=2000)
    gyro_noise_rad_s_sqrt_hz: float = quantity(
        3.0e-4, "rad/s/sqrt(Hz)", "gyro white-noise density (angle random walk)", gt=0)
    accel_noise_m_s2_sqrt_hz: float = quantity(
        4.0e-3, "m/s^2/sqrt(Hz)", "accelerometer white-noise density (velocity random "
        "walk)", gt=0)
    gyro_bias_walk_rad_s_sqrt_s: float = quantity(
        1.5e-4, "rad/s/sqrt(s)", "gyro bias random walk", ge=0)
    accel_bias_walk_m_s2_sqrt_s: float = quantity(
        3.0e-3, "m/s^2/sqrt(s)", "accelerometer bias random walk", ge=0)
    baro_offset_walk_m_sqrt_s: float = quantity(
        0.07, "m/sqrt(s)", "random walk of the barometer's height offset (an MS5611-class "
        "sensor's in-flight thermal and airflow drift, ~0.1 hPa = 0.8 m over ~300 s: "
        "0.8 sqrt(2/300); docs/estimation.md §10)", ge=0)
    gyro_bias_sigma_rad_s: float = quantity(
        0.01, "rad/s", "prior standard deviation of each gyro bias", gt=0)
    accel_bias_sigma_m_s2: float = quantity(
        0.15, "m/s^2", "prior standard deviation of each accelerometer bias", gt=0)
    baro_offset_sigma_m: float = quantity(
        0.5, "m", "prior standard deviation of the barometer's height offset (beyond the "
        "GNSS height's own accuracy)", gt=0)
    tilt_sigma_rad: float = quantity(
        0.02, "rad", "prior standard deviation of roll and pitch after alignment", gt=0)
    yaw_sigma_rad: float = quantity(
        0.15, "rad", "prior standard deviation of yaw after alignment", gt=0)
    align_time_s: float = quantity(
        1.0, "s", "how long accelerometer and magnetometer are averaged for the static "
        "alignment", gt=0, le=60)
    air_align_time_s: float = quantity(
        0.2, "s", "the alignment's averaging when the first GNSS fix finds the vehicle in "
        "the air (a simulation started in hover): it hovers open loop meanwhile", gt=0,
        le=60)
    gyro_calibration_at_rest: bool = quantity(
        True, "", "the gyro biases set at a still alignment on the ground to the mean rate "
        "read meanwhile (ArduPilot's INS_GYR_CAL 1, a gyro calibration at start-up; the "
        "filter then holds them to within the mean's noise); false: they start at 0 with "
        "gyro_bias_sigma_rad_s")
    align_max_accel_std_m_s2: float = quantity(
        1.0, "m/s^2", "alignment restarts while the specific force varies more than this "
        "(standard deviation of its magnitude): the vehicle is not still enough", gt=0)
    gnss_delay_s: float = quantity(
        0.1, "s", "age of a GNSS fix when it arrives: it is compared with the state that "
        "long ago", ge=0, le=0.5)
    output_tau_s: float = quantity(
        0.25, "s", "time constant over which the position and velocity the vehicle flies on "
        "take up each fusion's correction (EKF2's output predictor, EKF2_TAU_POS/VEL): the "
        "controllers see no step at each GNSS fix (0: at once)", ge=0)
    gnss_delay_uncertainty_s: float = quantity(
        0.05, "s", "how well gnss_delay_s is known: the fix's position noise grows by the "
        "speed times this", ge=0, le=0.5)
    gnss_pos_tau_s: float = quantity(
        0.0, "s", "correlation time of the receiver's position error (0: white, each fix "
        "independent, as EKF2 and EKF3 take it); above 0 the error is a Gauss-Markov state "
        "per axis, the fix's claimed accuracy its standard deviation, so that a slowly "
        "wandering receiver does not shrink the covariance below the error", ge=0, le=600)
    gnss_pos_correlated_fraction: float = quantity(
        0.9, "1", "with gnss_pos_tau_s > 0: the share of the claimed position variance that "
        "is the wander (the rest is white)", gt=0, lt=1)
    gnss_vel_noise_m_s: float = quantity(
        0.1, "m/s", "GNSS velocity noise (per axis; HIL_GPS carries no speed accuracy)",
        gt=0)
    gnss_pos_noise_min_m: float = quantity(
        0.01, "m", "floor on the GNSS position noise taken from the fix's eph/epv", gt=0)
    gnss_max_eph_m: float = quantity(
        5.0, "m", "fixes claiming a horizontal accuracy worse than this are not used", gt=0)
    gnss_fuse_height: bool = quantity(
        True, "", "fuse the GNSS height as well as the barometer's (the baro offset then "
        "follows it)")
    gnss_pos_gate_sigma: float = quantity(
        5.0, "1", "GNSS position innovation gate [standard deviations]", gt=0)
    gnss_vel_gate_sigma: float = quantity(
        5.0, "1", "GNSS velocity innovation gate [standard deviations]", gt=0)
    baro_noise_m: float = quantity(
        0.15, "m", "barometric height noise", gt=0)
    baro_delay_s: float = quantity(
        0.0, "s", "age of a barometer sample when it arrives", ge=0, le=0.5)
    baro_gate_sigma: float = quantity(
        5.0, "1", "barometric height innovation gate [standard deviations]", gt=0)
    mag_yaw_noise_rad: float = quantity(
        0.05, "rad", "magnetic heading noise", gt=0)
    mag_gate_sigma: float = quantity(
        3.0, "1", "magnetic heading innovation gate [standard deviations]", gt=0)
    mag_fusion: str = quantity(
        "3d", "", "3d: the field's three axes, with the magnetometer's bias (the vehicle's "
        "hard iron left after calibration) estimated; heading: the heading alone (the bias "
        "is then not estimated: it passes into the yaw)", choices=MAG_FUSIONS)
    mag_noise_gauss: float = quantity(
        0.01, "gauss", "3-axis fusion: noise of each axis (the sensor's noise, the field "
        "model's error and soft iron; EKF2's MAG_NOISE)", gt=0)
    mag_bias_sigma_gauss: float = quantity(
        0.01, "gauss", "3-axis fusion: prior standard deviation of each magnetometer bias",
        gt=0)
    mag_bias_walk_gauss_sqrt_s: float = quantity(
        1.0e-5, "gauss/sqrt(s)", "3-axis fusion: random walk of the magnetometer biases",
        ge=0)
    mag_3d_accel_m_s2: float = quantity(
        0.2, "m/s^2", "3-axis fusion only while the horizontal acceleration (low-passed "
        "over 1 s) reaches this, or the yaw rate mag_3d_yaw_rate_rad_s (EKF2's "
        "MAG_ACCLIM, MAG_YAWLIM): else the heading alone", gt=0)
    mag_3d_yaw_rate_rad_s: float = quantity(
        0.25, "rad/s", "3-axis fusion while the yaw rate (low-passed over 1 s) reaches this",
        gt=0)
    mag_3d_hold_s: float = quantity(
        5.0, "s", "3-axis fusion goes on this long after the last manoeuvre", ge=0)
    mag_yaw_only: bool = quantity(
        False, "", "heading fusion: the heading's Jacobian on yaw alone (EKF2's heading "
        "fusion: the magnetometer never corrects roll and pitch); False: its exact Jacobian, which "
        "includes the tilt error's effect on the heading through the field's inclination")
    baro_min_interval_s: float = quantity(
        0.02, "s", "barometer samples closer than this to the last fused one are skipped "
        "(the part's own output rate: an MS5611 gives about 50 Hz at full resolution)", ge=0)
    mag_min_interval_s: float = quantity(
        0.02, "s", "magnetometer samples closer than this to the last fused one are "
        "skipped", ge=0)
    gnss_timeout_s: float = quantity(
        1.0, "s", "no GNSS fused for this long: position and velocity flags drop, the "
        "filter reports no GNSS", gt=0)
    innovation_fail_s: float = quantity(
        2.0, "s", "an innovation test failing for this long makes the filter unhealthy",
        gt=0)
    gnss_reset_s: float = quantity(
        5.0, "s", "GNSS position rejected for this long (fixes still arriving): position "
        "and velocity are reset to the GNSS", gt=0)
    const_pos_after_s: float = quantity(
        10.0, "s", "no GNSS position for this long: constant-position mode (the held "
        "position fused with a large noise, to keep the attitude)", gt=0)
    const_pos_noise_m: float = quantity(
        10.0, "m", "noise of the held position in constant-position mode", gt=0)
    pos_variance_limit_m2: float = quantity(
        1.0e4, "m^2", "a position variance above this counts as a covariance blow-up",
        gt=0)
    converged_tilt_sigma_rad: float = quantity(
        0.02, "rad", "healthy needs roll and pitch standard deviations below this", gt=0)
    converged_yaw_sigma_rad: float = quantity(
        0.1, "rad", "healthy needs a yaw standard deviation below this", gt=0)
    tether_aid: bool = quantity(
        True, "", "fuse the winch's tether fix (ODOMETRY from the ground station) as a "
        "position source beside the GNSS (ArduPilot's ExternalNav, EK3_SRC1_POSXY 6)")
    tether_fix: TetherFixParams = quantity(
        TetherFixParams(), "", "the ground station's tether fix as the filter takes it: "
        "the alignment on it, its check against the GNSS ([estimator.tether_fix]; "
        "docs/estimation.md §10)")
    tether_noise_min_m: float = quantity(
        0.05, "m", "floor on each axis's standard deviation of a tether fix (added to its "
        "covariance)", gt=0)
    tether_gate_sigma: float = quantity(
        5.0, "1", "tether fix gate: its innovation's Mahalanobis distance [standard "
        "deviations]", gt=0)
    tether_max_delay_s: float = quantity(
        0.3, "s", "tether fixes older than this on arrival are not used (the delay buffer "
        "covers it)", gt=0, le=1.0)
    tether_timeout_s: float = quantity(
        1.0, "s", "no tether fix fused for this long: it no longer counts as a position "
        "source", gt=0)
    tether_reset_s: float = quantity(
        5.0, "s", "tether fixes rejected for this long without GNSS: the position is reset "
        "to the fix", gt=0)
    stationary_vel_noise_m_s: float = quantity(
        0.05, "m/s", "on the ground and disarmed (at rest on its gear): a zero velocity is "
        "fused with this noise on each axis (the stationary constraint EKF2 and EKF3 use on "
        "the ground without GNSS: the estimate does not drift)", gt=0)
    stationary_interval_s: float = quantity(
        0.1, "s", "the stationary constraint's interval", gt=0)
    arming_settle_s: float = quantity(
        2.0, "s", "arming is refused (PreArm: EKF settling) until the filter has been "
        "aligned this long: on the ground its first second takes in the gear's height and "
        "the tether's fix, which correct a consumer receiver's first fix by a metre (armed "
        "at once, such a vehicle took off from the wrong place and pulled a 2 m line "
        "taut); ArduPilot's EKF waits for 10 s of good GNSS", ge=0)
    ground_height_noise_m: float = quantity(
        0.05, "m", "on the ground and disarmed: the height the gear puts the vehicle at (the "
        "ground flat and level with the winder's, as the navigator's land detector takes "
        "it) is fused with the zero velocity, with this noise (0: not fused). A consumer "
        "receiver's height is metres off: without it a vehicle on the ground took itself "
        "to be 1.2 m up", ge=0)
    drag: DragFusionParams = quantity(
        DragFusionParams(), "", "the drag's specific-force fusion and the wind states "
        "(EKF3's drag fusion; docs/estimation.md §11)")

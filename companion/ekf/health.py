"""The filter's health, MAVLink's estimator flags and the status report, from its state,
its covariance and its aid sources' records (:func:`filter_status`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum, IntFlag

import numpy as np

from companion.ekf.aid_source import AidSources, AidSourceStatus
from companion.ekf.layout import IDX_P, IDX_TH, IDX_V, AidSourceKind
from companion.ekf.params import EstimatorParams
from tuavdefs.frames import Vec3


class FilterHealth(IntEnum):
    """What the filter's estimate is good for."""

    INITIALISING = 0
    """Not aligned yet: averaging for the static alignment, or waiting for a GNSS fix."""
    ALIGNED = 1
    """Initialised, no failure, but not converged yet (attitude uncertainty above the
    thresholds, or no GNSS fused yet)."""
    HEALTHY = 2
    """Converged and fusing GNSS."""
    UNHEALTHY = 3
    """Something failed: see :class:`HealthReason`."""


class HealthReason(IntFlag):
    """Why the filter is unhealthy (several can hold)."""

    NONE = 0
    NO_GNSS = 1
    """No GNSS position or velocity fused for ``gnss_timeout_s``."""
    GNSS_REJECTED = 2
    """The GNSS innovation test has failed for ``innovation_fail_s``."""
    BARO_REJECTED = 4
    """The barometer's innovation test has failed for ``innovation_fail_s``."""
    MAG_REJECTED = 8
    """The magnetic heading's innovation test has failed for ``innovation_fail_s``."""
    COVARIANCE = 16
    """A variance is negative or above ``pos_variance_limit_m2``."""
    NAN = 32
    """The state or the covariance is not finite (the filter must be reset)."""
    TETHER_REJECTED = 64
    """Without GNSS, the tether fix's innovation test has failed for
    ``innovation_fail_s``."""


class EstimatorFlags(IntFlag):
    """MAVLink's ``ESTIMATOR_STATUS_FLAGS`` (the same bit values)."""

    ATTITUDE = 1
    VELOCITY_HORIZ = 2
    VELOCITY_VERT = 4
    POS_HORIZ_REL = 8
    POS_HORIZ_ABS = 16
    POS_VERT_ABS = 32
    POS_VERT_AGL = 64
    CONST_POS_MODE = 128
    PRED_POS_HORIZ_REL = 256
    PRED_POS_HORIZ_ABS = 512
    GPS_GLITCH = 1024
    ACCEL_ERROR = 2048


class AidSource(IntFlag):
    """The measurements the filter fuses (within their timeouts)."""

    NONE = 0
    GNSS = 1
    """GNSS position."""
    TETHER = 2
    """The winch's tether fix."""
    BARO = 4
    MAG = 8
    PAD = 16
    """At rest on its gear (the stationary constraint fused): the position last fused
    holds, as nothing moves the vehicle."""


@dataclass(frozen=True)
class FilterStatus:
    """The filter's health, flags and checks at one time.

    The ``*_variance`` fields are what ArduPilot puts in ``EKF_STATUS_REPORT``: the square
    root of the latest test ratio of each measurement, |innovation| / (gate x its standard
    deviation), so 1.0 is at the gate and above 1 the measurement was rejected.
    """

    health: FilterHealth
    reasons: HealthReason
    flags: EstimatorFlags
    velocity_variance: float
    pos_horiz_variance: float
    pos_vert_variance: float
    compass_variance: float
    terrain_alt_variance: float
    pos_innovation_m: Vec3
    """Latest GNSS position innovation (measurement - delayed state) [m]."""
    vel_innovation_m_s: Vec3
    """Latest GNSS velocity innovation [m/s]."""
    baro_innovation_m: float
    mag_innovation_rad: float
    pos_sigma_m: Vec3
    """Standard deviations of the position estimate [m] (east, north, up)."""
    vel_sigma_m_s: Vec3
    attitude_sigma_rad: Vec3
    """Standard deviations of the attitude error about the inertial axes [rad]."""
    time_since_gnss_s: float
    """Since the last GNSS position fused [s] (inf: never)."""
    sources: AidSource = AidSource.NONE
    """What is fused now."""
    tether_variance: float = 0.0
    """sqrt of the latest tether measurement's test ratio (1.0 at its gate): the ground
    station's fix, or the raw reading fused tightly, whichever was tried last."""
    tether_innovation_m: Vec3 = (0.0, 0.0, 0.0)
    """Latest tether innovation (the fix, or the line's end, - the delayed state) [m]."""

    @property
    def healthy(self) -> bool:
        """Whether the estimate is fit to fly on."""
        return self.health == FilterHealth.HEALTHY



#: The health reason of each source whose innovation test fails for its ``fail_s`` (the
#: tether's only counts without GNSS position).
_REJECTED = ((AidSourceKind.GNSS_POS, HealthReason.GNSS_REJECTED),
             (AidSourceKind.BARO, HealthReason.BARO_REJECTED),
             (AidSourceKind.MAG, HealthReason.MAG_REJECTED))


def _sqrt0(v: float) -> float:
    return math.sqrt(max(v, 0.0))


def _vec3(v: np.ndarray) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


#: Leaving the pad without GNSS, how long [s] its position holds as a source at most: a
#: take-off dead-reckons from the pad on the IMU, baro and magnetometer, and on the
#: tether fixes as they come (a line lying slack on the ground gives none until the climb
#: lifts it, and while it lifts they come and go): on the lumped line they are back 7 s
#: after arming, 7 m up (docs/estimation.md §10, *The pad as a position source*).
PAD_HOLD_S = 15.0


def _pad_holds(t: float, src: AidSources) -> bool:
    """Whether the pad is a position source at ``t`` [s]: at rest on its gear (the
    stationary constraint fused) the position the alignment or the last fix gave holds, as
    the zero velocity keeps it from drifting; and leaving the pad it holds on the IMU's
    dead reckoning, and on the tether fixes the climb gives, until a GNSS position is fused
    again, for at most :data:`PAD_HOLD_S` (a line lying slack on the ground, friction holding
    it, pulls nothing at the exit: no tether fix until the climb lifts it, and while it
    lifts the fixes come and go)."""
    rest = src.zero_vel
    if rest.in_use(t):
        return True
    left = rest.time_last_fused
    return t - left <= PAD_HOLD_S and src.gnss_pos.time_last_fused < left


#: In flight, how long [s] after its last fused fix the tether still counts as a position
#: source, the IMU dead-reckoning from it (PX4 EKF2's ``EKF2_NOAID_TOUT``, 5 s): the
#: winch's fixes pause while the line goes slack for a moment (the vehicle moving in
#: towards the winder faster than the drum winds in, or passing over it, the load cell
#: reading less than the fix needs) or its fixes are rejected; 1-3 s gaps on the lumped
#: line in the GNSS-denied mission (docs/estimation.md §10, *Gaps in the fixes*).
TETHER_HOLD_S = 5.0


def _tether_holds(t: float, src: AidSources) -> bool:
    """Whether the last tether fix or raw reading fused still holds the position at ``t``
    [s]: within :data:`TETHER_HOLD_S` of it, no GNSS position fused since."""
    last = max(src.tether.time_last_fused, src.tether_line.time_last_fused)
    return t - last <= TETHER_HOLD_S and src.gnss_pos.time_last_fused < last


def latest_tether(src: AidSources) -> AidSourceStatus:
    """The tether's source last tried: the ground station's fix, or the raw reading fused
    tightly (docs/estimation.md §11): what reports the tether's innovation and test
    ratio."""
    line = src.tether_line
    return line if line.time_last_attempt > src.tether.time_last_attempt else src.tether


def filter_status(p: EstimatorParams, t: float, aligned: bool, x: np.ndarray, P: np.ndarray,
                  heading_innovation_rad: float, src: AidSources,
                  const_pos: bool) -> FilterStatus:
    """Health, flags and checks at ``t`` [s] of a filter with nominal state ``x`` and
    covariance ``P``, its sources' records ``src``, in constant-position mode or not."""
    var = np.diag(P)
    finite = bool(np.all(np.isfinite(x)) and np.all(np.isfinite(P)))
    reasons = HealthReason.NONE
    flags = EstimatorFlags(0)
    sources = AidSource.NONE
    health = FilterHealth.INITIALISING
    since_pos = t - src.gnss_pos.time_last_fused
    if aligned:
        if not finite:
            reasons |= HealthReason.NAN
        elif (np.any(var < 0.0)
              or float(np.max(var[IDX_P:IDX_P + 3])) > p.pos_variance_limit_m2):
            reasons |= HealthReason.COVARIANCE
        gnss_pos = src.gnss_pos.in_use(t)
        gnss_vel = src.gnss_vel.in_use(t)
        tether = src.tether.in_use(t) or src.tether_line.in_use(t)
        pad = _pad_holds(t, src)
        held = gnss_pos or tether or pad or _tether_holds(t, src)
        if not (held or gnss_vel):
            reasons |= HealthReason.NO_GNSS
        for kind, reason in _REJECTED:
            if src[kind].failing(t):
                reasons |= reason
        if not gnss_pos and latest_tether(src).failing(t):
            reasons |= HealthReason.TETHER_REJECTED
        if gnss_pos:
            sources |= AidSource.GNSS
        if tether:
            sources |= AidSource.TETHER
        if pad:
            sources |= AidSource.PAD
        baro = src.baro.in_use(t)
        if baro:
            sources |= AidSource.BARO
        if src.mag.in_use(t):
            sources |= AidSource.MAG
        vert = baro or src.gnss_hgt.in_use(t)
        if finite:
            flags |= EstimatorFlags.ATTITUDE
            if gnss_vel or held:   # a position source makes velocity observable
                flags |= EstimatorFlags.VELOCITY_HORIZ | EstimatorFlags.VELOCITY_VERT
            elif vert:
                flags |= EstimatorFlags.VELOCITY_VERT
            if held:
                # the fix is relative to the winder, whose global position is home
                flags |= EstimatorFlags.POS_HORIZ_REL | EstimatorFlags.POS_HORIZ_ABS
            if vert:
                flags |= EstimatorFlags.POS_VERT_ABS
        if const_pos:
            flags |= EstimatorFlags.CONST_POS_MODE
        if t - src.gnss_pos.time_last_attempt <= p.gnss_timeout_s:
            flags |= EstimatorFlags.PRED_POS_HORIZ_REL | EstimatorFlags.PRED_POS_HORIZ_ABS
        if src.gnss_pos.rejected:
            flags |= EstimatorFlags.GPS_GLITCH
        if reasons:
            health = FilterHealth.UNHEALTHY
        elif (held
              and max(var[IDX_TH], var[IDX_TH + 1]) < p.converged_tilt_sigma_rad ** 2
              and var[IDX_TH + 2] < p.converged_yaw_sigma_rad ** 2):
            health = FilterHealth.HEALTHY
        else:
            health = FilterHealth.ALIGNED
    sd = np.sqrt(np.maximum(var, 0.0))
    teth = latest_tether(src)
    pos = (src.gnss_pos if AidSource.GNSS in sources or AidSource.TETHER not in sources
           else teth)
    gp, gh = src.gnss_pos.innovation, src.gnss_hgt.innovation
    return FilterStatus(
        health, reasons, flags,
        velocity_variance=_sqrt0(src.gnss_vel.test_ratio),
        pos_horiz_variance=_sqrt0(pos.test_ratio),
        pos_vert_variance=_sqrt0(src.baro.test_ratio),
        compass_variance=_sqrt0(src.mag.test_ratio),
        terrain_alt_variance=0.0,
        pos_innovation_m=(gp[0], gp[1], gh[0]),
        vel_innovation_m_s=src.gnss_vel.innovation,
        baro_innovation_m=src.baro.innovation[0],
        mag_innovation_rad=float(heading_innovation_rad),
        pos_sigma_m=_vec3(sd[IDX_P:IDX_P + 3]), vel_sigma_m_s=_vec3(sd[IDX_V:IDX_V + 3]),
        attitude_sigma_rad=_vec3(sd[IDX_TH:IDX_TH + 3]),
        time_since_gnss_s=since_pos if aligned else math.inf,
        sources=sources,
        tether_variance=_sqrt0(teth.test_ratio),
        tether_innovation_m=teth.innovation)

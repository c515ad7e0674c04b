"""The tether governor: the one place of the policy that keeps the vehicle within the
room the winder's line gives (docs/control.md §3).

It reads the reference the navigator flies (position, velocity, acceleration), the
vehicle's estimated position and velocity with the estimate's standard deviation, and what
the winch reports of its tether (paid-out length, line speed, whether its drum is braked,
the tension); it gives:

- the limit [m] from the winder the stopping points keep within (:attr:`TetherGovernor.limit_m`)
  and the length targets may use (:attr:`TetherGovernor.reach_length_m`);
- the slowing of a leg, as the rate of the leg's clock (:meth:`TetherGovernor.slow_clock`,
  :meth:`TetherGovernor.scaled`), and the speed cap of a velocity target
  (:meth:`TetherGovernor.velocity_cap`);
- the brake decision (:meth:`TetherGovernor.check`: fly on, at rest, brake) and the brake
  itself (:class:`BrakeRef`); at rest, whether a stopped plan may resume
  (:meth:`TetherGovernor.may_resume`) or where a vehicle beyond a braked drum moves in
  (:meth:`TetherGovernor.move_in_target`);
- where an over-tension that has lasted moves the vehicle, towards the winder
  (:meth:`TetherGovernor.over_tension`).

What a paused plan is, and how it resumes, is the plan's (:mod:`companion.plan`).
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple, Protocol

from companion.reference import RefSample, _new
from companion.statustext import Notice, TextKind
from tuavdefs.jit import Signature, entry_point, njit, vec

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)


class GovernorSettings(Protocol):
    """The parameters the governor reads (``companion.navigation.NavigationParams`` has
    them, as the ``[navigation]`` TOML section and the TUAV_TETH_* / TUAV_TENS_* parameters
    name them)."""

    @property
    def tether_governor(self) -> int:
        """A :class:`GovernorMode` value."""
    @property
    def tether_brake_acc_m_s2(self) -> float:
        """The deceleration it brakes at and assumes of the vehicle [m/s^2]."""
    @property
    def tether_latency_s(self) -> float:
        """How long the vehicle goes on at its speed before it follows [s]."""
    @property
    def tether_margin_m(self) -> float:
        """Length the stopping point keeps short of the reported length [m]."""
    @property
    def tether_sigma_k(self) -> float:
        """Multiples of the estimate's position standard deviation added [1]."""
    @property
    def tension_limit_n(self) -> float:
        """Tension above which the vehicle moves towards the winder [N]."""
    @property
    def tension_time_s(self) -> float:
        """How long the tension must stay above the limit first [s]."""
    @property
    def tension_step_m(self) -> float:
        """How far towards the winder each over-tension move goes [m]."""


class GovernorMode(IntEnum):
    """What the governor counts on from the winder (``tether_governor``,
    TUAV_TETH_GOV)."""

    OFF = 0         #: no governor
    LENGTH = 1      #: the winder tracks a length (its law "paper"): the room is the
                    #: length it reported, where it may stop at any moment
    TENSION = 2     #: the winder holds the line's tension (its law "tension"): a free
                    #: drum pays out whatever the vehicle pulls, so the room is the whole
                    #: tether, or the length a braked drum holds


#: The tether governor's jerk while its brake builds up [m/s^3].
TETHER_BRAKE_JERK_M_S3 = 20.0
#: A drum whose line moves slower than this [m/s] has caught up with its reference.
TETHER_CAUGHT_UP_M_S = 0.02
#: Outward speed [m/s] from which the governor keeps its whole margin for the
#: estimate's uncertainty (in proportion below).
GOVERNOR_SIGMA_SPEED_M_S = 0.5
#: Room [m] the governor wants between the vehicle's distance and its limit before it
#: resumes what it stopped (or that it moves in to, when beyond).
TETHER_RESUME_ROOM_M = 0.1
#: The governor's slowing of a leg (its clock): the time [s] its deceleration's build-up
#: loses (a brake at tether_brake_acc_m_s2 reached at TETHER_BRAKE_JERK_M_S3, 3/20 s,
#: loses half of it; rounded up), added to the vehicle's latency in the speed limit.
GOVERNOR_SLOW_RAMP_S = 0.1
#: Largest deceleration [m/s^2] and jerk [m/s^3] the slowing of a leg puts on the
#: reference, and the acceleration [m/s^2] with which it gives the speed back.
GOVERNOR_SLOW_ACC_M_S2 = 2.0
GOVERNOR_SLOW_JERK_M_S3 = 8.0
GOVERNOR_RESUME_ACC_M_S2 = 0.8
#: Bandwidth [rad/s] of the leg clock's rate following its limit (critically damped).
GOVERNOR_CLOCK_OMEGA = 4.0
#: How far ahead [s] the slowing looks at the leg's own speed (its acceleration on).
GOVERNOR_LOOKAHEAD_S = 0.5
#: Length [m] the slowing keeps inside the braking limit (in full from an outward speed
#: of GOVERNOR_SIGMA_SPEED_M_S, in proportion below), so that in a flight without a fault
#: the brake is never needed.
GOVERNOR_SLOW_MARGIN_M = 0.02
#: The leg clock's rate limit below which a slowing is said, and the rate the clock and
#: its limit must both be back above before the next one is (a hysteresis: a clock
#: returning critically damped creeps towards 1 without ever rounding to it).
GOVERNOR_SLOWING_SAID_BELOW = 0.999
GOVERNOR_SLOWING_OVER_ABOVE = 0.9995


@njit
def governed_speed_m_s(pos: Vec3, direction: Vec3, limit_m: float, latency_s: float,
                       acc_m_s2: float, margin_s: float = 0.0) -> float:
    """Largest speed [m/s] along the unit ``direction`` at ``pos`` [m] from which a stop
    (``latency_s`` [s] at that speed, then braking at ``acc_m_s2`` [m/s^2]) stays within
    ``limit_m`` [m] of the origin (the winder): ``v t + v^2 / 2a <= r`` with ``r`` the
    distance along ``direction`` to that sphere (ArduPilot's fence idea, sqrt(2 a r),
    with a latency). ``math.inf`` for a motion inward from beyond it. A margin growing
    with the speed, the sphere ``margin_s`` [s] times ``v`` smaller, shortens ``r`` by
    ``dr/dlimit margin_s v`` (to first order): it is that much more latency."""
    d2 = pos[0] * pos[0] + pos[1] * pos[1] + pos[2] * pos[2]
    dc = pos[0] * direction[0] + pos[1] * direction[1] + pos[2] * direction[2]
    if d2 >= limit_m * limit_m:          # on or beyond the limit
        return math.inf if dc < 0.0 else 0.0
    root = math.sqrt(max(limit_m * limit_m - d2 + dc * dc, 0.0))
    r = -dc + root
    if margin_s > 0.0 and root > 0.0:
        latency_s += margin_s * limit_m / root
    return acc_m_s2 * (-latency_s + math.sqrt(latency_s * latency_s + 2.0 * r / acc_m_s2))


@njit
def slow_target(v: Vec3, p: Vec3, a: Vec3, pe: Vec3, ve: Vec3, s: float, limit_m: float,
                margin_m: float, latency_s: float, acc_m_s2: float,
                winch_speed_m_s: float) -> float:
    """The rate in [0, 1] the slowing asks of a leg's clock
    (:meth:`TetherGovernor.slow_clock`) for the leg's nominal velocity ``v`` [m/s],
    position ``p`` [m] and acceleration ``a`` [m/s^2], the vehicle's estimated position
    ``pe`` [m] and velocity ``ve`` [m/s], the clock's rate ``s`` now, the governor's limit
    ``limit_m`` [m] and its full margin ``margin_m`` [m], the latency [s] and deceleration
    [m/s^2] of the stop, and the line speed [m/s] the look-ahead counts on; 1 for a leg
    not moving."""
    speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if not speed > 1e-3:
        return 1.0
    u = (v[0] / speed, v[1] / speed, v[2] / speed)
    lim = limit_m
    d = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    d_e = math.sqrt(pe[0] * pe[0] + pe[1] * pe[1] + pe[2] * pe[2])
    ve_out = 0.0
    if d_e > 0:
        ve_out = max((ve[0] * pe[0] + ve[1] * pe[1] + ve[2] * pe[2]) / d_e, 0.0)
    # the margin M min(1, v_out / v_s) (v_s = GOVERNOR_SIGMA_SPEED_M_S) at the speed v the
    # leg is allowed (its outward part v cos, or the vehicle's): at most M, and at most
    # M ve_out / v_s plus M cos / v_s [s] per m/s of v; the larger speed either allows
    # (counted at the speed it has now, the margin grew as the leg sped up, faster than
    # the slowing followed)
    m_full = margin_m
    cos_out = (max((v[0] * p[0] + v[1] * p[1] + v[2] * p[2]) / (d * speed), 0.0)
               if d > 0 else 1.0)
    lim_v = lim - m_full * ve_out / GOVERNOR_SIGMA_SPEED_M_S
    m_s = m_full * cos_out / GOVERNOR_SIGMA_SPEED_M_S
    lim -= m_full
    lat, ab = latency_s, acc_m_s2
    v_max = max(min(governed_speed_m_s(p, u, lim, lat, ab, 0.0),
                    governed_speed_m_s(pe, u, lim, lat, ab, 0.0)),
                min(governed_speed_m_s(p, u, lim_v, lat, ab, m_s),
                    governed_speed_m_s(pe, u, lim_v, lat, ab, m_s)))
    # and GOVERNOR_LOOKAHEAD_S on: the leg's speed, direction and place then
    h = GOVERNOR_LOOKAHEAD_S
    ahead = speed + h * max(a[0] * u[0] + a[1] * u[1] + a[2] * u[2], 0.0)
    target = min(1.0, v_max / ahead)
    va = (v[0] + a[0] * h, v[1] + a[1] * h, v[2] + a[2] * h)
    sa = math.sqrt(va[0] * va[0] + va[1] * va[1] + va[2] * va[2])
    if sa > 1e-3:
        ua = (va[0] / sa, va[1] / sa, va[2] / sa)
        pa = (p[0] + v[0] * s * h, p[1] + v[1] * s * h, p[2] + v[2] * s * h)
        # the limit then: the length the winch pays out meanwhile at its reported line
        # speed, at most what the move gains in distance (a braked drum pays out
        # nothing); the place then against the length now counted the same run twice
        gain = math.sqrt(pa[0] * pa[0] + pa[1] * pa[1] + pa[2] * pa[2]) - d
        more = max(0.0, min(h * winch_speed_m_s, gain))
        target = min(target, max(
            governed_speed_m_s(pa, ua, lim + more, lat, ab, 0.0),
            governed_speed_m_s(pa, ua, lim_v + more, lat, ab, m_s)) / sa)
    return target


class BrakeRef:
    """The tether governor's stop: the reference's speed brought to rest along its
    direction, the deceleration ``acc`` [m/s^2] reached at ``jerk`` [m/s^3] from the
    acceleration it had along it; the position integrates it."""

    def __init__(self, ref: RefSample, acc: float, jerk: float) -> None:
        self.pos = list(ref.pos_m)
        v = ref.vel_m_s
        s = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        self.dir: Vec3 = (v[0] / s, v[1] / s, v[2] / s) if s > 1e-9 else _ZERO3
        self.speed = s if s > 1e-9 else 0.0
        self.acc_along = sum(ref.acc_m_s2[i] * self.dir[i] for i in range(3))
        self.acc_max = acc
        self.jerk_max = jerk
        self.yaw = ref.yaw_rad

    @property
    def stopped(self) -> bool:
        """Whether the reference is at rest."""
        return self.speed <= 0.0

    def step(self, dt: float) -> RefSample:
        d = self.dir
        if self.speed <= 0.0:
            return RefSample(tuple(self.pos), _ZERO3, _ZERO3, _ZERO3,  # type: ignore
                             self.yaw, 0.0)
        a = max(self.acc_along - self.jerk_max * dt, -self.acc_max)
        jerk = (a - self.acc_along) / dt
        speed = self.speed + a * dt
        if speed <= 0.0:         # at rest within this period
            step_m = 0.5 * self.speed * self.speed / max(-a, 1e-9)
            speed, a, jerk = 0.0, 0.0, 0.0
        else:
            step_m = 0.5 * (self.speed + speed) * dt
        self.pos = [self.pos[i] + d[i] * step_m for i in range(3)]
        self.speed, self.acc_along = speed, a
        return RefSample(tuple(self.pos), tuple(d[i] * speed for i in range(3)),  # type: ignore
                         tuple(d[i] * a for i in range(3)), tuple(d[i] * jerk for i in range(3)),
                         self.yaw, 0.0)


@njit
def brake_distance_m(speed_m_s: float, acc_along_m_s2: float, acc_m_s2: float,
                     jerk_m_s3: float) -> float:
    """An upper bound of the distance [m] a :class:`BrakeRef` runs from ``speed_m_s``
    [m/s] with ``acc_along_m_s2`` [m/s^2] along its motion: the build-up of the brake at
    ``jerk_m_s3`` [m/s^3] at the speed and acceleration it had, then ``v^2 / 2a`` at
    ``acc_m_s2``."""
    if speed_m_s <= 0.0:
        return 0.0
    a0 = max(acc_along_m_s2, 0.0)
    ramp = (a0 + acc_m_s2) / jerk_m_s3
    v1 = speed_m_s + 0.5 * a0 * ramp
    return speed_m_s * ramp + 0.5 * a0 * ramp * ramp + v1 * v1 / (2.0 * acc_m_s2)




#: Seconds between two over-tension moves while the over-tension lasts.
TENSION_REPEAT_S = 2.0
#: A winding-in drum's reported length is taken where it will be this long on [s] (the
#: report's age and the drum's stop, as the winder's CAN period leaves them).
WIND_IN_LEAD_S = 0.15


class Verdict(IntEnum):
    """The governor's decision on a period's reference (:meth:`TetherGovernor.check`; the
    code :func:`check_kernel` returns)."""

    FLY = 0          # fly it as it is
    AT_REST = 1      # at rest: a paused plan may resume, or the vehicle move in
    BRAKE = 2        # its stopping point passes the limit: brake now


#: the verdicts by code (a look-up, cheaper than the enum's call every period), and the
#: codes as the kernels return them
_VERDICTS = tuple(Verdict)
_FLY, _AT_REST, _BRAKE = int(Verdict.FLY), int(Verdict.AT_REST), int(Verdict.BRAKE)


class Decision(NamedTuple):
    """:meth:`TetherGovernor.check`'s answer: the verdict and the limit [m] it tested
    against (with the estimate's margin when moving outward)."""

    verdict: Verdict
    limit_m: float


#: :func:`slow_clock_kernel`'s and :func:`check_kernel`'s period inputs (a tuple of
#: floats), by index: the reference's (or a leg's nominal sample's) position [m],
#: velocity [m/s] and acceleration [m/s^2], the vehicle's estimated position [m] and
#: velocity [m/s], the estimate's position standard deviation [m], the leg clock's rate
#: and its rate of change [1/s], the period [s].
(GP_POS, GP_VEL, GP_ACC, GP_EST_POS, GP_EST_VEL, GP_SIGMA, GP_S, GP_SD, GP_DT,
 N_GP) = (0, 3, 6, 9, 12, 15, 16, 17, 18, 19)
#: The governor's room (a tuple of floats, made again only when the winch reports or the
#: parameters change), by index: :attr:`TetherGovernor.limit_m` [m], ``tether_sigma_k``
#: [1], ``tether_latency_s`` [s], ``tether_brake_acc_m_s2`` [m/s^2], the look-ahead's
#: line speed (:meth:`TetherGovernor.lookahead_winch_speed_m_s`) [m/s].
GR_LIMIT, GR_SIGMA_K, GR_LATENCY, GR_BRAKE_ACC, GR_WINCH_SPEED, N_GR = range(6)
#: The kernels' arguments, declared once.
GOVERNOR_SIGNATURE = Signature(vec(N_GP), vec(N_GR))


@njit
def slow_rate_kernel(period: tuple[float, ...], room: tuple[float, ...]) -> tuple[float, float]:
    """The rate in [0, 1] the slowing asks of a leg's clock for its sample in ``period``
    (:data:`GP_*`: the velocity there is the one counted, the leg's now or ahead) within
    the ``room`` (:data:`GR_*`), and the leg's speed [m/s]: :func:`slow_target` with the
    margin ``GOVERNOR_SLOW_MARGIN_M`` plus ``tether_sigma_k`` standard deviations, the
    latency ``tether_latency_s`` + :data:`GOVERNOR_SLOW_RAMP_S`; 1 for a leg not
    moving."""
    v = (period[GP_VEL], period[GP_VEL + 1], period[GP_VEL + 2])
    speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if not speed > 1e-3:
        return 1.0, speed
    return slow_target(
        v, (period[GP_POS], period[GP_POS + 1], period[GP_POS + 2]),
        (period[GP_ACC], period[GP_ACC + 1], period[GP_ACC + 2]),
        (period[GP_EST_POS], period[GP_EST_POS + 1], period[GP_EST_POS + 2]),
        (period[GP_EST_VEL], period[GP_EST_VEL + 1], period[GP_EST_VEL + 2]),
        period[GP_S], room[GR_LIMIT],
        GOVERNOR_SLOW_MARGIN_M + room[GR_SIGMA_K] * period[GP_SIGMA],
        room[GR_LATENCY] + GOVERNOR_SLOW_RAMP_S, room[GR_BRAKE_ACC],
        room[GR_WINCH_SPEED]), speed


@njit
def slow_clock_kernel(period: tuple[float, ...], room: tuple[float, ...]
                      ) -> tuple[float, float, float, float]:
    """One period (``period[GP_DT]`` [s]) of the leg clock's slowing
    (:meth:`TetherGovernor.slow_clock`) from its rate s and rate of change sd in
    ``period``: s follows :func:`slow_rate_kernel`'s target critically damped
    (:data:`GOVERNOR_CLOCK_OMEGA`), its effect on the reference limited to
    :data:`GOVERNOR_SLOW_JERK_M_S3` and :data:`GOVERNOR_SLOW_ACC_M_S2` (giving speed back
    at :data:`GOVERNOR_RESUME_ACC_M_S2`). Returns (s, sd after it, the target, the time
    [s] the clock fell behind the vehicle's in it)."""
    s, sd, dt = period[GP_S], period[GP_SD], period[GP_DT]
    target, speed = slow_rate_kernel(period, room)
    vs = max(speed, 0.1)
    w = GOVERNOR_CLOCK_OMEGA
    jm = GOVERNOR_SLOW_JERK_M_S3 / vs
    sdd = max(-jm, min(jm, w * w * (target - s) - 2.0 * w * sd))
    sd_new = max(-GOVERNOR_SLOW_ACC_M_S2 / vs,
                 min(GOVERNOR_RESUME_ACC_M_S2 / vs, sd + sdd * dt))
    s_new = s + 0.5 * (sd + sd_new) * dt
    if s_new >= 1.0:
        s_new, sd_new = 1.0, 0.0
    elif s_new <= 0.0:
        s_new, sd_new = 0.0, 0.0
    return s_new, sd_new, target, (1.0 - 0.5 * (s + s_new)) * dt


@njit
def check_kernel(period: tuple[float, ...], room: tuple[float, ...]) -> tuple[int, float]:
    """The brake decision (:meth:`TetherGovernor.check`) on the reference and the vehicle's
    estimate in ``period`` (:data:`GP_*`; the clock's entries unused) within the ``room``
    (:data:`GR_*`): (the :class:`Verdict`'s code, the limit [m] tested against)."""
    p = (period[GP_POS], period[GP_POS + 1], period[GP_POS + 2])
    v = (period[GP_VEL], period[GP_VEL + 1], period[GP_VEL + 2])
    a = (period[GP_ACC], period[GP_ACC + 1], period[GP_ACC + 2])
    lim = room[GR_LIMIT]
    d_ref = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if speed < 1e-3:
        return _AT_REST, lim
    if v[2] < 0.0 and v[0] * p[0] + v[1] * p[1] + v[2] * p[2] <= 0.0:
        # a descent coming closer to the winder: the line only gets shorter
        return _FLY, lim
    u = (v[0] / speed, v[1] / speed, v[2] / speed)
    ab, jerk = room[GR_BRAKE_ACC], TETHER_BRAKE_JERK_M_S3
    run = brake_distance_m(speed, a[0] * u[0] + a[1] * u[1] + a[2] * u[2], ab, jerk)
    sx, sy, sz = p[0] + u[0] * run, p[1] + u[1] * run, p[2] + u[2] * run
    stop = math.sqrt(sx * sx + sy * sy + sz * sz)
    if stop <= d_ref + 1e-4:          # not outward: nothing to govern
        return _FLY, lim
    v_out = (v[0] * p[0] + v[1] * p[1] + v[2] * p[2]) / d_ref if d_ref > 0 else speed
    pe = (period[GP_EST_POS], period[GP_EST_POS + 1], period[GP_EST_POS + 2])
    ve = (period[GP_EST_VEL], period[GP_EST_VEL + 1], period[GP_EST_VEL + 2])
    se = math.sqrt(ve[0] * ve[0] + ve[1] * ve[1] + ve[2] * ve[2])
    d_e = math.sqrt(pe[0] * pe[0] + pe[1] * pe[1] + pe[2] * pe[2])
    if se > 1e-6:       # the vehicle's own stopping point, if it is outward too
        run_e = se * room[GR_LATENCY] + se * se / (2.0 * ab)
        sx = pe[0] + ve[0] / se * run_e
        sy = pe[1] + ve[1] / se * run_e
        sz = pe[2] + ve[2] / se * run_e
        stop = max(stop, math.sqrt(sx * sx + sy * sy + sz * sz))
        if d_e > 0:
            v_out = max(v_out, (ve[0] * pe[0] + ve[1] * pe[1] + ve[2] * pe[2]) / d_e)
    # the estimate's uncertainty as margin, in full from an outward speed of
    # GOVERNOR_SIGMA_SPEED_M_S (at rest a margin beyond the winder's least slack
    # would forbid every move outward)
    lim -= (room[GR_SIGMA_K] * period[GP_SIGMA]
            * min(1.0, max(v_out, 0.0) / GOVERNOR_SIGMA_SPEED_M_S))
    if stop <= lim:
        return _FLY, lim
    return _BRAKE, lim


def towards_winder(pos: Vec3, keep_m: float, floor_m: float) -> Vec3:
    """The point [m] on the line from the winder to ``pos`` [m] ``keep_m`` [m] from the
    winder (the winder itself when ``keep_m`` is 0 or less), but no lower than
    ``floor_m`` [m] unless ``pos`` is already lower."""
    x, y, z = pos
    d = math.sqrt(x * x + y * y + z * z)
    k = max(keep_m, 0.0) / d if d > 0 else 0.0
    return (k * x, k * y, max(k * z, min(z, floor_m)))


class TetherGovernor:
    """The tether governor's state and decisions (module docstring): the winch's last
    report, the leg clock's slowing (rate ``s``, its rate of change ``sd``, the time
    ``clock_lag`` [s] the clock has fallen behind the vehicle's), the brake, and the
    over-tension's timing.

    ``tether_length_m`` is the length on the full drum [m]; ``gear_height_m`` the height
    [m] of the centre of mass on the gear (a move in keeps 1 m above it).
    """

    def __init__(self, params: GovernorSettings, tether_length_m: float,
                 gear_height_m: float) -> None:
        self.p = params
        self.tether_length_m = tether_length_m
        self.gear_height_m = gear_height_m
        self.locked_length_m: float | None = None   # the drum's length while braked [m]
        self.winch_length_m: float | None = None    # the last reported length [m]
        self.winch_speed_m_s = 0.0                  # and line speed [m/s]
        self.s, self.sd = 1.0, 0.0                  # the leg clock's rate and its change
        self.clock_lag = 0.0                        # [s] the leg clock is behind
        self.slowed = False                         # said once per slowing
        self.brake: BrakeRef | None = None          # the stop under way
        self._over_t: float | None = None           # since when over the tension limit [s]
        self._tension_move_t = -math.inf            # the last over-tension move [s]
        self._room: tuple[float, ...] | None = None  # the kernels' room (GR_*), or stale
        # the compiled decisions, called without numba's dispatch
        self._slow_clock = entry_point(slow_clock_kernel, GOVERNOR_SIGNATURE)
        self._slow_rate = entry_point(slow_rate_kernel, GOVERNOR_SIGNATURE)
        self._check = entry_point(check_kernel, GOVERNOR_SIGNATURE)

    @property
    def p(self) -> GovernorSettings:
        """The parameters."""
        return self._p

    @p.setter
    def p(self, params: GovernorSettings) -> None:
        self._p = params
        self._room = None
        #: what the governor counts on from the winder (``tether_governor``); made once
        #: per parameter set (they are frozen), read every period
        self.mode = GovernorMode(params.tether_governor)
        #: whether the governor is on (``tether_governor`` not OFF)
        self.enabled = self.mode is not GovernorMode.OFF

    @property
    def room(self) -> tuple[float, ...]:
        """The kernels' room (:data:`GR_*`): the limit and the parameters they read, made
        again after a report of the winch or new parameters."""
        room = self._room
        if room is None:
            p = self._p
            room = self._room = (
                float(self.limit_m), float(p.tether_sigma_k), float(p.tether_latency_s),
                float(p.tether_brake_acc_m_s2), float(self.lookahead_winch_speed_m_s()))
        return room

    # ----- what the winch reports

    def report(self, length_m: float, braked: bool, speed_m_s: float | None) -> None:
        """The winch's report: paid-out length [m], whether its drum is braked, its line
        speed [m/s] (None: unchanged)."""
        self.locked_length_m = (float(length_m) if braked and math.isfinite(length_m)
                                else None)
        if math.isfinite(length_m):
            self.winch_length_m = float(length_m)
        if speed_m_s is not None and math.isfinite(speed_m_s):
            self.winch_speed_m_s = float(speed_m_s)
        self._room = None

    def over_tension(self, t: float, tension_n: float | None, may_move: bool,
                     ref_pos: Vec3) -> Vec3 | None:
        """Where the vehicle, its reference at ``ref_pos`` [m], moves now (at ``t`` [s])
        for an over-tension: ``tension_step_m`` towards the winder (no lower than 1 m above
        the gear unless already lower) when every report for ``tension_time_s`` has said
        the tension [N] (None: unknown) is above ``tension_limit_n``, the vehicle
        ``may_move``, and the last such move is :data:`TENSION_REPEAT_S` old; else None."""
        if tension_n is None or not tension_n > self.p.tension_limit_n:
            self._over_t = None
            return None
        if self._over_t is None:
            self._over_t = t
        if (not may_move or t - self._over_t < self.p.tension_time_s
                or t - self._tension_move_t < TENSION_REPEAT_S):
            return None
        self._tension_move_t = t
        x, y, z = ref_pos
        d = math.sqrt(x * x + y * y + z * z)
        return towards_winder((x, y, z), d - self.p.tension_step_m, self.gear_height_m + 1.0)

    @property
    def reach_length_m(self) -> float:
        """The tether length [m] targets may use: the whole tether, or the length a braked
        drum has paid out (LOCK, HOLD, a lost winder: it pays out no more)."""
        length = self.tether_length_m
        if self.locked_length_m is not None:
            length = min(length, self.locked_length_m)
        return length

    @property
    def limit_m(self) -> float:
        """Distance [m] from the winder the governor keeps the stopping point of the
        reference and of the vehicle within: with :attr:`GovernorMode.LENGTH`, the length
        the drum last reported (it may stop there at any moment: a snag, a lost bus's
        watchdog; while winding in, where it would be :data:`WIND_IN_LEAD_S` on), or the
        whole tether before any report; with :attr:`GovernorMode.TENSION` the whole
        tether (a free drum renders to the pull: its speed follows the vehicle's
        reported radial speed, docs/control.md §8); a braked drum's length in both; less
        ``tether_margin_m`` (moving outward, :meth:`check` keeps ``tether_sigma_k``
        times the estimate's position standard deviation more)."""
        length = self.tether_length_m
        if self.winch_length_m is not None and self.mode is not GovernorMode.TENSION:
            length = min(length, self.winch_length_m
                         + WIND_IN_LEAD_S * min(self.winch_speed_m_s, 0.0))
        if self.locked_length_m is not None:
            length = min(length, self.locked_length_m)
        return length - self.p.tether_margin_m

    def lookahead_winch_speed_m_s(self) -> float:
        """The line speed [m/s] the slowing's look-ahead counts on: the winch's reported
        one, never paying out while the drum is braked nor beyond the whole tether."""
        ws = self.winch_speed_m_s
        if self.locked_length_m is not None or self.winch_length_m is None:
            return min(ws, 0.0)
        room = self.tether_length_m - self.winch_length_m
        return min(ws, max(room, 0.0) / GOVERNOR_LOOKAHEAD_S)

    # ----- the slowing of legs (the leg clock) and of velocity targets

    def reset_clock(self) -> None:
        """A new leg or script: its clock runs at the vehicle's rate (what it lost
        before stays lost)."""
        self.s, self.sd = 1.0, 0.0

    def slow_rate(self, nom: RefSample | None, s: float, ahead_vel: Vec3 | None,
                  pos: Vec3, vel: Vec3, sigma_m: float) -> tuple[float, float]:
        """The rate in [0, 1] the slowing asks of the leg's clock for the leg's nominal
        sample ``nom`` (None: none yet) with the clock at rate ``s``, the vehicle at
        ``pos`` [m] moving at ``vel`` [m/s] (its estimate, of position standard deviation
        ``sigma_m`` [m]), and the speed [m/s] it counted: the leg's now, or the larger of
        the leg's plan :data:`GOVERNOR_LOOKAHEAD_S` on, ``ahead_vel`` [m/s] (None:
        unknown) (:func:`slow_rate_kernel`)."""
        if nom is None:
            return 1.0, 0.0
        v = nom.vel_m_s
        if ahead_vel is not None:
            sa2 = (ahead_vel[0] * ahead_vel[0] + ahead_vel[1] * ahead_vel[1]
                   + ahead_vel[2] * ahead_vel[2])
            if math.sqrt(sa2) > math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]):
                v = ahead_vel
        return self._slow_rate((*nom.pos_m, *v, *nom.acc_m_s2, *pos, *vel, sigma_m, s,
                                0.0, 0.0), self._room or self.room)

    def slow_clock(self, nom: RefSample | None, pos: Vec3, vel: Vec3, sigma_m: float,
                   dt: float) -> Notice | None:
        """The fence-like part of the governor, one period ``dt`` [s]: the rate s of the
        leg's clock follows (critically damped, its effect on the reference limited to
        :data:`GOVERNOR_SLOW_JERK_M_S3` and :data:`GOVERNOR_SLOW_ACC_M_S2`) the largest
        rate at which the leg's speed along its path stays within
        :func:`governed_speed_m_s` of the room the tether leaves, from the reference's and
        the vehicle's positions (latency ``tether_latency_s`` +
        :data:`GOVERNOR_SLOW_RAMP_S`, deceleration ``tether_brake_acc_m_s2``, the limit
        :attr:`limit_m` less ``tether_sigma_k`` position standard deviations):
        :func:`slow_clock_kernel`. Returns the notice to say when a slowing begins."""
        if nom is None:         # (a leg not moving: its rate 1)
            nom = _AT_REST_SAMPLE
        s_new, sd_new, target, lag = self._slow_clock(
            (*nom.pos_m, *nom.vel_m_s, *nom.acc_m_s2, *pos, *vel, sigma_m, self.s, self.sd,
             dt), self._room or self.room)
        notice = None
        if target < GOVERNOR_SLOWING_SAID_BELOW and not self.slowed:
            self.slowed = True
            notice = _SLOWING
        elif min(target, s_new) >= GOVERNOR_SLOWING_OVER_ABOVE:
            self.slowed = False
        self.clock_lag += lag
        self.s, self.sd = s_new, sd_new
        return notice

    def scaled(self, ref: RefSample) -> RefSample:
        """A leg's sample ``ref`` on a clock running at rate s (ds/dt = sd, its own rate
        taken as 0): velocity v s, acceleration a s^2 + v sd, jerk j s^3 + 3 a s sd, with
        v, a, j the leg's derivatives in its own time (position, velocity and acceleration
        continuous)."""
        s, sd = self.s, self.sd
        if s == 1.0 and sd == 0.0:
            return ref
        vx, vy, vz = ref.vel_m_s
        ax, ay, az = ref.acc_m_s2
        jx, jy, jz = ref.jerk_m_s3
        return _new(RefSample, (
            ref.pos_m, (vx * s, vy * s, vz * s),
            (ax * s * s + vx * sd, ay * s * s + vy * sd, az * s * s + vz * sd),
            (jx * s * s * s + 3.0 * ax * s * sd, jy * s * s * s + 3.0 * ay * s * sd,
             jz * s * s * s + 3.0 * az * s * sd),
            ref.yaw_rad, ref.yaw_rate_rad_s * s))

    def velocity_cap(self, cmd: Vec3, ref_pos: Vec3, pos: Vec3, sigma_m: float
                     ) -> tuple[float, Notice | None]:
        """The fence-like part of the governor for a velocity target: the cap [m/s] on
        the speed of its command ``cmd`` [m/s] (inf: none), :func:`governed_speed_m_s` of
        the room the tether leaves ahead of the reference at ``ref_pos`` [m] (latency
        :data:`GOVERNOR_SLOW_RAMP_S`, its brake's build-up) and of the vehicle at ``pos``
        [m] (latency ``tether_latency_s``), less a leg's slowing margin (with ``sigma_m``
        [m] the estimate's standard deviation): the brake's own test with margin, so that
        a target streamed outward slows to the line's room rather than meeting the brake.
        And the notice to say when a slowing begins."""
        speed = math.sqrt(cmd[0] * cmd[0] + cmd[1] * cmd[1] + cmd[2] * cmd[2])
        if speed < 1e-3:
            return math.inf, None
        u = (cmd[0] / speed, cmd[1] / speed, cmd[2] / speed)
        p, pe = ref_pos, pos
        d = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        v_out = speed * (u[0] * p[0] + u[1] * p[1] + u[2] * p[2]) / d if d > 0 else speed
        lim = self.limit_m - ((GOVERNOR_SLOW_MARGIN_M + self.p.tether_sigma_k * sigma_m)
                              * min(1.0, max(v_out, 0.0) / GOVERNOR_SIGMA_SPEED_M_S))
        ab = self.p.tether_brake_acc_m_s2
        v_max = min(governed_speed_m_s((p[0], p[1], p[2]), u, lim, GOVERNOR_SLOW_RAMP_S, ab),
                    governed_speed_m_s(pe, u, lim, self.p.tether_latency_s, ab))
        notice = None
        if v_max < speed:
            if not self.slowed:
                self.slowed = True
                notice = _SLOWING
        else:
            self.slowed = False
        return max(v_max, 0.0), notice

    # ----- the brake

    def check(self, ref: RefSample, pos: Vec3, vel: Vec3, sigma_m: float) -> Decision:
        """The governor's test of a period's reference ``ref`` with the vehicle at ``pos``
        [m] moving at ``vel`` [m/s] (its estimate, of position standard deviation
        ``sigma_m`` [m]): when the stopping point of the reference moving outward, or of
        the vehicle (going on for ``tether_latency_s`` before it follows), braking at
        ``tether_brake_acc_m_s2``, would pass :attr:`limit_m` (less ``tether_sigma_k``
        standard deviations, in full from an outward speed of
        :data:`GOVERNOR_SIGMA_SPEED_M_S`), BRAKE; a reference at rest, AT_REST; else
        FLY (:func:`check_kernel`)."""
        code, lim = self._check((*ref.pos_m, *ref.vel_m_s, *ref.acc_m_s2, *pos, *vel,
                                 sigma_m, 1.0, 0.0, 0.0), self._room or self.room)
        return _new(Decision, (_VERDICTS[code], lim))

    def start_brake(self, ref: RefSample, dt: float) -> RefSample:
        """Brake the reference ``ref`` from now on; the first period's [s] sample."""
        self.brake = BrakeRef(ref, self.p.tether_brake_acc_m_s2, TETHER_BRAKE_JERK_M_S3)
        return self.brake.step(dt)

    def step_brake(self, dt: float) -> tuple[RefSample, bool]:
        """The brake stepped ``dt`` [s]: its sample, and whether it is at rest (then it
        is over)."""
        b = self.brake
        assert b is not None
        ref = b.step(dt)
        if b.stopped:
            self.brake = None
            return ref, True
        return ref, False

    def may_resume(self, ref_pos: Vec3, pos: Vec3, limit_m: float) -> bool:
        """Whether a stopped plan may go on, its reference at rest at ``ref_pos`` [m] and
        the vehicle at ``pos`` [m]: the drum is not braked and has paid out
        :data:`TETHER_RESUME_ROOM_M` of room within ``limit_m`` [m], or (a line with
        little slack at rest) it has caught up with the winder's reference
        (:data:`TETHER_CAUGHT_UP_M_S`) and stands with some room."""
        p, pe = ref_pos, pos
        d = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        room = limit_m - max(d, math.sqrt(pe[0] ** 2 + pe[1] ** 2 + pe[2] ** 2))
        caught_up = abs(self.winch_speed_m_s) < TETHER_CAUGHT_UP_M_S and room > 0.0
        return (room >= TETHER_RESUME_ROOM_M or caught_up) and self.locked_length_m is None

    def move_in_target(self, ref_pos: Vec3, limit_m: float) -> Vec3 | None:
        """Where a reference at rest at ``ref_pos`` [m] beyond the ``limit_m`` [m] of a
        braked drum moves in to (radially, :data:`TETHER_RESUME_ROOM_M` short of it, no
        lower than 1 m above the gear unless already lower); None when it need not."""
        p = ref_pos
        d = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        if self.locked_length_m is None or not (d > limit_m and d > 0):
            return None
        return towards_winder(p, limit_m - TETHER_RESUME_ROOM_M, self.gear_height_m + 1.0)


_SLOWING = Notice(TextKind.TETHER_SLOWING, "Tether: slowing to the room the line gives")
#: the sample the slowing takes for a leg with none yet: at rest (its rate 1)
_AT_REST_SAMPLE = RefSample(_ZERO3, _ZERO3, _ZERO3, _ZERO3, 0.0, 0.0)

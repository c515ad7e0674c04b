"""The onboard software in one step: what the flight computer does every control period.

:class:`Companion` holds the navigation filter (:class:`companion.ekf.NavFilter`, fed
the IMU, barometer, magnetometer and GNSS), the navigation
(:class:`companion.navigation.Navigator`: modes, arming, take-off, landing, guided targets,
missions) and the flight control (:class:`companion.flight_controller.FlightController`),
and steps them together from what the links deliver: the sensors (and, for comparison, the
simulator's state) from the simulator link, the winch's reports from the component link.
With ``EstimatorParams.kind`` "truth" it flies on the simulator's state instead of its
filter's estimate. The companion process (``companion/__main__.py``) wraps it with sockets; the
offline runner (``tuav_sitl/offline.py``) calls the same object with what the links would
deliver, so both fly the same onboard software. Ground stations act on :attr:`nav` (through
the MAVLink layer, or a scenario's script offline).

It knows only its own parameter files (the vehicle as its designers believe it) and what
arrives on its links: never the plant's objects, parameters or rotor speeds.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from companion.ekf import AidSource, EstimatorParams, FilterStatus, NavFilter
from companion.ekf.drag import DragModel
from companion.failsafes import FailsafeParams, Failsafes
from companion.flight_controller import FlightController, FlightStep, VehicleState
from companion.gains import FlightControlParams
from companion.navigation import (
    FlightMode,
    MotorState,
    NavigationParams,
    Navigator,
    Reason,
    Refusal,
    air_start_threshold_m,
)
from companion.reference import RefSample
from companion.simlink_client import GpsFix, ImuSample
from tuavdefs.airframe import rotor_speed_to_command
from tuavdefs.component_link import ExternalPosition, TetherReading
from tuavdefs.frames import ned_to_enu, quat_rotate
from tuavdefs.line_shape import LineModel, line_top
from tuavdefs.params import SystemParams

_STOPPED = (0.0, 0.0, 0.0, 0.0)
#: A record built as the tuple it is (tuple.__new__), without its Python-level constructor
_new = tuple.__new__
#: An unhealthy navigation filter for this long in flight triggers the EKF failsafe [s]
#: (ArduCopter checks its EKF's variances at 10 Hz and acts after about 1 s).
EKF_FAILSAFE_S = 1.0
#: How often the filter's health is checked [s] (5 Hz: within the failsafe's second).
HEALTH_CHECK_S = 0.2
#: A line leaving the exit below this elevation lies on the ground there [rad] (the ground
#: station's ground_elevation_rad): its pull is not the suspended line's.
_LINE_OFF_GROUND_RAD = 0.03
#: No raw reading fused tightly this period (a period without readings allocates none).
_NONE_TAKEN: frozenset[float] = frozenset()


class OnboardInputs(NamedTuple):
    """What the simulator link delivers for one control period."""

    t_s: float
    """Simulated time of the period [s]."""
    truth: VehicleState | None
    """The simulator's state (HIL_STATE_QUATERNION; inertial z-up frame, body FLU, SI):
    flown on only with ``EstimatorParams.kind`` "truth"."""
    imu: ImuSample | None = None
    """The period's IMU, magnetometer and barometer sample (HIL_SENSOR)."""
    gps: GpsFix | None = None
    """A GNSS fix, when one arrived this period (HIL_GPS)."""


class OnboardOutputs(NamedTuple):
    """What one onboard step produces."""

    rotor_commands: tuple[float, float, float, float]
    """Normalised rotor commands, 0..1 (zeros unless flying)."""
    motors: MotorState
    armed: bool
    state: VehicleState | None
    """The state the vehicle flew on this period (what its telemetry reports); None while
    its filter has not aligned."""
    reference: RefSample | None
    """The reference the flight controller tracked (None when not flying)."""
    flight: FlightStep | None
    """The flight controller's diagnostics (only when asked for, and flying)."""


class Companion:
    """Navigation and flight control stepped together at ``gains.rate_hz``.

    ``params`` is the companion's own model of the system (vehicle, tether, environment).
    A period is :meth:`step`, or :meth:`begin` then :meth:`finish` for a caller that acts
    when the navigator starts (what :meth:`begin` returns); the navigator's events are
    :meth:`Navigator.pop_events`.
    """

    def __init__(self, params: SystemParams, gains: FlightControlParams,
                 nav_params: NavigationParams, estimator: EstimatorParams | None = None, *,
                 failsafes: FailsafeParams | None = None) -> None:
        self.params = params
        veh = params.vehicle
        g = params.environment.gravity_m_s2
        est = estimator if estimator is not None else EstimatorParams()
        self.estimator_params = est
        #: the vehicle's drag as the filter's drag fusion models it (the controllers'
        #: vehicle model)
        env = params.environment
        self._drag_model = DragModel.from_vehicle(veh, env.air_density_kg_m3)
        #: the line as the companion believes it (its pull in the wind, for drag fusion)
        self._line = LineModel.from_tether(params.tether, g, env.air_density_kg_m3)
        #: the winch's latest raw tether reading (None: none yet)
        self._reading: TetherReading | None = None
        #: raw readings received since the last step (the filter's tight fusion)
        self._readings: list[TetherReading] = []
        self.filter: NavFilter | None = self._new_filter()
        self.gps: GpsFix | None = None
        """The last GNSS fix received (what GPS_RAW_INT reports)."""
        self.imu: ImuSample | None = None
        """The last IMU sample received."""
        self._airborne_at_boot: bool | None = None
        self._unhealthy_since: float | None = None
        self._healthy = self.filter is None
        self._health_t_s = -math.inf
        self._status: FilterStatus | None = None
        self._t_s = -math.inf               # the last period's time [s]
        self.flight = FlightController(gains, veh, params.tether, g)
        self.nav = Navigator(nav_params, veh.gear_height_m, params.tether.total_length_m)
        #: the link failsafes (a lost ground station, a lost winder)
        self.failsafes = Failsafes(failsafes or FailsafeParams(), self.nav)
        self.dt_s = 1.0 / gains.rate_hz
        self._min_speed = veh.rotor_speed_min_rad_s
        #: the rotor speed [rad/s] the vehicle's own model says hovers it (the motor model
        #: starts there when the vehicle starts in the air)
        self.hover_speed_rad_s = math.sqrt(veh.mass_kg * g / (4.0 * veh.rotor_thrust_coeff))
        #: its rotor commands (flown open loop while a vehicle found in the air has no
        #: estimate yet)
        self._hover_commands = (rotor_speed_to_command(self.hover_speed_rad_s, veh),) * 4
        self.started = False
        #: the period :meth:`begin` opened: its time [s] and the state to fly on (None
        #: before the first state)
        self._period: tuple[float, VehicleState | None] = (-math.inf, None)
        self.nav.prearm = self._prearm
        #: ArduPilot's ARMING_CHECK bitmask: 0 skips the pre-arm checks, else they run
        self.arming_check = 1
        self._was_flying = False
        self.steps = 0
        #: tether fixes received since the last step (ODOMETRY from the winch)
        self._external: list[ExternalPosition] = []
        self._sources: AidSource | None = None
        self._attach_m = tuple(veh.tether_attachment_m)

    @property
    def gains(self) -> FlightControlParams:
        """The flight-control gains flown now."""
        return self.flight.gains

    def set_gains(self, gains: FlightControlParams) -> None:
        """Fly with ``gains`` from the next step on (see FlightController.set_gains)."""
        self.flight.set_gains(gains)

    def set_nav_params(self, params: NavigationParams) -> None:
        """Fly with these navigation parameters from the next step on."""
        self.nav.p = params

    def reboot(self) -> None:
        """Restart the onboard state as a reboot would (call it disarmed): a new navigation
        filter, aligning again before arming is allowed; the navigator at power-on with its
        parameters and stored mission (:meth:`Navigator.reboot`); the flight controller is
        reset when it next flies; the next state starts the navigator again (:meth:`begin`
        returns True). The parameters stay, as in storage."""
        self.filter = self._new_filter()
        self._airborne_at_boot = None
        self._unhealthy_since = None
        self._healthy = self.filter is None
        self._health_t_s = -math.inf
        self._status = None
        self.nav.reboot()
        self.started = False
        self._was_flying = False

    def _new_filter(self) -> NavFilter | None:
        """A navigation filter on the estimator's parameters (None: flying on the truth)."""
        est = self.estimator_params
        if est.kind != "ekf":
            return None
        return NavFilter(est, self.params.environment.gravity_m_s2,
                         ned_to_enu(tuple(est.earth_field_ned_gauss)), self._drag_model,
                         self._line, tuple(self.params.vehicle.tether_attachment_m))

    def wind_estimate(self) -> tuple[float, float, float]:
        """The onboard wind estimate [m/s], z-up (what WIND reports). With the filter's
        drag fusion, its wind states (EKF3's). Otherwise the wind the position loop's
        disturbance estimate implies: the horizontal disturbance read as linear drag in
        moving air (v + m d / D per axis; what is left of the tether's pull after its
        model shows as wind too), zero on the ground."""
        f = self.filter
        if f is not None and f.drag_fusion:
            return f.wind_m_s
        if not self.nav.flying:
            return (0.0, 0.0, 0.0)
        d = self.flight.position.d_hat
        veh = self.params.vehicle
        drag = veh.drag_coeff_n_s_m
        ref = self.nav.reference()
        v = ref.vel_m_s if ref is not None else (0.0, 0.0, 0.0)   # the velocity flown
        wx, wy = (v[i] + veh.mass_kg * d[i] / drag[i] if drag[i] > 0 else 0.0
                  for i in range(2))
        return (wx, wy, 0.0)

    def winch_report(self, t_s: float, length_m: float, speed_m_s: float,
                     tension_n: float | None, braked: bool = False,
                     healthy: bool = True) -> None:
        """A report of the winch at ``t_s`` [s]: paid-out length [m], line speed [m/s],
        drum tension [N] (None: not measured), whether its drum is braked (the navigator
        bounds its reach by it and acts on an over-tension), whether it says it is healthy
        (the winder failsafe)."""
        self.failsafes.winch_heard(t_s, length_m, healthy)
        self.flight.winch_report(t_s, length_m, speed_m_s, tension_n)
        self.nav.winch_report(length_m, tension_n, braked or self.failsafes.winch_lost,
                              speed_m_s)

    def gcs_heard(self, t_s: float) -> None:
        """A ground station's HEARTBEAT at ``t_s`` [s] (the ground-station failsafe)."""
        self.failsafes.gcs_heard(t_s)

    def external_position(self, fix: ExternalPosition) -> None:
        """A tether fix from the winch (its time on the vehicle's clock, the tether's
        attachment point [m], covariance [m^2]): fused with the next step's sensors."""
        if len(self._external) < 16:      # bounded: a flood waits for the next step
            self._external.append(fix)

    def tether_reading(self, reading: TetherReading) -> None:
        """The raw reading a tether fix of the winch was made of (length, tension, exit
        angles, at its sample time on the vehicle's clock): the tether's pull in the drag
        fusion, and the filter's tight fusion (docs/estimation.md §11)."""
        self._reading = reading
        if len(self._readings) < 16:      # bounded: a flood waits for the next step
            self._readings.append(reading)

    def _line_pull(self, t_s: float, pos_m: tuple[float, float, float]
                   ) -> tuple[float, float, float] | None:
        """The line's pull on the vehicle [N] (inertial) from the latest raw reading: the
        line's model (its weight and its drag in the filter's wind, taken at the vehicle's
        height ``pos_m[2]`` [m] and sheared below it) integrated from the exit in the
        direction and with the tension measured, ``-T(L)``; None without a fresh reading
        of a line leaving the exit above the ground."""
        r, f, est = self._reading, self.filter, self.estimator_params
        if (r is None or f is None or abs(t_s - r.t_s) > est.drag.tether_max_age_s
                or r.elevation_rad < _LINE_OFF_GROUND_RAD or not r.tension_n > 0.0):
            return None
        m = self._line
        u = f.wind_m_s
        kw, kc, b_psi, b_eps = f.line_states
        w_b = f.line_weight_belief_n_m
        w = kw * (m.weight_n_m if w_b is None else w_b)
        top = line_top(r.length_m, r.tension_n, r.azimuth_rad - b_psi, r.elevation_rad - b_eps,
                       w, kc * m.drag_n_s2_m3, u[0], u[1], m.ea_n,
                       max(pos_m[2], 1.0), est.drag.tether_wind_shear, 1.0, m.steps)
        return (-top[3], -top[4], -top[5])

    def _fuse_readings(self, t_s: float) -> set[float] | frozenset[float]:
        """The raw tether readings into the filter's tight fusion; the sample times of
        those it took (their ground station's fixes are then not fused as well)."""
        f = self.filter
        readings, self._readings = self._readings, []
        taken: set[float] = set()
        if f is None or not f.tether_line_fusion:
            return taken
        flying = self.nav.flying
        for r in readings:
            if f.fuse_tether_reading(t_s, r.t_s, r.length_m, r.tension_n, r.azimuth_rad,
                                     r.elevation_rad, flying, r.weight_n_m) is not None:
                taken.add(round(r.t_s, 3))
        return taken

    def _fuse_external(self, t_s: float, taken: set[float] | frozenset[float]) -> None:
        f = self.filter
        fixes, self._external = self._external, []
        if f is None:
            return
        for fix in fixes:
            if taken and round(fix.t_s, 3) in taken:
                continue      # its raw reading was fused tightly
            pos = fix.pos_m
            if f.aligned and any(self._attach_m):
                # the fix is of the attachment point: the vehicle's origin is R r_a below
                # it (the attitude's error is small beside the fix's)
                off = quat_rotate(f.state().quat, self._attach_m)
                pos = (pos[0] - off[0], pos[1] - off[1], pos[2] - off[2])
            f.fuse_tether(t_s, fix.t_s, pos, fix.cov_m2)

    def _fuse_drag(self, t_s: float) -> None:
        """The drag's specific force into the filter, in the air only, with the tether's
        pull from the winch's raw reading in the filter's wind (:meth:`_line_pull`), or
        without one the flight controller's windless tether model at the estimated
        position, the winch's reported length and tension (docs/estimation.md §11)."""
        f = self.filter
        nav = self.nav
        if not nav.flying:
            f.fuse_drag(t_s, False, (0.0, 0.0, 0.0))
            return
        fc = self.flight
        winch = fc.winch
        pos = f.state().pos_m
        pull = self._line_pull(t_s, pos)
        if pull is None:
            pull = fc.tether_model.estimate(pos, winch.length_at(t_s), winch.tension_n).force_n
        f.fuse_drag(t_s, True, pull)

    def _announce_sources(self, sources: AidSource) -> None:
        """A STATUSTEXT (through the navigator's events) when the position sources change."""
        old, self._sources = self._sources, sources
        gnss, tether = AidSource.GNSS in sources, AidSource.TETHER in sources
        if old is None:
            if tether and not gnss:
                self.nav.notice("EKF: tether fix in use, no GNSS")
            elif tether:
                self.nav.notice("EKF: GNSS and tether fix in use")
            return
        was_gnss, was_tether = AidSource.GNSS in old, AidSource.TETHER in old
        if was_gnss and not gnss:
            self.nav.notice("EKF: GNSS lost, tether fix in use" if tether
                            else "EKF: GNSS lost")
        elif gnss and not was_gnss:
            self.nav.notice("EKF: GNSS in use" + (" with tether fix" if tether else ""))
        elif tether and not was_tether:
            self.nav.notice("EKF: tether fix in use")
        elif was_tether and not tether:
            self.nav.notice("EKF: tether fix lost")

    @property
    def last_status(self) -> FilterStatus | None:
        """The navigation filter's status as last checked (:data:`HEALTH_CHECK_S`; None
        when flying on the truth or before the first check): what telemetry reports."""
        return self._status

    @property
    def ekf_failsafe(self) -> bool:
        """Whether the EKF failsafe holds now: the filter unhealthy in flight for
        :data:`EKF_FAILSAFE_S` (what the onboard log records as its ERR)."""
        since = self._unhealthy_since
        return since is not None and self._t_s - since >= EKF_FAILSAFE_S

    @property
    def navigation_healthy(self) -> bool:
        """Whether what the vehicle flies on is usable (arming needs it): the filter's
        health as last checked (:data:`HEALTH_CHECK_S`)."""
        return self._healthy

    def _check_health(self, t_s: float) -> None:
        """The filter's health, again if :data:`HEALTH_CHECK_S` have passed (its status
        is too costly for every period)."""
        f = self.filter
        if f is None or t_s - self._health_t_s < HEALTH_CHECK_S:
            return
        self._health_t_s = t_s
        self._status = st = f.status(t_s)
        self._healthy = f.aligned and st.healthy
        if f.aligned:
            # the tether governor's margin: the estimate's largest position sigma [m]
            sig = max(st.pos_sigma_m)
            self.nav.position_sigma_m = sig if math.isfinite(sig) else 0.0
            self._announce_sources(st.sources)

    def estimator_check(self) -> Refusal | None:
        """Whether the estimate is ready to arm on now: None when it is (flying on the
        simulator's state, or a filter healthy as last checked and aligned for
        ``arming_settle_s``), else why not. The one source of readiness: the estimator's
        pre-arm check and what telemetry reports as ready (EKF_STATUS_REPORT's flags,
        SYS_STATUS's AHRS, GPS and pre-arm bits, HOME_POSITION) both ask it, as
        ArduPilot's EKF is not healthy, and says so, until it has settled."""
        f = self.filter
        if f is None:
            return None
        if not self.navigation_healthy:
            return Refusal(Reason.PREARM, "PreArm: EKF not healthy")
        since = f.aligned_at_s
        if since is None or self._t_s - since < self.estimator_params.arming_settle_s:
            return Refusal(Reason.PREARM, "PreArm: EKF settling")
        return None

    def estimator_ready(self) -> bool:
        """:meth:`estimator_check` passes."""
        return self.estimator_check() is None

    def _prearm(self) -> Refusal | None:
        """ArduCopter's pre-arm check of the estimator (skipped with ARMING_CHECK 0)."""
        return None if self.arming_check == 0 else self.estimator_check()

    def estimate(self, inputs: OnboardInputs) -> VehicleState | None:
        """The period's sensors into the filter; the state to fly on (None while the
        filter has not aligned). With kind "truth", the simulator's state."""
        imu, gps = inputs.imu, inputs.gps
        if imu is not None:
            self.imu = imu
        if gps is not None:
            self.gps = gps
        f = self.filter
        t = self._t_s = inputs.t_s
        if f is None:
            return inputs.truth
        if imu is not None:
            f.predict(t, imu.gyro_flu_rad_s, imu.accel_flu_m_s2)
            f.fuse_baro(t, imu.pressure_alt_m)
            f.fuse_mag(t, imu.mag_flu_gauss)
        if self.started and self.nav.landed and not self.nav.armed:
            # at rest on its gear: no drift without GNSS, and the gear's height
            f.fuse_stationary(t, self.params.vehicle.gear_height_m)
        taken = self._fuse_readings(t) if self._readings else _NONE_TAKEN
        if self._external:
            self._fuse_external(t, taken)
        if f.drag_due(t):
            self._fuse_drag(t)
        self._check_health(t)
        if gps is not None:
            if self._airborne_at_boot is None:
                # (an accuracy not given is taken as large: on the ground, never a launch)
                epv = gps.epv_m if gps.epv_m >= 0.0 and math.isfinite(gps.epv_m) else math.inf
                self._airborne_at_boot = (gps.position_enu_m[2] > air_start_threshold_m(
                    self.params.vehicle.gear_height_m, epv))
                if self._airborne_at_boot:   # flying open loop: align sooner
                    f.start_in_air()
            f.fuse_gnss(t, gps.position_enu_m, gps.velocity_enu_m_s, gps.eph_m, gps.epv_m)
        return f.state() if f.aligned else None

    def _ekf_failsafe(self, t_s: float) -> None:
        """ArduCopter's EKF failsafe: an unhealthy filter for ``EKF_FAILSAFE_S`` in flight
        lands the vehicle (one landing already goes on)."""
        nav = self.nav
        if self.navigation_healthy or not nav.flying:
            self._unhealthy_since = None
            return
        if self._unhealthy_since is None:
            self._unhealthy_since = t_s
        elif (t_s - self._unhealthy_since >= EKF_FAILSAFE_S
              and nav.mode != FlightMode.LAND and not nav.landing):
            # (a vehicle already landing lands: a line lying on the ground at the touchdown
            # gives no tether fix)
            nav.failsafe_land("EKF Failsafe: landing")

    def start(self, t_s: float, state: VehicleState) -> None:
        """Initialise from the first state: on the ground (disarmed) or in the air (armed,
        GUIDED, holding where it is). :meth:`step` calls it with the first state."""
        self.started = True
        self.nav.start(t_s, state.pos_m, state.vel_m_s, state.quat,
                       airborne=self._airborne_at_boot)
        if self.nav.flying:
            self.flight.reset(state, (self.hover_speed_rad_s,) * 4)
            self._was_flying = True

    def _open_loop_hover(self, t_s: float) -> tuple[float, float, float, float]:
        """The rotor commands a vehicle found in the air flies while its filter aligns:
        the thrust that balances its weight and the tether's pull as its own model has it
        at the fix's position, the winch's reported length and tension (its weight alone
        before a report), on the attitude it has (a tethered hover is tilted into the
        pull: the magnitude, not the vertical part). Without the pull a heavy line drags
        the vehicle down in free fall, where the accelerometer shows no tilt to align on."""
        gps, fc = self.gps, self.flight
        veh = self.params.vehicle
        weight = veh.mass_kg * self.params.environment.gravity_m_s2
        if gps is None:
            return self._hover_commands
        winch = fc.winch
        fx, fy, fz = fc.tether_model.estimate(gps.position_enu_m, winch.length_at(t_s),
                                               winch.tension_n)[0]
        thrust = math.sqrt(fx * fx + fy * fy + (weight - fz) ** 2)
        if not math.isfinite(thrust):
            return self._hover_commands
        speed = math.sqrt(thrust / (4.0 * veh.rotor_thrust_coeff))
        return (rotor_speed_to_command(speed, veh),) * 4

    def step(self, inputs: OnboardInputs, diagnostics: bool = False) -> OnboardOutputs:
        """One control period: :meth:`begin` then :meth:`finish`."""
        self.begin(inputs)
        return self.finish(diagnostics)

    def begin(self, inputs: OnboardInputs) -> bool:
        """A control period's first half: the estimate; the first state starts the
        navigator (:meth:`start`). Returns whether it started in this period: what a caller
        does then (a script's mission, a goto, home announced) goes between this and
        :meth:`finish`, before the navigator's first step."""
        t = inputs.t_s
        state = self.estimate(inputs)
        self._period = (t, state)
        if state is None or self.started:
            return False
        self.start(t, state)
        return True

    def finish(self, diagnostics: bool = False) -> OnboardOutputs:
        """The period :meth:`begin` opened, completed: the navigator's reference, then the
        flight controller's rotor commands (with its diagnostics if ``diagnostics``). Until
        the first state, a vehicle the GNSS finds in the air hovers open loop, one on the
        ground stays disarmed."""
        t, state = self._period
        if state is None:
            self.steps += 1
            if self._airborne_at_boot:
                return OnboardOutputs(self._open_loop_hover(t), MotorState.FLY, True, None,
                                      None, None)
            return OnboardOutputs(_STOPPED, MotorState.OFF, False, None, None, None)
        if self.filter is not None:
            self._ekf_failsafe(t)
        self.failsafes.check(t)
        ref, motors = self.nav.step(t, state.pos_m, state.vel_m_s, state.quat, self.dt_s)
        fs = None
        if motors is MotorState.FLY and ref is not None:
            if not self._was_flying:
                self.flight.reset(state, (self._min_speed,) * 4)
                self._was_flying = True
            if diagnostics:
                fs = self.flight.update(t, state, ref)
                cmds = fs.rotor_commands
            else:
                cmds = self.flight.commands(t, state, ref)
        else:
            self._was_flying = False
            cmds = _STOPPED
        self.steps += 1
        return _new(OnboardOutputs, (cmds, motors, motors is not MotorState.OFF, state, ref, fs))

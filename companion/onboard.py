"""The onboard software in one step: what the flight computer does every control period.

:class:`Companion` holds the navigation (:class:`companion.navigation.Navigator`: modes,
arming, take-off, landing, guided targets, missions) and the flight control
(:class:`companion.flight_controller.FlightController`), and steps them together from what
the links deliver: the vehicle's state from the simulator link, the winch's reports from the
component link. The companion process (``companion/__main__.py``) wraps it with sockets; the
offline runner (``tuav_sitl/offline.py``) calls the same object with what the links would
deliver, so both fly the same onboard software. Ground stations act on :attr:`nav` (through
the MAVLink layer, or a scenario's script offline).

It knows only its own parameter files (the vehicle as its designers believe it) and what
arrives on its links: never the plant's objects, parameters or rotor speeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from companion.flight_controller import FlightController, FlightStep, VehicleState
from companion.gains import FlightControlParams
from companion.navigation import MotorState, NavEvent, NavigationParams, Navigator
from companion.reference import RefSample
from tuavdefs.params import SystemParams

_STOPPED = (0.0, 0.0, 0.0, 0.0)


class OnboardInputs(NamedTuple):
    """What the simulator link delivers for one control period."""

    t_s: float
    """Simulated time of the period [s]."""
    state: VehicleState
    """The vehicle's state as the link reports it (inertial z-up frame, body FLU, SI)."""


class OnboardOutputs(NamedTuple):
    """What one onboard step produces."""

    rotor_commands: tuple[float, float, float, float]
    """Normalised rotor commands, 0..1 (zeros unless flying)."""
    motors: MotorState
    armed: bool
    state: VehicleState
    """The state the vehicle flew on this period (what its telemetry reports)."""
    reference: RefSample | None
    """The reference the flight controller tracked (None when not flying)."""
    flight: FlightStep | None
    """The flight controller's diagnostics (only when asked for, and flying)."""


class Companion:
    """Navigation and flight control stepped together at ``gains.rate_hz``.

    ``params`` is the companion's own model of the system (vehicle, tether, environment);
    ``goto`` [m], if the vehicle starts in the air, is flown to after the first step;
    ``on_event(kind, value)`` hears the navigator's events.
    """

    def __init__(self, params: SystemParams, gains: FlightControlParams,
                 nav_params: NavigationParams, *,
                 on_event: Callable[[NavEvent, object], None] | None = None) -> None:
        self.params = params
        veh = params.vehicle
        g = params.environment.gravity_m_s2
        self.gravity_m_s2 = g
        self.flight = FlightController(gains, veh, params.tether, g)
        self.nav = Navigator(nav_params, veh.gear_height_m, params.tether.total_length_m,
                             on_event=on_event)
        self.dt_s = 1.0 / gains.rate_hz
        self._min_speed = veh.rotor_speed_min_rad_s
        #: the rotor speed [rad/s] the vehicle's own model says hovers it (the motor model
        #: starts there when the vehicle starts in the air)
        self.hover_speed_rad_s = math.sqrt(veh.mass_kg * g / (4.0 * veh.rotor_thrust_coeff))
        self.started = False
        self._was_flying = False
        self.steps = 0

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

    def winch_report(self, t_s: float, length_m: float, speed_m_s: float,
                     tension_n: float | None) -> None:
        """A report of the winch at ``t_s`` [s]: paid-out length [m], line speed [m/s],
        drum tension [N] (None: not measured)."""
        self.flight.winch_report(t_s, length_m, speed_m_s, tension_n)

    def start(self, inputs: OnboardInputs) -> None:
        """Initialise from the first state: on the ground (disarmed) or in the air (armed,
        GUIDED, holding where it is). :meth:`step` calls it on its first call."""
        state = inputs.state
        self.started = True
        self.nav.start(inputs.t_s, state.pos_m, state.vel_m_s, state.quat)
        if self.nav.flying:
            self.flight.reset(state, (self.hover_speed_rad_s,) * 4)
            self._was_flying = True

    def step(self, inputs: OnboardInputs, diagnostics: bool = False) -> OnboardOutputs:
        """One control period: the navigator's reference, then the flight controller's
        rotor commands (with its diagnostics if ``diagnostics``)."""
        if not self.started:
            self.start(inputs)
        t, state = inputs
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
        return OnboardOutputs(cmds, motors, motors is not MotorState.OFF, state, ref, fs)

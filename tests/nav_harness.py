"""A closed loop for flight-logic tests: the plant's truth model, the companion's onboard
step (:class:`companion.onboard.Companion`: navigator and flight controller) and the ground
station's WinderHost, stepped in one process at their own rates (as the offline runner
does)."""

from __future__ import annotations

import math

from companion.ekf import EstimatorParams
from companion.flight_controller import VehicleState
from companion.gains import FlightControlParams
from companion.navigation import MotorState, NavigationParams
from companion.onboard import Companion, OnboardInputs
from groundstation.lbar import LBarParams
from groundstation.winder_control import WinderControlParams
from groundstation.winder_host import WinderHost
from sitl.plant import POS, QUAT, RATES, VEL, Plant, PlantInputs, initial_state
from tuavdefs.params import SystemParams


class Loop:
    """Plant + controllers + navigator; ``run_until(cond, limit_s)`` steps the loop."""

    def __init__(self, start_xy: tuple[float, float] = (2.0, 0.0),
                 nav: NavigationParams | None = None) -> None:
        self.params = params = SystemParams()
        g = params.environment.gravity_m_s2
        gains = FlightControlParams()
        self.plant = Plant(params)
        model = self.plant.model
        pos0 = (start_xy[0], start_xy[1], model.gear)
        self.winder = WinderHost(WinderControlParams(), LBarParams(), params.winder,
                                 params.tether, g)
        length0, _ = self.winder.lbar.length(pos0)
        self.plant.x[:] = initial_state(model, pos0, tether_length_m=length0)
        self.companion = Companion(params, gains, nav or NavigationParams(),
                                   EstimatorParams(kind="truth"))
        self.nav = self.companion.nav
        self.n_ctrl = round(1.0 / (self.plant.dt_s * gains.rate_hz))
        self.n_wind = round(1.0 / (self.plant.dt_s * WinderControlParams().rate_hz))
        self.dt_ctrl = 1.0 / gains.rate_hz
        self.k = 0
        self.inputs = PlantInputs()
        self.torque = 0.0
        self.motors = MotorState.OFF
        self.events: list[tuple[float, object, object]] = []
        self.max_taut = -math.inf
        #: whether the winch's reports reach the companion (False: the link is lost), and
        #: whether they say HEALTHY
        self.winch_link = True
        self.winch_healthy = True
        self.companion.start(0.0, self._state())

    def _state(self) -> VehicleState:
        x = self.plant.x.tolist()
        return VehicleState(tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]), tuple(x[RATES]))

    @property
    def t(self) -> float:
        """Simulated time [s]."""
        return self.k * self.plant.dt_s

    @property
    def pos(self) -> tuple[float, float, float]:
        """The UAV's true position [m]."""
        return tuple(self.plant.x[POS].tolist())

    def step(self) -> None:
        """One physics step (and the controllers when their periods come)."""
        plant, k = self.plant, self.k
        t = self.t
        if k % self.n_wind == 0:
            x = plant.x.tolist()
            tension = plant.tether_forces().drum_tension_n
            ws = self.winder.update(plant.tether_length_m, plant.drum_rate_rad_s, tension,
                                    tuple(x[POS]), tuple(x[VEL]))
            self.torque = ws.torque_n_m
            if self.winch_link:
                self.companion.winch_report(
                    t, plant.tether_length_m,
                    plant.drum_rate_rad_s * self.params.winder.drum_radius_m, tension,
                    healthy=self.winch_healthy)
            d = math.dist(tuple(x[POS]), (0.0, 0.0, 0.0))
            self.max_taut = max(self.max_taut, d - plant.tether_length_m)
        if k % self.n_ctrl == 0:
            out = self.companion.step(OnboardInputs(t, self._state()))
            for kind, value in self.nav.pop_events():
                self.events.append((t, kind, value))
            self.motors = out.motors
            self.inputs = PlantInputs(out.rotor_commands, out.armed, self.torque, True)
        else:
            self.inputs = self.inputs._replace(winder_torque_n_m=self.torque)
        plant.step(self.inputs)
        self.k += 1

    def control_step(self) -> None:
        """Step to the next control period."""
        self.step()
        while self.k % self.n_ctrl:
            self.step()

    def run_until(self, cond, limit_s: float) -> bool:
        """Step until ``cond(self)`` holds (checked each control period) or ``limit_s`` of
        simulated time more have passed; returns whether it held."""
        end = self.t + limit_s
        while self.t < end:
            self.control_step()
            if cond(self):
                return True
        return False

    def kinds(self) -> list[object]:
        """Event kinds so far, in order."""
        return [k for _, k, _ in self.events]

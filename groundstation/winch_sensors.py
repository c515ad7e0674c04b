"""What the winch's own sensors say: the winch sensor node's frames (the line's length and
speed, the load cell's tension and its sample clock, the node's heartbeat, the guide arm's
exit angles), the axis's bus voltage and current and its motor's current, the tension the
winch takes from them (:class:`TensionSource`), and the tether fix the station makes of
length, the load cell's tension and exit angles (``groundstation.tether_fix``).

The tension the winch acts on (the law's feed-forward, the over-tension pay-out, the slack
guard, the ground pre-tension, ``WINCH_STATUS``) is the load cell's; the motor's current
(``groundstation.winch_current``) takes its place while the load cell is silent (no
``Winch_Tension`` for ``load_cell_silence_s`` of encoder frames), reports itself unhealthy,
or disagrees with it by more than ``tension_disagree_n`` for ``tension_disagree_s``; each
change of source is said. Without a current (no ``Get_Iq`` on the bus) the load cell's last
reading stays the tension, as it always did. The tether fix takes the load cell alone."""

from __future__ import annotations

import enum
import math

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.lbar import LBarEstimator
from groundstation.tether_fix import FixScatter, ReportedWind, TetherFix, TetherFixer, WindSource
from groundstation.winch_current import CurrentTension
from groundstation.winch_params import WinchParams
from groundstation.winch_report import Notice, notice
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl

Vec3 = tuple[float, float, float]


def wrap_ms(d_ms: int) -> int:
    """A difference of two 16-bit millisecond clocks as the nearer of its two readings."""
    d = d_ms & 0xFFFF
    return d - 0x10000 if d >= 0x8000 else d


class TensionSource(enum.Enum):
    """Where the tension the winch acts on comes from."""

    LOAD_CELL = "load cell"     #: the load cell at the fairlead (Winch_Tension)
    CURRENT = "current"         #: the winder motor's current (Get_Iq), cruder


class WinchSensors:
    """The sensor node's latest readings and the tether fix made of them."""

    def __init__(self, fixer: TetherFixer | None, current: CurrentTension,
                 params: WinchParams) -> None:
        #: the tether fix (groundstation.tether_fix), on this station's own tether beliefs
        self.fixer = fixer
        #: the fix's recent scatter, which widens its covariance (the line's sway)
        self.scatter = FixScatter(fixer.p) if fixer is not None else None
        #: the vehicle's wind as the fix takes it (given it with wind_source = vehicle)
        self.wind = ReportedWind(fixer.p) if fixer is not None else None
        #: the tension from the motor's current (groundstation.winch_current)
        self.current = current
        self.p = params
        #: where :attr:`tension_n` comes from now
        self.source = TensionSource.LOAD_CELL
        self._since_load_cell = 0           # encoder frames since the last Winch_Tension
        self._disagree_frames = 0           # encoder frames in a row the two disagree
        self.fixes = 0
        """Tether fixes computed."""
        self.sensor_length_m = math.nan     # Winch_Length
        self.sensor_speed_m_s = math.nan
        #: the tension the winch acts on [N] (the load cell's, or the current's)
        self.tension_n = math.nan
        self.load_cell_n = math.nan         # last finite Winch_Tension [N]
        self.sensor_brake: bool | None = None
        self.load_cell_healthy: bool | None = None
        self.at_full_stop = False
        self.voltage_v = math.nan           # the axis's bus
        self.current_a = math.nan
        self.sample_time_ms: int | None = None
        self._sensor_clock_ms: int | None = None   # Sample_Time unwrapped [ms]
        #: the last Winch_Exit_Angle: (azimuth [rad], elevation [rad], sample time [ms]
        #: modulo 65536, valid), or None
        self.exit_angle: tuple[float, float, int, bool] | None = None
        self._clock_ms: int | None = None     # the winch's clock, unwrapped [ms]

    @property
    def sensor_clock_s(self) -> float | None:
        """The winch sensor node's clock [s]: the last ``Winch_Tension`` Sample_Time,
        unwrapped from its 16 bits, None before one came."""
        c = self._sensor_clock_ms
        return None if c is None else c * 1e-3

    # ------------------------------------------------------------------ the frames

    def on_bus_voltage_current(self, data: bytes) -> None:
        self.voltage_v, self.current_a = cp.decode_bus_voltage_current(data)

    def on_length(self, data: bytes) -> None:
        length_m, speed_m_s = cp.decode_winch_length(data)
        if math.isfinite(length_m) and math.isfinite(speed_m_s):
            self.sensor_length_m, self.sensor_speed_m_s = length_m, speed_m_s

    def on_tension(self, data: bytes) -> int | None:
        """A ``Winch_Tension`` frame; returns the stamp of the one before (None: none)."""
        last = self.sample_time_ms
        tension_n, self.sensor_brake, self.sample_time_ms = cp.decode_winch_tension(data)
        prev = self._sensor_clock_ms
        if prev is None:
            self._sensor_clock_ms = self.sample_time_ms
        else:
            self._sensor_clock_ms = prev + wrap_ms(self.sample_time_ms - prev)
        self._since_load_cell = 0
        if math.isfinite(tension_n):
            self.load_cell_n = tension_n
            if self.source is TensionSource.LOAD_CELL:
                self.tension_n = tension_n
        return last

    def on_iq(self, data: bytes) -> None:
        """A ``Get_Iq`` frame: the motor's measured q-axis current."""
        self.current.on_iq(cp.decode_iq(data).measured_a)

    def on_encoder(self, length_m: float, omega_rad_s: float,
                   motor_drives: bool) -> Notice | None:
        """An encoder frame (one control period): the current's estimate advanced (while
        the motor drives the drum: ``motor_drives``, and the sensor node reports the brake
        released) and the tension's source chosen (module docstring); returns the notice
        of a change."""
        p, cur = self.p, self.current
        cur.on_encoder(length_m, omega_rad_s, motor_drives and self.sensor_brake is not True)
        self._since_load_cell += 1
        lc, ct = self.load_cell_n, cur.tension_n
        if math.isfinite(lc) and math.isfinite(ct) and abs(lc - ct) > p.tension_disagree_n:
            self._disagree_frames += 1
        else:
            self._disagree_frames = 0
        dt = cur.dt_s
        silent = (self._since_load_cell * dt > p.load_cell_silence_s
                  or self.load_cell_healthy is False or not math.isfinite(lc))
        disagree = self._disagree_frames * dt > p.tension_disagree_s
        source = (TensionSource.CURRENT if math.isfinite(ct) and (silent or disagree)
                  else TensionSource.LOAD_CELL)
        said = None
        if source is not self.source:
            self.source = source
            why = "silent" if silent else "disagrees" if disagree else "back"
            said = notice(mavlink2.MAV_SEVERITY_WARNING if source is TensionSource.CURRENT
                          else mavlink2.MAV_SEVERITY_NOTICE,
                          f"winch: load cell {why}, tension from {source.value}")
        if source is TensionSource.CURRENT:
            self.tension_n = ct
        elif math.isfinite(lc):
            self.tension_n = lc
        return said

    def on_heartbeat(self, data: bytes) -> None:
        hb = cp.decode_winch_heartbeat(data)
        self.load_cell_healthy = hb.load_cell_healthy
        self.at_full_stop = hb.at_full_stop
        self.sensor_brake = hb.brake_engaged

    def on_exit_angle(self, data: bytes) -> bool:
        """A ``Winch_Exit_Angle`` frame; returns False for a direction no guide arm can
        read (below the ground, beyond the vertical, an azimuth off the circle): no fix
        from it."""
        az, el, stamp, valid = cp.decode_winch_exit_angle(data)
        good = -math.pi <= az <= math.pi and -0.1 <= el <= 0.5 * math.pi
        self.exit_angle = (az, el, stamp, valid and good)
        return good

    # ----------------------------------------------------------------- what they say

    def line_leaves(self, ground_elevation_rad: float, window_s: float) -> bool:
        """Whether the guide arm reads the line leaving the exit above the ground
        (``ground_elevation_rad``) in a reading no older than ``window_s`` [s] against the
        load cell's sample."""
        ea = self.exit_angle
        return bool(ea is not None and ea[3] and ea[1] >= ground_elevation_rad
                    and self.sample_time_ms is not None
                    and wrap_ms(self.sample_time_ms - ea[2]) <= 1e3 * window_s)

    def _fix_inputs_valid(self, length_m: float) -> bool:
        """Whether length, tension and a valid exit angle no older than ``max_age_s``
        against the tension's sample are at hand for the tether fix."""
        fixer, ea = self.fixer, self.exit_angle
        if (fixer is None or ea is None or not ea[3] or self.sample_time_ms is None
                or not (math.isfinite(length_m) and math.isfinite(self.load_cell_n))
                or self.load_cell_healthy is False):
            return False
        return abs(wrap_ms(self.sample_time_ms - ea[2])) * 1e-3 <= fixer.p.max_age_s

    def tether_reading(self, fix: TetherFix, length_m: float,
                       lbar: LBarEstimator) -> cl.TetherReading | None:
        """The raw reading the tether fix ``fix`` was made of (``length_m`` [m], the load
        cell's tension, the guide arm's angles, at the fix's sample time on the vehicle's
        clock) with the line's weight per metre as ``lbar`` estimates it (NaN: none yet),
        None without a valid exit angle."""
        ea = self.exit_angle
        if ea is None or not ea[3]:
            return None
        return cl.TetherReading(fix.sample_time_ms * 1e-3, length_m, self.load_cell_n, ea[0],
                                ea[1], lbar.estimated_weight_n_m)

    def measured_position_m(self, length_m: float, lbar: LBarEstimator) -> Vec3 | None:
        """The UAV's position [m] as the winder itself measures it (its tether fix's mean
        from length ``length_m`` [m], tension and exit angles, the line taken as hanging
        from the exit), None when the fix has no valid inputs: the slack floor's input
        (docs/control.md §3), whatever the vehicle reports or fuses."""
        if not self._fix_inputs_valid(length_m):
            return None
        fixer, ea = self.fixer, self.exit_angle
        assert fixer is not None and ea is not None
        # the tension as the trim low-passes it: a dynamic line's axial waves and snaps
        # (0-20 N at 20-25 Hz) would otherwise swing the fix, and the floor, which pays
        # out fast and takes back slowly, would ratchet the line out onto the ground
        return fixer.suspended_end(length_m, lbar.drum_tension_n(self.load_cell_n), ea[0],
                                   ea[1], lbar.weight_n_m())

    def set_wind(self, wind_m_s: Vec3, uav: tuple[Vec3, Vec3] | None,
                 uav_time_ms: int | None) -> None:
        """The vehicle's wind estimate [m/s] (z-up; its WIND_COV), taken at the time [ms]
        and height of its last reported (position [m], velocity [m/s]) ``uav`` (the
        message carries neither), gated by its horizontal speed: the tether fix's wind
        with ``wind_source = "vehicle"`` (groundstation.tether_fix.ReportedWind); ignored
        before a position with its time, or without a fix."""
        if self.wind is None or uav is None or uav_time_ms is None:
            return
        self.wind.report(uav_time_ms * 1e-3, wind_m_s, uav[0][2], math.hypot(*uav[1][:2]))

    def tether_fix(self, length_m: float, reported_m: Vec3 | None,
                   uav_time_ms: int | None, lbar: LBarEstimator) -> TetherFix | None:
        """The UAV's position from length, tension and exit angles now (``reported_m`` the
        position the vehicle reports, ``uav_time_ms`` its time), or None when one is
        missing, invalid or older than ``max_age_s`` against the tension's sample."""
        fixer, ea = self.fixer, self.exit_angle
        if not self._fix_inputs_valid(length_m):
            return None
        assert fixer is not None and ea is not None
        az, el, stamp, _ = ea
        if not fixer.readable(self.load_cell_n, el):
            return None
        t_ms = self._unwrap_ms(stamp, uav_time_ms)
        wind = wind_cov = None
        if self.wind is not None and WindSource(fixer.p.wind_source) is WindSource.VEHICLE:
            wind = self.wind.wind_m_s(t_ms * 1e-3)
            wind_cov = self.wind.covariance_m2_s2()
        pos, cov, ground = fixer.position(length_m, self.load_cell_n, az, el, reported_m,
                                          lbar.weight_n_m(), wind, wind_cov)
        self.fixes += 1
        if self.scatter is not None:
            cov = self.scatter.widen(t_ms * 1e-3, pos, cov, reported_m, ground)
        return TetherFix(pos, cov, t_ms, ground)

    def _unwrap_ms(self, stamp_ms: int, uav_time_ms: int | None) -> int:
        """The winch's 16-bit clock [ms] as a full time: the nearest to the vehicle's
        time of its last position (the same clock in the simulator), else carried on from
        the last one unwrapped."""
        ref = uav_time_ms if uav_time_ms is not None else self._clock_ms
        full = stamp_ms if ref is None else ref + wrap_ms(stamp_ms - ref)
        self._clock_ms = full
        return full

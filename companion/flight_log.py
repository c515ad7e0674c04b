"""The companion's onboard log, as ArduCopter keeps one: a DataFlash ``.bin`` per boot in
a log directory (``00000001.BIN``, ``00000002.BIN``, ... and ``LASTLOG.TXT``, as ArduPilot
names them), with ArduPilot's message names, field names, units and multipliers where
ArduPilot has the message, so that ``mavlogdump.py``, MAVExplorer and other log tools read
and graph it as an ArduCopter log.

Everything in it is what the companion knows: its sensors as the simulator link delivered
them, its navigation filter, its navigator; never the plant's state. ``TimeUS`` is the
companion's (simulated) clock [us]. Angles are in degrees, frames NED (position from the
EKF origin, the winder) and body FRD, as ArduPilot's.

Records, and when they are written (simulated time):

- ``FMT``, ``UNIT``, ``MULT``, ``FMTU`` at the start (companion.dataflash);
- ``PARM`` every parameter at the start and at each change (name, value); ``MSG`` every
  STATUSTEXT; ``MODE`` each mode change (mode number, reason 0);
- ``EV`` each event (:class:`LogEvent`: armed, disarmed, landed, airborne, home set) and
  ``ERR`` each failsafe or estimator error and its end (:class:`ErrorSubsystem`,
  :class:`ErrorCode`), as ArduCopter writes them;
- each GNSS fix (HIL_GPS): ``GPS`` (fix type, the GPS week ``GWk`` and its milliseconds
  ``GMS``, satellites, HDOP, latitude, longitude, altitude AMSL, ground speed and course,
  vertical speed down) and ``GPA`` (accuracies [m], the fix's time [ms], the time since the
  last fix [ms]). The fix's time is its ``time_usec`` (UNIX time when it is one, else the
  simulated time, mapped to the real time by :class:`LogClock`): log tools take the log's
  date from these records;
- at :data:`IMU_RATE_HZ`: ``IMU`` (the gyroscope [rad/s] and accelerometer [m/s^2] sample,
  temperature, health, sample rate);
- at :data:`RATE_HZ`: ``ATT`` (desired and flown roll, pitch, yaw), ``RATE`` (body rates
  [deg/s]), ``POS`` (lat, lng, altitude AMSL, above home, above origin [m]), ``CTUN``
  (throttle out, desired and flown altitude [m], desired and flown climb rate [m/s]),
  ``RCIN`` (the RC receiver's 14 channels [us]: 0, there is no receiver), ``RCOU`` (the
  rotor outputs as PWM [us], channels 1-4), ``BARO`` (altitude above the boot's, pressure
  altitude AMSL [m], pressure [Pa], temperature, climb rate), ``MAG`` (the field [mGauss]),
  and the filter's ``XKF1`` (attitude, velocity, position from the origin, gyro bias),
  ``XKF2`` (accelerometer bias, the wind states, Earth field, magnetometer bias) and
  ``XKQ`` (attitude quaternion, NED to body);
- at each check of the filter's health (companion.onboard.HEALTH_CHECK_S): ``XKF3`` (the
  innovations of GNSS velocity and position, barometric height and magnetic heading),
  ``XKF4`` (the square roots of the test ratios x 100, the fault, timeout, solution and
  GNSS-check bits) and the project's ``XKFT`` (the tether's innovation, test ratio,
  whether it is fused: the ground station's fix, or the raw reading fused tightly, whichever
  was tried last) and, with the tight fusion, ``XKTL`` (the line's states: weight and drag
  factors, the guide arm's biases [rad], and their standard deviations). Innovations are
  ArduPilot's sign: estimate minus measurement;
- ``TETH`` (the project's own): each winch report: paid-out length [m], line speed [m/s],
  tension [N].

:meth:`FlightLog.period` (the sensors, the filter, the events) and :meth:`FlightLog.record`
(the vehicle's telemetry) are called after the control period's answer is out; the records
are packed there (microseconds) and written by the writer's own thread.
"""

from __future__ import annotations

import contextlib
import math
import time
from enum import IntEnum
from pathlib import Path
from typing import TYPE_CHECKING

from companion.dataflash import DataFlashWriter, LogFormat
from companion.ekf import AidSource, EstimatorFlags, FilterHealth, HealthReason
from tuavdefs.frames import (
    enu_to_ned,
    flu_to_frd,
    local_enu_to_global,
    quat_enu_flu_to_ned_frd,
    quat_to_euler,
)
from tuavdefs.simlink import SENSOR_ABS_PRESSURE, SENSOR_ACCEL, SENSOR_GYRO, SENSOR_MAG

if TYPE_CHECKING:
    from companion.ekf import FilterStatus
    from companion.onboard import Companion, OnboardInputs, OnboardOutputs
    from companion.simlink_client import GpsFix, ImuSample

__all__ = ["FORMATS", "IMU_RATE_HZ", "RATE_HZ", "ErrorCode", "ErrorSubsystem", "FlightLog",
           "LogClock", "LogEvent", "gps_week_ms", "log_path", "next_log_number"]

#: Rate of the periodic records [Hz of simulated time].
RATE_HZ = 10.0
#: Rate of the IMU records [Hz of simulated time] (ArduCopter's 25 Hz IMU logging).
IMU_RATE_HZ = 25.0
#: The GPS epoch, 1980-01-06 00:00:00 UTC, as UNIX time [s]; GPS time's lead on UTC (the
#: leap seconds since, as log tools take it) [s]; a GPS week [s].
GPS_EPOCH_UNIX_S = 315964800
GPS_LEAP_S = 18
GPS_WEEK_S = 604800
#: A HIL_GPS ``time_usec`` at least this is UNIX time (MAVLink: the format is inferred from
#: the magnitude; this is 2001-09-09), below it the simulated time [us].
UNIX_USEC_MIN = 10**15
#: XKF4.GPS's bit for a fix whose claimed accuracy the filter refuses (EKF3's bad_hAcc).
GPS_CHECK_BAD_HACC = 1 << 1
_NAN_FAULTS = 0b11                  # XKF4.FS: quaternion and velocity not finite
_NOT_INITIALISED_FAULT = 1 << 7     # XKF4.FS: the filter is not initialised
_SS_USING_GPS = 1 << 13             # XKF4.SS (ArduPilot's nav_filter_status bits)
_SS_GPS_GLITCHING = 1 << 14
_SS_GPS_QUALITY_GOOD = 1 << 15
_SS_INITIALISED = 1 << 16
_SS_ESTIMATOR_BITS = 0x3FF          # the bits MAVLink's ESTIMATOR_STATUS_FLAGS shares
_RC_CHANNELS = 14


class LogEvent(IntEnum):
    """``EV`` ids: ArduPilot's numbers for the events the companion has."""

    ARMED = 10
    DISARMED = 11
    LAND_COMPLETE = 18
    SET_HOME = 25
    NOT_LANDED = 28


class ErrorSubsystem(IntEnum):
    """``ERR`` subsystems: ArduPilot's numbers, and the project's winder failsafe (a
    number beyond ArduPilot's)."""

    FAILSAFE_GCS = 8
    GPS = 11
    EKFCHECK = 16
    FAILSAFE_EKFINAV = 17
    FAILSAFE_WINCH = 200


class ErrorCode(IntEnum):
    """``ERR`` codes: ArduPilot's (their meaning depends on the subsystem)."""

    RESOLVED = 0
    """The error or failsafe ended."""
    OCCURRED = 1
    """A failsafe began."""
    BAD_VARIANCE = 2
    """EKFCHECK: the filter is unhealthy while armed; GPS: a glitch (the same number)."""


FORMATS = [
    LogFormat(64, "PARM", "QNf", "TimeUS,Name,Value", "s--", "F--"),
    LogFormat(65, "MSG", "QZ", "TimeUS,Message", "s-", "F-"),
    LogFormat(66, "MODE", "QMBB", "TimeUS,Mode,ModeNum,Rsn", "s---", "F---"),
    LogFormat(67, "ATT", "Qffffff", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw",
              "sddddhh", "F000000"),
    LogFormat(68, "RATE", "Qfff", "TimeUS,R,P,Y", "skkk", "F000"),
    LogFormat(69, "POS", "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt", "sDUmmm",
              "FGG000"),
    LogFormat(70, "CTUN", "Qfffff", "TimeUS,ThO,DAlt,Alt,DCRt,CRt", "s-mmnn", "F-0000"),
    LogFormat(71, "RCOU", "Q" + "H" * _RC_CHANNELS,
              "TimeUS," + ",".join(f"C{i}" for i in range(1, _RC_CHANNELS + 1)),
              "s" + "Y" * _RC_CHANNELS, "F" + "-" * _RC_CHANNELS),
    LogFormat(72, "TETH", "Qfff", "TimeUS,Len,Spd,Ten", "smnN", "F000"),
    LogFormat(73, "RCIN", "Q" + "H" * _RC_CHANNELS,
              "TimeUS," + ",".join(f"C{i}" for i in range(1, _RC_CHANNELS + 1)),
              "s" + "Y" * _RC_CHANNELS, "F" + "-" * _RC_CHANNELS),
    LogFormat(74, "EV", "QB", "TimeUS,Id", "s-", "F-"),
    LogFormat(75, "ERR", "QBB", "TimeUS,Subsys,ECode", "s--", "F--"),
    LogFormat(76, "GPS", "QBBIHBcLLeffffB",
              "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
              "s#-s-S-DUmnhnh-", "F--C-0BGGB000--"),
    LogFormat(77, "GPA", "QBCCCCfBIHeHH",
              "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,AEl,RTCMFU,RTCMFD",
              "s#-mmnd-ssm--", "F-BBBB0-CCB--"),
    LogFormat(78, "IMU", "QBffffffIIfBBHH",
              "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
              "s#EEEooo--O--zz", "F-000000-----00"),
    LogFormat(79, "BARO", "QBfffcfIffB",
              "TimeUS,I,Alt,AltAMSL,Press,Temp,CRt,SMS,Offset,GndTemp,Health",
              "s#mmPOnsmO-", "F-000B0C00-"),
    LogFormat(80, "MAG", "QBhhhhhhhhhBI",
              "TimeUS,I,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOX,MOY,MOZ,Health,S",
              "s#GGGGGGGGG-s", "F-CCCCCCCCC-F"),
    LogFormat(81, "XKF1", "QBccCfffffffccce",
              "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH",
              "s#ddhnnnnmmmkkkm", "F-BBB0000000BBBB"),
    LogFormat(82, "XKF2", "QBccccchhhhhhfff",
              "TimeUS,C,AX,AY,AZ,VWN,VWE,MN,ME,MD,MX,MY,MZ,IDX,IDY,IS",
              "s#ooonnGGGGGGoor", "F-BBBBBCCCCCC000"),
    LogFormat(83, "XKF3", "QBcccccchhhccff",
              "TimeUS,C,IVN,IVE,IVD,IPN,IPE,IPD,IMX,IMY,IMZ,IYAW,IVT,RErr,ErSc",
              "s#nnnmmmGGGdn--", "F-BBBBBBCCCBB00"),
    LogFormat(84, "XKF4", "QBHHHHHfffHBIHb",
              "TimeUS,C,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI",
              "s#-----rmm-----", "F-BBBBB000-----"),
    LogFormat(85, "XKQ", "QBffff", "TimeUS,C,Q1,Q2,Q3,Q4", "s#----", "F-0000"),
    LogFormat(86, "XKFT", "QBfffHB", "TimeUS,C,ITN,ITE,ITD,TR,U", "s#mmm--", "F-000B-"),
    LogFormat(87, "XKTL", "QBffffffff", "TimeUS,C,KW,KC,BPsi,BEps,SKW,SKC,SBPsi,SBEps",
              "s#--rr--rr", "F-00000000"),
]


def log_path(log_dir: Path, number: int) -> Path:
    """Log ``number``'s file in ``log_dir``."""
    return Path(log_dir) / f"{number:08d}.BIN"


def next_log_number(log_dir: Path) -> int:
    """One more than the highest log number in ``log_dir`` (1 in an empty one)."""
    numbers = [int(p.stem) for p in Path(log_dir).glob("*.BIN") if p.stem.isdigit()]
    return max(numbers, default=0) + 1


def gps_week_ms(utc_s: float) -> tuple[int, int]:
    """The GPS week (since 1980-01-06) and the milliseconds into it of UNIX time ``utc_s``
    [s] (GPS time leads UTC by :data:`GPS_LEAP_S`)."""
    ms = round((utc_s - GPS_EPOCH_UNIX_S + GPS_LEAP_S) * 1000.0)
    week, ms = divmod(ms, GPS_WEEK_S * 1000)
    return int(week), int(ms)


class LogClock:
    """The real time the companion's simulated clock stands for: UNIX time [s] =
    ``utc_at_zero_s`` + simulated time. Unset, it is anchored at the wall clock the first
    time it is asked (the run's start); the logs of later boots share it."""

    def __init__(self, utc_at_zero_s: float | None = None) -> None:
        self.utc_at_zero_s = utc_at_zero_s

    def utc_s(self, t_s: float) -> float:
        """UNIX time [s] of simulated time ``t_s`` [s]."""
        if self.utc_at_zero_s is None:
            self.utc_at_zero_s = time.time() - t_s
        return self.utc_at_zero_s + t_s


class _Schedule:
    """Due every ``1 / rate_hz`` [s] of simulated time, at ``phase`` x that interval past
    the log's start and its multiples (schedules of different phases put their records in
    different control periods). A call later than a whole interval waits for the grid's
    next point."""

    __slots__ = ("step_s", "phase_s", "base_s", "next_s")

    def __init__(self, rate_hz: float, phase: float = 0.0) -> None:
        self.step_s = 1.0 / rate_hz
        self.phase_s = phase * self.step_s
        self.base_s = self.next_s = math.inf

    def start(self, t0_s: float) -> None:
        """The grid from the log's start ``t0_s`` [s]."""
        self.base_s = self.next_s = t0_s + self.phase_s

    def due(self, t_s: float) -> bool:
        nxt = self.next_s
        if t_s < nxt - 1e-6:
            return False
        step = self.step_s
        if t_s - nxt < step - 1e-6:
            self.next_s = nxt + step
            return True
        base = self.base_s
        self.next_s = base + math.ceil((t_s - base) / step - 1e-6) * step
        return self.due(t_s)


def _i16(x: float) -> int:
    """``x`` rounded into an int16 (saturated; 0 if not a number)."""
    if -32768.0 <= x <= 32767.0:
        return round(x)
    return 0 if x != x else (32767 if x > 0 else -32768)


def _u16(x: float) -> int:
    """``x`` rounded into a uint16 (saturated; 0 if not a number)."""
    if 0.0 <= x <= 65535.0:
        return round(x)
    return 65535 if x > 0 else 0


def _i32(x: float) -> int:
    """``x`` rounded into an int32 (saturated; 0 if not a number)."""
    if -2147483648.0 <= x <= 2147483647.0:
        return round(x)
    return 0 if x != x else (2147483647 if x > 0 else -2147483648)


#: What the events are checked on each period (see FlightLog._events), at power-on:
#: disarmed, landed, no home, no failsafe, no estimator error.
_POWER_ON = (False, True, None, False, False, False, False)


class FlightLog:
    """One boot's log in ``log_dir``, global positions from ``origin`` (the winder's
    latitude deg, longitude deg, ground altitude m AMSL: the EKF origin); ``clock`` maps
    the simulated time to the real one (a new one, anchored at the first period, if not
    given)."""

    def __init__(self, log_dir: Path, origin: tuple[float, float, float],
                 clock: LogClock | None = None) -> None:
        self.dir = Path(log_dir)
        # a full disk or a lost folder costs the log (the writer then says so), not the boot
        with contextlib.suppress(OSError):
            self.dir.mkdir(parents=True, exist_ok=True)
        self.number = next_log_number(self.dir)
        with contextlib.suppress(OSError):
            (self.dir / "LASTLOG.TXT").write_text(f"{self.number}\n")
        self.writer = DataFlashWriter(log_path(self.dir, self.number), FORMATS)
        self.origin = origin
        self.clock = clock if clock is not None else LogClock()
        self._t_us = 0
        # the records of a rate on a grid from the log's first period, the grids apart:
        # fewer records in one period (the filter's checks come on the start's 5 Hz grid)
        self._telemetry = _Schedule(RATE_HZ, 0.25)
        self._slow = _Schedule(RATE_HZ, 0.5)
        self._fast = _Schedule(IMU_RATE_HZ, 0.25)
        self._started = False
        self._events_state = _POWER_ON
        self._status: FilterStatus | None = None
        self._healthy_once = False
        self._glitch = False
        self._gps_ms: int | None = None          # the last fix's time [ms]
        self._gps_bad_hacc = False
        self._baro_ground: tuple[float, float] | None = None   # (altitude m, temperature C)
        self._baro_last: tuple[float, float] | None = None     # (time s, altitude m)

    @property
    def path(self) -> Path:
        return self.writer.path

    def param(self, name: str, value: float) -> None:
        self.writer.write("PARM", self._t_us, name, float(value))

    def message(self, text: str) -> None:
        self.writer.write("MSG", self._t_us, text[:64])

    def mode(self, number: int) -> None:
        self.writer.write("MODE", self._t_us, number, number, 0)

    def tether(self, t_s: float, length_m: float, speed_m_s: float, tension_n: float
               ) -> None:
        self.writer.write("TETH", round(t_s * 1e6), length_m, speed_m_s, tension_n)

    def event(self, event: LogEvent) -> None:
        """An ``EV`` record now."""
        self.writer.write("EV", self._t_us, int(event))

    def error(self, subsystem: ErrorSubsystem, code: ErrorCode) -> None:
        """An ``ERR`` record now."""
        self.writer.write("ERR", self._t_us, int(subsystem), int(code))

    # ----- the control period's sensors, filter and events

    def period(self, inputs: OnboardInputs, out: OnboardOutputs, onboard: Companion
               ) -> None:
        """The records of one control period: ``inputs`` what the simulator link delivered,
        ``out`` what ``onboard`` (the companion's onboard step) made of them."""
        t = inputs.t_s
        self._t_us = t_us = round(t * 1e6)
        if not self._started:
            self._start(t)
        w = self.writer
        gps = inputs.gps
        if gps is not None:
            self._gps(t_us, gps, onboard)
        imu = inputs.imu
        fast, slow = self._fast, self._slow     # (the method called only when near due)
        if imu is not None and t >= fast.next_s - 1e-6 and fast.due(t):
            p, q, r = flu_to_frd(imu.gyro_flu_rad_s)
            ax, ay, az = flu_to_frd(imu.accel_flu_m_s2)
            bits = imu.fields_updated
            rate_hz = round(1.0 / onboard.dt_s)
            w.write("IMU", t_us, 0, p, q, r, ax, ay, az, 0, 0, imu.temperature_c,
                    int(bits & SENSOR_GYRO == SENSOR_GYRO),
                    int(bits & SENSOR_ACCEL == SENSOR_ACCEL), rate_hz, rate_hz)
        if t >= slow.next_s - 1e-6 and slow.due(t):
            if imu is not None:
                self._baro_mag(t, t_us, imu)
            state = out.state
            if onboard.filter is not None and state is not None:
                self._states(t_us, onboard, state)
        status = onboard.last_status
        if status is not self._status and status is not None:
            self._status = status
            self._checks(t_us, status, onboard)
        nav, fs = onboard.nav, onboard.failsafes
        armed = nav.armed
        healthy = onboard.navigation_healthy
        if healthy:
            self._healthy_once = True
        # (the EKF check from the filter's first health: not while a vehicle started in the
        # air flies open loop until it aligns)
        now = (armed, nav.landed, nav.home_m, fs.gcs_lost, fs.winch_lost,
               armed and self._healthy_once and not healthy, onboard.ekf_failsafe)
        if now != self._events_state:
            self._events(now)

    def _start(self, t_s: float) -> None:
        """The schedules' grids and the clock from the log's first time ``t_s`` [s]."""
        self._started = True
        for schedule in (self._telemetry, self._slow, self._fast):
            schedule.start(t_s)
        self.clock.utc_s(t_s)

    def _events(self, now: tuple) -> None:
        """``EV`` and ``ERR`` for what changed since the last period."""
        was = self._events_state
        self._events_state = now
        armed, landed, home = now[:3]
        if armed and not was[0]:
            self.event(LogEvent.ARMED)
        if landed != was[1]:        # (after arming, before the disarming it brings)
            self.event(LogEvent.LAND_COMPLETE if landed else LogEvent.NOT_LANDED)
        if was[0] and not armed:
            self.event(LogEvent.DISARMED)
        if home != was[2] and home is not None:
            self.event(LogEvent.SET_HOME)
        for i, subsystem, bad in ((3, ErrorSubsystem.FAILSAFE_GCS, ErrorCode.OCCURRED),
                                  (4, ErrorSubsystem.FAILSAFE_WINCH, ErrorCode.OCCURRED),
                                  (5, ErrorSubsystem.EKFCHECK, ErrorCode.BAD_VARIANCE),
                                  (6, ErrorSubsystem.FAILSAFE_EKFINAV, ErrorCode.OCCURRED)):
            if now[i] != was[i]:
                self.error(subsystem, bad if now[i] else ErrorCode.RESOLVED)

    def _gps(self, t_us: int, gps: GpsFix, onboard: Companion) -> None:
        """``GPS`` and ``GPA`` of a fix."""
        us = gps.time_usec
        utc = us * 1e-6 if us >= UNIX_USEC_MIN else self.clock.utc_s(us * 1e-6)
        week, week_ms = gps_week_ms(utc)
        ve, vn, vu = gps.velocity_enu_m_s
        course = math.degrees(math.atan2(ve, vn)) % 360.0
        self.writer.write(
            "GPS", t_us, 0, gps.fix_type, week_ms, week, gps.satellites_visible,
            _i16(gps.eph_m * 100.0), _i32(gps.lat_deg * 1e7), _i32(gps.lon_deg * 1e7),
            _i32(gps.alt_amsl_m * 100.0), math.hypot(ve, vn), course, -vu, 0.0, 1)
        sample_ms = (us // 1000) & 0xFFFFFFFF
        delta_ms = 0 if self._gps_ms is None else _u16(sample_ms - self._gps_ms)
        self._gps_ms = sample_ms
        self.writer.write(
            "GPA", t_us, 0, _u16(gps.epv_m * 100.0), _u16(gps.eph_m * 100.0),
            _u16(gps.epv_m * 100.0), 0, 0.0, 1, sample_ms, delta_ms, -2147483648, 0, 0)
        f = onboard.filter
        self._gps_bad_hacc = f is not None and not gps.eph_m <= f.params.gnss_max_eph_m

    def _baro_mag(self, t: float, t_us: int, imu: ImuSample) -> None:
        """``BARO`` and ``MAG`` of the period's sample."""
        alt_amsl, temp = imu.pressure_alt_m, imu.temperature_c
        if self._baro_ground is None and math.isfinite(alt_amsl):
            self._baro_ground = (alt_amsl, temp)   # the boot's calibration
        ground, ground_c = self._baro_ground or (alt_amsl, temp)
        alt = alt_amsl - ground
        last = self._baro_last
        climb = (alt - last[1]) / (t - last[0]) if last is not None and t > last[0] else 0.0
        self._baro_last = (t, alt)
        sample_ms = (imu.time_usec // 1000) & 0xFFFFFFFF
        bits = imu.fields_updated
        w = self.writer
        w.write("BARO", t_us, 0, alt, alt_amsl, imu.abs_pressure_hpa * 100.0,
                _i16(temp * 100.0), climb, sample_ms, 0.0, ground_c,
                int(bits & SENSOR_ABS_PRESSURE != 0 and math.isfinite(alt)))
        mx, my, mz = flu_to_frd(imu.mag_flu_gauss)
        w.write("MAG", t_us, 0, _i16(mx * 1e3), _i16(my * 1e3), _i16(mz * 1e3), 0, 0, 0,
                0, 0, 0, int(bits & SENSOR_MAG == SENSOR_MAG),
                imu.time_usec & 0xFFFFFFFF)

    def _states(self, t_us: int, onboard: Companion, state) -> None:
        """``XKF1``, ``XKF2``, ``XKQ``: the estimate flown (the filter's output) and the
        filter's bias states."""
        f = onboard.filter
        q_ned = quat_enu_flu_to_ned_frd(state.quat)
        roll, pitch, yaw = (math.degrees(a) for a in quat_to_euler(q_ned))
        vn, ve, vd = enu_to_ned(state.vel_m_s)
        pn, pe, pd = enu_to_ned(state.pos_m)
        gx, gy, gz = (math.degrees(v) * 100.0 for v in flu_to_frd(f.gyro_bias_rad_s))
        w = self.writer
        w.write("XKF1", t_us, 0, _i16(roll * 100.0), _i16(pitch * 100.0),
                _u16((yaw % 360.0) * 100.0) % 36000, vn, ve, vd, vd, pn, pe, pd, _i16(gx),
                _i16(gy), _i16(gz), _i32(self.origin[2] * 100.0))
        ax, ay, az = flu_to_frd(f.accel_bias_m_s2)
        en, ee, ed = enu_to_ned(f.earth_field_enu_gauss)
        bx, by, bz = flu_to_frd(f.mag_bias_gauss)
        # the wind states (zero without drag fusion, as EKF3's without its BCOEF)
        vwn, vwe, _ = enu_to_ned(f.wind_m_s)
        w.write("XKF2", t_us, 0, _i16(ax * 100.0), _i16(ay * 100.0), _i16(az * 100.0),
                _i16(vwn * 100.0), _i16(vwe * 100.0), _i16(en * 1e3), _i16(ee * 1e3),
                _i16(ed * 1e3), _i16(bx * 1e3),
                _i16(by * 1e3), _i16(bz * 1e3), 0.0, 0.0, 0.0)
        w.write("XKQ", t_us, 0, *q_ned)

    def _checks(self, t_us: int, st: FilterStatus, onboard: Companion) -> None:
        """``XKF3``, ``XKF4``, ``XKFT`` of a new filter status, and a GPS glitch's ``ERR``."""
        w = self.writer
        # ArduPilot's innovations are estimate - measurement, the filter's measurement -
        # estimate: negated, but for the height (up in the filter, down here) and the
        # heading (anticlockwise in the filter, clockwise here)
        ivn, ive, ivd = enu_to_ned(st.vel_innovation_m_s)
        ipn, ipe, _ = enu_to_ned(st.pos_innovation_m)
        w.write("XKF3", t_us, 0, _i16(-ivn * 100.0), _i16(-ive * 100.0), _i16(-ivd * 100.0),
                _i16(-ipn * 100.0), _i16(-ipe * 100.0), _i16(st.baro_innovation_m * 100.0),
                0, 0, 0, _i16(math.degrees(st.mag_innovation_rad) * 100.0), 0, 0.0, 0.0)
        initialised = st.health is not FilterHealth.INITIALISING
        sources, flags = st.sources, st.flags
        faults = ((_NAN_FAULTS if HealthReason.NAN in st.reasons else 0)
                  | (0 if initialised else _NOT_INITIALISED_FAULT))
        timeouts = 0
        if initialised:
            timeouts = (int(not sources & (AidSource.GNSS | AidSource.TETHER))
                        | int(EstimatorFlags.VELOCITY_HORIZ not in flags) << 1
                        | int(AidSource.BARO not in sources) << 2
                        | int(AidSource.MAG not in sources) << 3)
        glitch = EstimatorFlags.GPS_GLITCH in flags
        gps_checks = GPS_CHECK_BAD_HACC if self._gps_bad_hacc else 0
        solution = ((int(flags) & _SS_ESTIMATOR_BITS)
                    | (_SS_USING_GPS if AidSource.GNSS in sources else 0)
                    | (_SS_GPS_GLITCHING if glitch else 0)
                    | (_SS_GPS_QUALITY_GOOD if self._gps_ms is not None and not gps_checks
                       else 0)
                    | (_SS_INITIALISED if initialised else 0))
        w.write("XKF4", t_us, 0, _u16(st.velocity_variance * 100.0),
                _u16(st.pos_horiz_variance * 100.0), _u16(st.pos_vert_variance * 100.0),
                _u16(st.compass_variance * 100.0), 0, max(st.attitude_sigma_rad[:2]), 0.0,
                0.0, faults, timeouts, solution, gps_checks, 0)
        itn, ite, itd = enu_to_ned(st.tether_innovation_m)
        w.write("XKFT", t_us, 0, -itn, -ite, -itd, _u16(st.tether_variance * 100.0),
                int(AidSource.TETHER in sources))
        f = onboard.filter
        if f is not None and f.tether_line_fusion:
            w.write("XKTL", t_us, 0, *f.line_states, *f.line_sigmas)
        if glitch != self._glitch:
            self._glitch = glitch
            self.error(ErrorSubsystem.GPS,
                       ErrorCode.BAD_VARIANCE if glitch else ErrorCode.RESOLVED)

    # ----- the vehicle's telemetry

    def record(self, tm, ref, home_m) -> None:
        """The periodic records of telemetry ``tm`` (companion.telemetry.Telemetry) when
        due; ``ref`` the navigator's reference (None when not flying), ``home_m`` its home
        (None: unknown)."""
        self._t_us = t_us = round(tm.t_s * 1e6)
        if not self._started:
            self._start(tm.t_s)
        if not self._telemetry.due(tm.t_s):
            return
        w = self.writer
        roll, pitch, yaw = (math.degrees(a) for a in
                            quat_to_euler(quat_enu_flu_to_ned_frd(tm.quat)))
        des_yaw = yaw if ref is None else math.degrees(math.pi / 2 - ref.yaw_rad)
        w.write("ATT", t_us, roll, roll, pitch, pitch, des_yaw % 360.0, yaw % 360.0)
        p, q, r = (math.degrees(v) for v in flu_to_frd(tm.rates_rad_s))
        w.write("RATE", t_us, p, q, r)
        lat, lon, alt = local_enu_to_global(tm.pos_m, self.origin)
        home_z = home_m[2] if home_m is not None else 0.0
        w.write("POS", t_us, round(lat * 1e7), round(lon * 1e7), alt,
                tm.pos_m[2] - home_z, tm.pos_m[2])
        climb = -enu_to_ned(tm.vel_m_s)[2]
        d_alt, d_climb = ((tm.pos_m[2], climb) if ref is None
                          else (ref.pos_m[2], ref.vel_m_s[2]))
        w.write("CTUN", t_us, tm.throttle, d_alt, tm.pos_m[2], d_climb, climb)
        w.write("RCIN", t_us, *_NO_RC)
        motors = tm.motors or (0.0, 0.0, 0.0, 0.0)
        w.write("RCOU", t_us, *(1000 + round(1000 * min(max(c, 0.0), 1.0)) for c in motors),
                *_NO_RC[len(motors):])

    def close(self) -> None:
        self.writer.close()


#: The RC input channels' values without a receiver [us] (as ArduPilot logs them).
_NO_RC = (0,) * _RC_CHANNELS

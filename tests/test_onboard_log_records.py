"""The onboard DataFlash log's records as ArduPilot writes them (GPS, GPA, IMU, BARO, MAG,
EKF3's XKF1-4 and XKQ, the tether fix's XKFT, RCIN, RCOU, EV, ERR, with FMTU/UNIT/MULT),
from a real flight of the plant and companion processes: a take-off, a ground-station
failsafe and its end, a landing. A tap between the companion and the plant keeps what the
simulator link carried; the truths: those HIL_SENSOR and HIL_GPS frames as pymavlink
decodes them, the wall clock around the run (the log's date), the records' own schedules,
the flight the ground station flew, and pymavlink's DFReader and ``mavlogdump.py`` reading
the file."""

from __future__ import annotations

import contextlib
import math
import re
import shutil
import socket
import subprocess
import threading
import time

import pytest
from gcs_util import Vehicle, arm, command, wait_msg
from pymavlink import DFReader, mavutil

from companion.flight_log import IMU_RATE_HZ, RATE_HZ, ErrorCode, ErrorSubsystem, LogEvent
from tuavdefs.frames import global_to_local_enu
from tuavdefs.simlink import HOME_DEFAULT

M = mavutil.mavlink
#: One control period of the plant [us]: the records' times are the periods' times.
PERIOD_US = 4000


class SimLinkTap:
    """A TCP relay between the companion and the plant's simulator link (``Vehicle``'s
    ``sim_relay``) that keeps every byte the plant sent."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.from_plant = bytearray()
        self.plant_port = 0

    def __call__(self, plant_port: int) -> int:
        self.plant_port = plant_port
        threading.Thread(target=self._serve, daemon=True).start()
        return self.server.getsockname()[1]

    def _serve(self) -> None:
        comp, _ = self.server.accept()
        end = time.monotonic() + 60.0
        while True:
            try:
                plant = socket.create_connection(("127.0.0.1", self.plant_port))
                break
            except OSError:
                if time.monotonic() > end:
                    comp.close()
                    return
                time.sleep(0.05)
        for s in (comp, plant):
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        threading.Thread(target=self._pipe, args=(comp, plant, None), daemon=True).start()
        self._pipe(plant, comp, self.from_plant)

    @staticmethod
    def _pipe(src: socket.socket, dst: socket.socket, keep: bytearray | None) -> None:
        try:
            while data := src.recv(65536):
                if keep is not None:
                    keep += data
                dst.sendall(data)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                with contextlib.suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)

    def messages(self) -> dict[str, list]:
        """HIL_SENSOR and HIL_GPS as sent, decoded by pymavlink."""
        mav = M.MAVLink(None)
        mav.robust_parsing = True
        out: dict[str, list] = {"HIL_SENSOR": [], "HIL_GPS": []}
        for msg in mav.parse_buffer(bytes(self.from_plant)) or []:
            if msg.get_type() in out:
                out[msg.get_type()].append(msg)
        return out


def set_param(m, name: str, value: float, kind: int) -> None:
    m.mav.param_set_send(1, 1, name.encode(), value, kind)
    got = wait_msg(m, "PARAM_VALUE", lambda p: p.param_id == name, 10)
    assert got is not None and got.param_value == pytest.approx(value)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """Take-off to 6 m; the ground station silent with FS_GCS_ENABLE set (the failsafe:
    RTL), then heard again; LAND. The log read back, the link's frames, the wall clock."""
    tmp = tmp_path_factory.mktemp("records")
    tap = SimLinkTap()
    wall0 = time.time()
    veh = Vehicle(tmp, extra=("--log-dir", str(tmp / "logs")), sim_relay=tap)
    try:
        m = veh.connect()
        m.set_mode("GUIDED")
        assert arm(m).result == M.MAV_RESULT_ACCEPTED     # a ground station heard
        command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 6)
        assert wait_msg(m, "STATUSTEXT", lambda s: "Takeoff complete" in s.text, 60)
        set_param(m, "FS_GCS_TIMEOUT", 2.0, M.MAV_PARAM_TYPE_REAL32)
        set_param(m, "FS_GCS_ENABLE", 1, M.MAV_PARAM_TYPE_INT8)
        assert wait_msg(m, "STATUSTEXT", lambda s: "GCS Failsafe" in s.text, 30)
        # heard again (the failsafe off first: silent afterwards, it would come back)
        set_param(m, "FS_GCS_ENABLE", 0, M.MAV_PARAM_TYPE_INT8)
        m.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        time.sleep(0.5)
        m.set_mode("LAND")
        assert wait_msg(m, "STATUSTEXT", lambda s: "Disarmed" in s.text, 90)
        time.sleep(0.5)
    finally:
        veh.stop()
    wall1 = time.time()
    path = tmp / "logs" / "00000001.BIN"
    log = DFReader.DFReader_binary(str(path))
    rec: dict[str, list] = {}
    while (msg := log.recv_msg()) is not None:
        rec.setdefault(msg.get_type(), []).append(msg)
    return {"path": path, "log": log, "rec": rec, "wire": tap.messages(),
            "wall": (wall0, wall1)}


def steps_us(records) -> set[int]:
    stamps = [r.TimeUS for r in records]
    return {b - a for a, b in zip(stamps, stamps[1:], strict=False)}


def test_every_record_type_with_its_units(flight):
    rec, log = flight["rec"], flight["log"]
    assert {"FMT", "UNIT", "MULT", "FMTU", "GPS", "GPA", "IMU", "BARO", "MAG", "XKF1",
            "XKF2", "XKF3", "XKF4", "XKQ", "XKFT", "RCIN", "RCOU", "EV", "ERR", "ATT",
            "POS", "CTUN", "PARM", "MODE", "MSG"} <= set(rec)
    unit = {name: log.formats[log.name_to_id[name]] for name in ("GPS", "IMU", "XKF1",
                                                                  "BARO", "MAG")}
    assert unit["GPS"].get_unit("Lat") == "deglatitude"
    assert unit["GPS"].get_unit("GMS") == "ms"           # s with the multiplier 1e-3
    assert unit["IMU"].get_unit("GyrX") == "rad/s"
    assert unit["IMU"].get_unit("AccZ") == "m/s/s"
    assert unit["XKF1"].get_unit("PN") == "m"
    assert unit["BARO"].get_unit("Press") == "Pa"
    assert unit["MAG"].get_unit("MagX") == "mGauss"


def test_records_on_their_schedules(flight):
    rec = flight["rec"]
    tol = PERIOD_US // 2
    for name, rate in (("IMU", IMU_RATE_HZ), ("BARO", RATE_HZ), ("MAG", RATE_HZ),
                       ("XKF1", RATE_HZ), ("XKF2", RATE_HZ), ("XKQ", RATE_HZ),
                       ("ATT", RATE_HZ), ("RCIN", RATE_HZ), ("RCOU", RATE_HZ)):
        steps = steps_us(rec[name])
        assert max(steps) <= 1e6 / rate + tol and min(steps) >= 1e6 / rate - tol, name
    # the filter's checks at each of the companion's health checks: 0.2 s, or the first
    # period after when the sum of the periods' times falls just short of it
    for name in ("XKF3", "XKF4", "XKFT"):
        steps = steps_us(rec[name])
        assert min(steps) >= 200_000 - tol and max(steps) <= 200_000 + PERIOD_US, name
    # a GPS and a GPA for each fix the link carried, in its order
    wire = [(g.lat, g.lon, g.alt) for g in flight["wire"]["HIL_GPS"]]
    logged = [(round(g.Lat * 1e7), round(g.Lng * 1e7)) for g in rec["GPS"]]
    assert len(rec["GPA"]) == len(logged) >= len(wire) - 2 > 100
    assert logged == [(lat, lon) for lat, lon, _ in wire[:len(logged)]]


def test_the_gps_time_gives_the_real_date(flight):
    rec = flight["rec"]
    wall0, wall1 = flight["wall"]
    first = min((r for recs in rec.values() for r in recs if hasattr(r, "TimeUS")),
                key=lambda r: r._timestamp)
    assert wall0 - 1.0 <= first._timestamp <= wall1
    gps = rec["GPS"]
    assert gps[0].GWk > 2000 and 0 <= gps[0].GMS < 7 * 86400 * 1000
    # GPS time (GWk, GMS) and the records' clock advance together
    for g in (gps[len(gps) // 2], gps[-1]):
        gps_s = (g.GWk - gps[0].GWk) * 604800 + (g.GMS - gps[0].GMS) * 1e-3
        assert gps_s == pytest.approx((g.TimeUS - gps[0].TimeUS) * 1e-6, abs=0.002)
        assert g._timestamp - gps[0]._timestamp == pytest.approx(gps_s, abs=0.002)


def test_sensor_records_hold_what_the_link_carried(flight):
    rec, wire = flight["rec"], flight["wire"]
    sensors = {s.time_usec: s for s in wire["HIL_SENSOR"]}
    for imu in rec["IMU"]:
        s = sensors[imu.TimeUS]
        assert (imu.GyrX, imu.GyrY, imu.GyrZ) == pytest.approx((s.xgyro, s.ygyro, s.zgyro),
                                                               rel=1e-6, abs=1e-9)
        assert (imu.AccX, imu.AccY, imu.AccZ) == pytest.approx((s.xacc, s.yacc, s.zacc),
                                                               rel=1e-6, abs=1e-9)
        assert abs(imu.T - s.temperature) < 1e-4
        assert imu.GH == imu.AH == 1 and imu.GHz == 1e6 / PERIOD_US
    for baro in rec["BARO"]:
        s = sensors[baro.TimeUS]
        assert baro.AltAMSL == pytest.approx(s.pressure_alt, abs=1e-3)
        assert baro.Press == pytest.approx(s.abs_pressure * 100.0, rel=1e-6)
        assert baro.Alt == pytest.approx(s.pressure_alt - rec["BARO"][0].AltAMSL, abs=1e-3)
    for mag in rec["MAG"]:
        s = sensors[mag.TimeUS]
        assert abs(mag.MagX - s.xmag * 1e3) <= 0.5 and abs(mag.MagZ - s.zmag * 1e3) <= 0.5
    fixes = wire["HIL_GPS"]
    for g, fix in zip(rec["GPS"], fixes, strict=False):
        assert (g.Status, g.NSats) == (fix.fix_type, fix.satellites_visible)
        assert g.Alt == pytest.approx(fix.alt * 1e-3, abs=0.006)
        assert g.Spd == pytest.approx(math.hypot(fix.vn, fix.ve) * 0.01, abs=1e-5)
        assert abs(g.VZ - fix.vd * 0.01) < 1e-5
        assert g.HDop == pytest.approx(fix.eph * 0.01, abs=0.006)


def test_filter_records_follow_the_fixes(flight):
    rec = flight["rec"]
    gps = rec["GPS"]
    stamps = [g.TimeUS for g in gps]
    worst_h = worst_v = 0.0
    for x in rec["XKF1"]:
        i = min(range(len(stamps)), key=lambda k: abs(stamps[k] - x.TimeUS))
        east, north, up = global_to_local_enu(gps[i].Lat, gps[i].Lng, gps[i].Alt,
                                              HOME_DEFAULT)
        worst_h = max(worst_h, math.hypot(x.PN - north, x.PE - east))
        worst_v = max(worst_v, abs(-x.PD - up))
        q = next(k for k in rec["XKQ"] if k.TimeUS == x.TimeUS)
        assert math.hypot(q.Q1, q.Q2, q.Q3, q.Q4) == pytest.approx(1.0, abs=1e-5)
        # the quaternion's yaw (NED) is XKF1's
        yaw = math.degrees(math.atan2(2 * (q.Q1 * q.Q4 + q.Q2 * q.Q3),
                                      1 - 2 * (q.Q3 ** 2 + q.Q4 ** 2))) % 360.0
        assert abs((yaw - x.Yaw + 180.0) % 360.0 - 180.0) < 0.02
    assert worst_h < 0.5 and worst_v < 1.0
    # aligned and healthy in flight: the solution's attitude, velocity and position bits,
    # GNSS in use, the test ratios under their gates
    flying = [k for k in rec["XKF4"] if k.SS & (1 << 16)]
    assert flying and all(k.SS & 0b111111 == 0b111111 for k in flying[10:])
    assert all(k.SS & (1 << 13) for k in flying[10:])
    assert max(k.SP for k in flying[10:]) < 100 and max(k.SH for k in flying[10:]) < 100
    assert any(k.FS & (1 << 7) for k in rec["XKF4"])          # not initialised at first
    assert all(abs(k.IPN) < 1.0 and abs(k.IPE) < 1.0 for k in rec["XKF3"])


def test_events_and_errors_as_arducopter_writes_them(flight):
    rec = flight["rec"]
    ids = [e.Id for e in rec["EV"]]
    want = [LogEvent.SET_HOME, LogEvent.ARMED, LogEvent.NOT_LANDED, LogEvent.LAND_COMPLETE,
            LogEvent.DISARMED]
    it = iter(ids)
    assert all(w in it for w in want), ids
    errs = [(e.Subsys, e.ECode) for e in rec["ERR"]]
    assert errs == [(ErrorSubsystem.FAILSAFE_GCS, ErrorCode.OCCURRED),
                    (ErrorSubsystem.FAILSAFE_GCS, ErrorCode.RESOLVED)]
    failsafe = next(e for e in rec["ERR"] if e.ECode == ErrorCode.OCCURRED)
    text = next(t for t in rec["MSG"] if "GCS Failsafe" in t.Message)
    assert abs(text.TimeUS - failsafe.TimeUS) <= PERIOD_US
    motors = [r.C1 for r in rec["RCOU"]]
    assert max(motors) > 1200 and motors[0] == motors[-1] == 1000
    assert all(r.C1 == r.C14 == 0 for r in rec["RCIN"])      # no RC receiver


@pytest.mark.skipif(shutil.which("mavlogdump.py") is None, reason="pymavlink's tool")
def test_mavlogdump_reads_it_with_its_date(flight):
    out = subprocess.run([shutil.which("mavlogdump.py"), str(flight["path"])],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    days = {time.strftime("%Y-%m-%d", time.localtime(w)) for w in flight["wall"]}
    gps = [ln for ln in lines if ": GPS {" in ln]
    assert len(gps) == len(flight["rec"]["GPS"])
    assert {ln[:10] for ln in lines if ": " in ln[:30]} <= days
    assert any(": XKF4 {" in ln for ln in lines) and any(": ERR {" in ln for ln in lines)


#: MAVExplorer's graphs (MAVProxy's tools/graphs/*.xml) an ArduCopter log with one IMU,
#: barometer, compass, GPS and EKF3 core offers: each must be offered for this log too,
#: and plot finite values.
GRAPHS = ("EKF3/State Values/Pos NE", "EKF3/State Values/Velocity NE",
          "EKF3/State Values/Gyro Bias", "EKF3/State Values/Euler Yaw",
          "EKF3/Innovations/Position Innovation NE", "EKF3/Innovations/Velocity Innovation NE",
          "EKF3/Innovations/Normalised Innovations EK3 Lane1",
          "EKF3/State Values/Solution Status", "Sensors/Accelerometer/Accelerometers",
          "Sensors/Gyroscope/Gyro 1 XYZ", "Sensors/Barometer/Barometer",
          "Sensors/Compass/Compass", "Sensors/Compass/EarthField Error EK3 Lane1",
          "Sensors/GPS/GPS Accuracy", "Sensors/GPS/GPS Vel NE", "Speed/Ground Speed",
          "Attitude/Roll and Pitch", "Servos/Servos 1-4", "RC/RC Input 1-4")


def _fields(expression: str) -> list[str]:
    """An expression's terms as MAVExplorer evaluates them (without the axis suffix
    ``:2`` and a unit ``<...>``)."""
    out = []
    for term in expression.split():
        if term.endswith(">") and "<" in term:
            term = term[:term.rfind("<")]
        if len(term) > 2 and term[-2] == ":" and term[-1].isdigit():
            term = term[:-2]
        out.append(term)
    return out


def _value(term: str, messages: dict) -> float | None:
    """A term's value as MAVExplorer takes it (None: not available now)."""
    try:
        return mavutil.evaluate_expression(term, messages)
    except Exception:  # noqa: BLE001 - as MAVExplorer's expression_ok: not plottable
        return None


def test_mavexplorer_offers_its_graphs_and_they_plot(flight):
    lxml = pytest.importorskip("lxml.objectify")
    mavproxy = pytest.importorskip("MAVProxy")
    from pathlib import Path
    graphs: dict[str, list[str]] = {}
    for xml in sorted((Path(mavproxy.__file__).parent / "tools" / "graphs").glob("*.xml")):
        for g in lxml.fromstring(xml.read_bytes()).graph:
            graphs.setdefault(g.attrib["name"], []).extend(
                e.text for e in g.expression if e.text)
    mlog = mavutil.mavlink_connection(str(flight["path"]), zero_time_base=False)
    points: dict[str, int] = {}
    while (msg := mlog.recv_msg()) is not None:
        kind = msg.get_type()
        for name in GRAPHS:
            for expr in graphs[name]:
                terms = _fields(expr)
                if not any(re.search(rf"\b{kind}\b", t) for t in terms):
                    continue        # (plotted when one of its messages comes)
                values = [_value(t, mlog.messages) for t in terms]
                if all(v is not None and math.isfinite(v) for v in values):
                    points[name] = points.get(name, 0) + 1
                    break
    assert {name: points.get(name, 0) for name in GRAPHS if points.get(name, 0) < 50} == {}

"""The real ground-station process (``python -m groundstation``) between a real python-can
udp_multicast bus and a real pymavlink TCP server. On the bus, this script is the winder:
the plant's own simulated ODrive axis and winch sensors (``sitl.odrive_axis``) around the
plant's drum model (``sitl.winder``), stepped in real time (1 kHz physics, frames on a 4 ms
grid as the plant sends them) under a constant line tension. On the component link it is
the companion: it serves TCP, sends the UAV's LOCAL_POSITION_NED as system 1 component 1,
and ground-station commands as system 255 component 190 (as the companion forwards them).
Run inside a private network namespace; prints one JSON line of observations for
tests/test_groundstation_process.py to judge."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402

from sitl.odrive_axis import OdriveAxis, WinchSensors  # noqa: E402
from sitl.winder import WinderModel  # noqa: E402
from tests.gcs_util import free_port
from tests.netns import paper_law  # noqa: E402
from tuavdefs import can_protocol as cp  # noqa: E402
from tuavdefs import component_link as cl  # noqa: E402
from tuavdefs.canbus import CanLink  # noqa: E402
from tuavdefs.frames import enu_to_ned  # noqa: E402
from tuavdefs.params import SystemParams  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
UAV = (10.0, 0.0, 5.0)
START_LENGTH_M = 12.0
TENSION_N = 5.0
ENC_ID = cp.frame_id(cp.AXIS_NODE_ID_DEFAULT, cp.Cmd.GET_ENCODER_ESTIMATES)
NAN = math.nan



class Winder:
    """The axis, the sensors and the drum on the bus, in real time."""

    def __init__(self, link: CanLink) -> None:
        p = SystemParams()
        self.r_w = p.winder.drum_radius_m
        self.model = WinderModel(p.winder, p.tether)
        self.axis = OdriveAxis(torque_limit_nm=p.winder.motor_torque_limit_n_m,
                               vel_limit_rev_s=p.winder.motor_speed_limit_rad_s / (2 * math.pi))
        self.sensors = WinchSensors()
        self.link = link
        self.theta = START_LENGTH_M / self.r_w
        self.omega = 0.0
        self.n = 0
        self.t0 = time.monotonic()
        self.encoder_on = True
        self.host_frames: list[tuple[float, str, object]] = []   # (wall, message, value)
        self.encoder_sent: list[float] = []

    @property
    def length(self) -> float:
        return self.theta * self.r_w

    def service(self) -> None:
        while True:
            rx = self.link.recv(timeout_s=0.0)
            if rx is None:
                return
            now = time.monotonic()
            spec = cp.spec_for_id(rx.arbitration_id)
            if spec is not None and spec.direction is cp.Direction.HOST_TO_AXIS:
                try:
                    value = spec.decode(rx.data)
                except cp.CanFrameError:
                    value = "bad"
                self.host_frames.append((now, spec.name, value))
            elif spec is not None and rx.is_remote:
                self.host_frames.append((now, spec.name, "RTR"))
            for f in self.axis.handle(now - self.t0, rx.arbitration_id, rx.data, rx.is_remote,
                                      rx.is_extended):
                self.link.send(f.arbitration_id, f.data, f.is_remote, len(f.data))

    def step_to_now(self) -> None:
        target = time.monotonic() - self.t0
        while (self.n + 1) * 1e-3 <= target:
            braked = not self.axis.enabled
            applied = self.model.motor_torque_n_m(self.axis.torque_command_nm, self.omega,
                                                  self.axis.enabled)
            acc = self.model.acceleration(self.theta, self.omega, applied, TENSION_N, braked)
            before = self.omega
            self.omega += acc * 1e-3
            self.theta += self.omega * 1e-3
            self.theta, self.omega = self.model.project(self.theta, self.omega, before, braked)
            self.n += 1
            if self.n % 4:
                continue
            t = self.n * 1e-3
            two_pi = 2 * math.pi
            frames = self.axis.tick(t, self.theta / two_pi, self.omega / two_pi, applied, 48.0)
            frames += self.sensors.tick(t, self.length, self.omega * self.r_w, TENSION_N,
                                        braked, False, False)
            for f in frames:
                if f.arbitration_id == ENC_ID and not f.is_remote:
                    if not self.encoder_on:
                        continue
                    self.encoder_sent.append(time.monotonic())
                self.link.send(f.arbitration_id, f.data, f.is_remote, len(f.data))


class Companion:
    """The component link's server end, as the companion is to the winch."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(f"tcpin:127.0.0.1:{port}", dialect="common",
                                               source_system=255, source_component=190)
        self.conn.mav.robust_parsing = True
        self.fc = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)    # the autopilot's own ids
        self.msgs: list[tuple[float, str, dict]] = []
        self._next_position = 0.0

    def pump(self) -> None:
        while True:
            m = self.conn.recv_match(blocking=False)
            if m is None:
                break
            d = m.to_dict()
            d["src"] = [m.get_srcSystem(), m.get_srcComponent()]
            if m.get_type() == "STATUSTEXT":
                d["text"] = m.text
            self.msgs.append((time.monotonic(), m.get_type(), d))
        now = time.monotonic()
        if now >= self._next_position and self.conn.port is not None:
            self._next_position = now + 0.02
            n = enu_to_ned(UAV)
            self.conn.write(self.fc.local_position_ned_encode(
                0, *n, 0.0, 0.0, 0.0).pack(self.fc))

    def command_long(self, target: int, *params: float) -> float:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(1, target, mavlink2.MAV_CMD_DO_WINCH, 0, *p)
        return time.monotonic()

    def command_int(self, target: int, *params: float) -> float:
        p = list(params) + [NAN] * (4 - len(params))
        self.conn.mav.command_int_send(1, target, 0, mavlink2.MAV_CMD_DO_WINCH, 0, 0, *p,
                                       0, 0, 0.0)
        return time.monotonic()

    def of(self, kind: str, since: float = 0.0) -> list[tuple[float, dict]]:
        return [(t, d) for t, k, d in self.msgs if k == kind and t >= since]


def main() -> int:
    port = free_port()
    comp = Companion(port)
    link = CanLink("udp_multicast")
    # the paper's law: the drum here pulls a constant 5 N, no line, which the tension law
    # (the default), regulating the line's pull to its set-point, winds in to the taut
    # floor (FULLY_RETRACTED); the paper's law follows L-bar, which the modes are checked on
    law_dir = Path(tempfile.mkdtemp(prefix="gs_session_"))
    law = paper_law.write(law_dir)
    gs = subprocess.Popen([sys.executable, "-m", "groundstation", "--can", "udp_multicast",
                           "--mavlink", f"127.0.0.1:{port}", "--control", str(law["control"])],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out: dict = {}
    winder = None

    def run(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if winder is not None:
                winder.service()
                winder.step_to_now()
            comp.pump()
            time.sleep(0.0003)

    def run_until(cond, timeout: float = 30.0) -> bool:
        """Run until ``cond()`` holds (a busy machine may take much longer than the
        physics needs), at most ``timeout`` [s wall]."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if cond():
                return True
            run(0.01)
        return False

    def settled(since: list) -> bool:
        """The drum still (under 1 mm/s) for 0.5 s of its own time."""
        if abs(winder.omega * winder.r_w) > 1e-3:
            since[0] = winder.n
        return winder.n - since[0] >= 500

    def run_until_settled(timeout: float = 30.0) -> bool:
        mark = [winder.n]
        return run_until(lambda: settled(mark), timeout)

    def ack_after(t0: float, timeout: float = 5.0) -> dict | None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            acks = comp.of("COMMAND_ACK", t0)
            if acks:
                t, d = acks[0]
                return {**d, "latency_s": t - t0}
            run(0.005)
        return None

    def texts_after(t0: float) -> list[list]:
        return [[d["severity"], d["text"]] for _, d in comp.of("STATUSTEXT", t0)]

    try:
        # the ground station connects (its first heartbeat), then the winder appears
        deadline = time.monotonic() + 60.0
        while not comp.of("HEARTBEAT") and time.monotonic() < deadline:
            run(0.05)
        hb = comp.of("HEARTBEAT")
        out["heartbeat"] = hb[0][1] if hb else None
        winder = Winder(link)
        # (its first answer may take seconds on a busy machine: the compiled law loads)
        run_until(lambda: winder.axis.state == cp.AxisState.CLOSED_LOOP_CONTROL, 180.0)
        run(0.2)
        run_until_settled()
        out["armed_state"] = int(winder.axis.state)
        out["first_answer_after_s"] = (winder.host_frames[0][0] - winder.t0
                                       if winder.host_frames else None)
        out["first_host_frames"] = [[n, str(v)] for _, n, v in winder.host_frames[:4]]
        out["relaxed_length_m"] = winder.length
        # WINCH_STATUS rate while frames flow (real time: simulated = wall)
        # (per second of the winder's own time: the rate is of simulated time)
        t0, n0 = time.monotonic(), winder.n
        run(2.0)
        st = comp.of("WINCH_STATUS", t0)
        out["status_rate_hz"] = len(st) / ((winder.n - n0) * 1e-3)
        out["status_sample"] = st[-1][1]

        # 1. pay out 1 m at 0.5 m/s (COMMAND_LONG to the winch)
        start = winder.length
        t0 = comp.command_long(169, 0, 1, 1.0, 0.5)
        out["length_ack"] = ack_after(t0)
        run_until(lambda: winder.length - start >= 0.5)
        out["length_mid_speed_m_s"] = winder.omega * winder.r_w
        run_until(lambda: winder.length - start >= 0.99, 10.0)
        run_until_settled()
        out["length_paid_m"] = winder.length - start

        # 2. wind in 5 m (COMMAND_INT to the autopilot): clamped to the taut floor
        t0 = comp.command_int(1, 0, 1, -5.0, 0.5)
        out["clamp_ack"] = ack_after(t0)
        run(0.5)
        run_until_settled()
        out["clamp_texts"] = texts_after(t0)
        out["clamp_length_m"] = winder.length

        # 3. rate control, 0.25 m/s for 2 s (to every component)
        start = winder.length
        t0 = comp.command_long(0, 0, 2, NAN, 0.25)
        out["rate_ack"] = ack_after(t0)
        n0 = winder.n
        run_until(lambda: winder.n - n0 >= 2000)      # 2 s of the winder's time
        out["rate_paid_m"] = winder.length - start
        out["rate_status_flags"] = comp.of("WINCH_STATUS")[-1][1]["status"]

        # 4. retract: to the straight-line distance + min slack
        t0 = comp.command_long(169, 1, 6)
        out["retract_ack"] = ack_after(t0)
        run(0.5)
        run_until_settled()
        out["retract_texts"] = texts_after(t0)
        out["retract_length_m"] = winder.length
        out["retract_status"] = comp.of("WINCH_STATUS")[-1][1]

        # 5. hold: the axis idles, the brake holds the drum
        t0 = comp.command_int(0, 0, 5)
        out["hold_ack"] = ack_after(t0)
        run_until(lambda: winder.axis.state == cp.AxisState.IDLE)
        run(0.3)
        out["hold_frames"] = [[n, str(v)] for t, n, v in winder.host_frames
                              if t >= t0 and n == "Set_Axis_State"][:3]
        out["hold_state"] = int(winder.axis.state)
        held = winder.length
        run(1.0)
        out["hold_drift_m"] = winder.length - held
        out["hold_status_flags"] = comp.of("WINCH_STATUS")[-1][1]["status"]

        # 6. relaxed again: re-armed, back on L-bar
        t0 = comp.command_long(1, 0, 0)
        out["relax_ack"] = ack_after(t0)
        run_until(lambda: winder.axis.state == cp.AxisState.CLOSED_LOOP_CONTROL)
        run(0.5)
        run_until_settled()
        out["relax_frames"] = [[n, str(v)] for t, n, v in winder.host_frames
                               if t >= t0 and n != "Get_Bus_Voltage_Current"][:4]
        out["relax_state"] = int(winder.axis.state)
        out["relax_length_m"] = winder.length

        # 7. what is refused, and what is not for us
        refused = {}
        for name, target, params in [("deliver", 169, (0, 4)), ("load_payload", 169, (0, 9)),
                                     ("instance", 169, (3, 0)),
                                     ("nan_length", 169, (0, 1, NAN, 0.5)),
                                     ("nan_rate", 169, (0, 2, NAN, NAN))]:
            t0 = comp.command_long(target, *params)
            ack = ack_after(t0)
            run(0.05)
            refused[name] = {"ack": ack, "texts": texts_after(t0)}
        t0 = comp.command_long(42, 0, 5)
        refused["other_component"] = {"ack": ack_after(t0, 1.0), "texts": texts_after(t0)}
        out["refused"] = refused
        out["state_after_refused"] = int(winder.axis.state)

        # 8. encoder frames stop for 1.5 s, then come back
        winder.encoder_on = False
        run(1.5)
        t_stop = max(t for t in winder.encoder_sent)
        winder.encoder_on = True
        t_back = time.monotonic()
        run(1.5)
        run_until(lambda: winder.axis.state == cp.AxisState.CLOSED_LOOP_CONTROL)
        run_until_settled()
        idles = [t - t_stop for t, n, v in winder.host_frames
                 if t > t_stop and n == "Set_Axis_State" and v == cp.AxisState.IDLE]
        out["lost_idle_after_s"] = idles[0] if idles else None
        out["lost_texts"] = [[d["severity"], d["text"], t - t_stop]
                             for t, d in comp.of("STATUSTEXT", t_stop)]
        lost_status = [(t, d["status"]) for t, d in comp.of("WINCH_STATUS", t_stop + 0.15)
                       if t < t_back]
        out["lost_status_times"] = [t - t_stop for t, _ in lost_status]
        out["lost_status_flags"] = sorted({f for _, f in lost_status})
        out["lost_heartbeats"] = len([t for t, _ in comp.of("HEARTBEAT", t_stop)
                                      if t < t_back])
        out["back_frames"] = [[n, str(v), t - t_back] for t, n, v in winder.host_frames
                              if t >= t_back and n != "Get_Bus_Voltage_Current"][:4]
        out["back_state"] = int(winder.axis.state)
        out["back_errors"] = int(winder.axis.active_errors)
        out["back_status_flags"] = comp.of("WINCH_STATUS")[-1][1]["status"]
        out["back_length_m"] = winder.length
        out["axis_dropped"] = dict(winder.axis.counters)
    finally:
        gs.terminate()
        try:
            out["gs_out"] = gs.communicate(timeout=20)[0]
        except subprocess.TimeoutExpired:
            gs.kill()
            out["gs_out"] = gs.communicate()[0]
        out["gs_rc"] = gs.returncode
        link.close()
        comp.conn.close()
        shutil.rmtree(law_dir, ignore_errors=True)
    print(json.dumps(out, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())

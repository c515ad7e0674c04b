"""A first pymavlink script as a new user writes it: connect to TCP 5760, and on the first
GLOBAL_POSITION_INT (the vehicle knows where it is) switch to GUIDED and arm. ArduPilot
streams GLOBAL_POSITION_INT before its EKF is ready, so that arm may be refused; it must
then be refused with a PreArm text before anything said the vehicle was ready. Then it
waits for the pre-arm checks to pass (SYS_STATUS's PREARM_CHECK health), arms once more,
takes off to 3 m and lands. Run unchanged against ``tuav-sitl up``; its last line is what
it saw, as JSON: the first arm's result and the readiness reports received before it."""

import json

from pymavlink import mavutil

M = mavutil.mavlink
m = mavutil.mavlink_connection("tcp:127.0.0.1:5760")
ready_seen: set[str] = set()
texts: list[str] = []


def readiness(msg) -> None:
    """Note which of the vehicle's reports say it is ready."""
    kind = msg.get_type()
    if kind == "HOME_POSITION":
        ready_seen.add("HOME_POSITION")
    elif kind == "EKF_STATUS_REPORT" and msg.flags & 512:
        ready_seen.add("EKF_STATUS_REPORT 512")
    elif kind == "SYS_STATUS":
        for name in ("PREARM_CHECK", "SENSOR_GPS", "AHRS"):
            bit = getattr(M, f"MAV_SYS_STATUS_{name}")
            if msg.onboard_control_sensors_health & bit:
                ready_seen.add(f"SYS_STATUS {name}")
    elif kind == "STATUSTEXT":
        texts.append(msg.text)


def wait(mtype, condition=lambda msg: True, timeout_s=60.0):
    """The next message of this type meeting the condition (noting readiness on the way)."""
    while True:
        msg = m.recv_match(blocking=True, timeout=timeout_s)
        if msg is None:
            raise TimeoutError(f"no {mtype} within {timeout_s} s")
        if msg.get_srcComponent() != 1:
            continue
        readiness(msg)
        if msg.get_type() == mtype and condition(msg):
            return msg


def arm() -> int:
    m.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    return wait("COMMAND_ACK", lambda a: a.command == M.MAV_CMD_COMPONENT_ARM_DISARM).result


wait("HEARTBEAT")
m.target_system, m.target_component = 1, 1
wait("GLOBAL_POSITION_INT")
m.set_mode("GUIDED")
wait("COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_SET_MODE)
before = sorted(ready_seen)          # what said "ready" before the arm went out
first = arm()
print(f"first arm: {first}", flush=True)
if first != M.MAV_RESULT_ACCEPTED:
    why = wait("STATUSTEXT", lambda s: s.text.startswith("PreArm"), 10).text
    print(f"refused: {why}", flush=True)
    wait("SYS_STATUS", lambda s: s.onboard_control_sensors_health
         & M.MAV_SYS_STATUS_PREARM_CHECK)
    second = arm()
    print(f"armed once the pre-arm checks passed: {second}", flush=True)
    assert second == M.MAV_RESULT_ACCEPTED, texts
m.mav.command_long_send(1, 1, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 3)
wait("GLOBAL_POSITION_INT", lambda g: g.relative_alt > 2700)
m.mav.command_long_send(1, 1, M.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
wait("HEARTBEAT", lambda h: not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
print("landed and disarmed", flush=True)
print(json.dumps({"first_arm": first, "ready_before": before,
                  "refusals": [t for t in texts if t.startswith("PreArm")]}))

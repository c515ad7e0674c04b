"""``tuav-sitl candump`` on a real udp_multicast bus: a sender puts known frames on it and
two candump processes (default format with --decode, and -L) print them. Run inside a
private network namespace; prints one JSON line."""

import json
import subprocess
import sys
import time
from pathlib import Path

from tuavdefs import can_protocol as cp
from tuavdefs.canbus import CanLink

ROOT = Path(__file__).resolve().parents[2]
FRAMES = [
    (cp.frame_id(0, cp.Cmd.SET_INPUT_TORQUE), cp.encode_set_input_torque(1.5), False),
    (cp.frame_id(0, cp.Cmd.GET_ENCODER_ESTIMATES), cp.encode_encoder_estimates(2.25, -0.5),
     False),
    (cp.frame_id(0, cp.Cmd.GET_TORQUES), bytes(8), True),
    (cp.frame_id(0, cp.Cmd.ESTOP), b"", False),
    (cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_LENGTH),
     cp.encode_winch_length(12.5, 0.25), False),
]


def _group_members() -> int:
    """How many sockets of this network namespace have joined a multicast group beyond the
    all-hosts ones (the users columns of /proc/net/igmp and igmp6; the namespace is ours
    alone)."""
    users = 0
    for line in Path("/proc/net/igmp").read_text().splitlines()[1:]:
        fields = line.split()
        if line.startswith("\t") and len(fields) >= 2 and fields[0] != "010000E0":
            users += int(fields[1])
    for line in Path("/proc/net/igmp6").read_text().splitlines():
        fields = line.split()
        if len(fields) >= 4 and not fields[2].startswith(("ff02", "ff01")):
            users += int(fields[3])
    return users


def _wait_for_members(n: int, timeout_s: float) -> None:
    """Wait until ``n`` sockets have joined (then a little longer), at most ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while _group_members() < n and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(0.2)


def main() -> int:
    log = Path(sys.argv[1]) / "bus.log"
    cmd = [sys.executable, "-m", "tuav_sitl", "candump", "--can", "udp_multicast",
           "--count", str(len(FRAMES)), "--timeout", "20"]
    dump_l = subprocess.Popen([*cmd, "-L", "--log", str(log)], cwd=ROOT,
                              stdout=subprocess.PIPE, text=True)
    dump_d = subprocess.Popen([*cmd, "--decode"], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    # a recorder as up runs it, but asleep for 60 s after its first burst: the frames after
    # the first are still queued on its socket when SIGTERM stops it
    rec_log = Path(sys.argv[1]) / "recorder.log"
    recorder = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "candump", "--can",
                                 "udp_multicast", "-s", "2", "--interval", "60", "--log",
                                 str(rec_log)], cwd=ROOT)
    _wait_for_members(3, 60.0)   # all have joined the group (a busy machine is slow)
    link = CanLink("udp_multicast")
    for fid, data, remote in FRAMES:
        link.send(fid, data, is_remote=remote, dlc=len(data))
        time.sleep(0.05)
    out_l = dump_l.communicate(timeout=60)[0]
    out_d = dump_d.communicate(timeout=60)[0]
    link.close()
    recorder.terminate()
    recorder.wait(timeout=30)
    decoded = subprocess.run([sys.executable, "-m", "cantools", "decode", str(cp.dbc_path())],
                             input=out_l, capture_output=True, text=True, timeout=60)
    print(json.dumps({"L": out_l.splitlines(), "default": out_d.splitlines(),
                      "log_file": log.read_text().splitlines(),
                      "recorder_log": rec_log.read_text().splitlines(),
                      "recorder_rc": recorder.returncode,
                      "cantools": decoded.stdout, "cantools_rc": decoded.returncode}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

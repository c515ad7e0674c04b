"""CanLink's own udp_multicast implementation against python-can's bus, both ways, in one
process: frames arrive intact, remote frames keep their DLC, own frames are dropped. Run
inside a private network namespace; prints one JSON line."""

import json
import time

import can

from tuavdefs.canbus import CanLink


def main() -> int:
    a, b = CanLink("udp_multicast"), CanLink("udp_multicast")
    pc = can.Bus(interface="udp_multicast", channel="239.74.163.2", hop_limit=0)
    try:
        a.send(0x29, b"\x01\x02\x03")
        a.send(0x2A, b"", True, dlc=8)
        pc.send(can.Message(arbitration_id=0x123, data=b"\xaa\xbb", is_extended_id=False))
        pc.send(can.Message(arbitration_id=0x1ABCDE, data=b"\x05", is_extended_id=True))
        time.sleep(0.05)
        got_b = [b.recv(0.2) for _ in range(4)]
        got_a = [a.recv(0.2) for _ in range(2)]
        extra_a = a.recv(0.05)
        got_pc = [pc.recv(0.2) for _ in range(2)]
        out = {
            "b": [[f.arbitration_id, f.data.hex(), f.is_remote, f.is_extended]
                  for f in got_b if f],
            "a": [[f.arbitration_id, f.data.hex()] for f in got_a if f],
            "a_extra": extra_a is not None, "own_dropped": a.own_frames_dropped,
            "pc": [[m.arbitration_id, bytes(m.data).hex(), m.is_remote_frame, m.dlc]
                   for m in got_pc if m],
            "stamp_ok": all(f and abs(f.timestamp - time.time()) < 5.0 for f in got_b),
        }
        # a burst of frames sent back to back, taken in one call as they arrived
        out["empty_ready"] = b.recv_ready()
        out["burst_sent"] = a.send_frames([(0x31, b"\x01", False), (0x32, bytes(8), True),
                                           (0x33, b"", False)])
        time.sleep(0.05)
        out["burst"] = [[f.arbitration_id, f.data.hex(), f.is_remote, f.is_extended]
                        for f in b.recv_ready()]
        got_pc = []
        while (m := pc.recv(0.2)) is not None:
            got_pc.append(m)
        out["burst_pc"] = [[m.arbitration_id, bytes(m.data).hex(), m.is_remote_frame, m.dlc]
                           for m in got_pc if 0x31 <= m.arbitration_id <= 0x33]
        out["fileno_ok"] = a.fileno() == a._mc.rx.fileno() >= 0
    finally:
        pc.shutdown()
        a.close()
        b.close()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

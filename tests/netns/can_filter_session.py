"""The kernel's socket filter of :class:`tuavdefs.canbus.CanLink` on udp_multicast: it drops
the datagrams of one UDP source port (the link's own), and without it the link drops them
itself. Run inside a private network namespace; prints one JSON line."""

import json
import socket
import struct
import time

from tuavdefs import canbus
from tuavdefs.canbus import MULTICAST_PORT, CanLink

#: Frames of the unread burst (more than a default receive buffer holds).
BURST = 3000


def _texts(link: CanLink) -> list[str]:
    got = []
    while (f := link.recv(0.05)) is not None:
        got.append(f.data.decode())
    return got


def main() -> int:
    a, b = CanLink("udp_multicast"), CanLink("udp_multicast")
    # a plain member of the group whose filter drops b's source port
    watcher = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    watcher.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    attached = canbus.attach_socket_filter(
        watcher, canbus.drop_source_port_filter(b._mc.own_port))
    watcher.bind(("", MULTICAST_PORT))
    watcher.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                       socket.inet_aton(canbus.DEFAULT_GROUP) + struct.pack("@I", 0))
    watcher.settimeout(0.2)
    # a link on a kernel that refuses socket filters
    attach = canbus.attach_socket_filter
    canbus.attach_socket_filter = lambda sock, program: False
    try:
        c = CanLink("udp_multicast")
    finally:
        canbus.attach_socket_filter = attach
    try:
        for text in ("from a", "from a", "from a"):
            a.send(0x29, text.encode())
        b.send(0x2A, b"from b")
        c.send(0x2B, b"from c")
        c.send(0x2B, b"from c")
        time.sleep(0.05)
        a_got, c_got = _texts(a), _texts(c)
        seen = []
        watcher.settimeout(0.05)
        try:
            while True:
                raw = watcher.recv(4096)
                seen.append(canbus.WireCodec().decode(raw)[1].decode())
        except TimeoutError:
            pass
        out = {
            "filter_attached": attached and a._mc.kernel_filter,
            "filtered_socket_got": sorted(set(seen) - {"from c"}),
            "a_got": sorted(set(a_got) - {"from c"}),
            "a_user_dropped": a._mc._own_dropped,
            "a_own_dropped": a.own_frames_dropped,
            "fallback_got": sorted(set(c_got) - {"from a"}),
            "fallback_own_dropped": c.own_frames_dropped,
            "fallback_filter": c._mc.kernel_filter,
        }
        # a burst nobody reads meanwhile: a link with the default receive buffer loses the
        # end of it, one with a recorder's buffer keeps every frame
        small, big = CanLink("udp_multicast"), CanLink("udp_multicast")
        granted = big.set_receive_buffer(4 * 1024 * 1024)
        sender = CanLink("udp_multicast")
        for i in range(BURST):
            sender.send(0x30, i.to_bytes(4, "little"))
        time.sleep(0.1)
        small_got, big_got = len(small.recv_ready()), big.recv_ready()
        for link in (small, big, sender):
            link.close()
        out.update(burst_granted=granted, burst_small_got=small_got,
                   burst_big_got=[int.from_bytes(f.data, "little") for f in big_got])
    finally:
        watcher.close()
        for link in (a, b, c):
            link.close()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

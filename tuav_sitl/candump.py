"""``tuav-sitl candump``: the live winder bus, printed as can-utils' ``candump`` prints it.

Works on every bus spec the stack uses (SocketCAN or udp_multicast), so it is the way to
watch the bus where ``candump`` itself cannot (no SocketCAN). Output is line-buffered, so
``tuav-sitl candump -L | python -m cantools decode <the DBC>`` works; ``--decode`` appends
the signals decoded with the project's DBC; ``--log FILE`` also writes candump ``-L`` lines
to a file (flushed at least once a second). Timestamps are the kernel's receive times.

Frames are printed in bursts: after a wake-up every frame already waiting is read and the
output flushed once. A recorder that need not show frames the moment they pass (``tuav-sitl
up``'s, which logs to a file with ``-s 2``) also waits ``--interval`` between bursts, so it
wakes up a hundred times a second rather than once a frame: in lockstep at 20 times real
time the bus carries several thousand frames a second, and a wake-up per frame cost the
stack as much CPU as the ground station. Such a recorder asks for a receive buffer of
:data:`RECORDER_BUFFER_BYTES`, which holds about half a second of that traffic: ``tuav-sitl
up`` runs it at idle priority in lockstep (:mod:`tuav_sitl.realtime`), where it may read
late but must not lose a frame.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from typing import TextIO

from tuav_sitl.candump_format import format_default, format_log
from tuavdefs.can_protocol import dbc_path
from tuavdefs.canbus import CanBusError, CanLink
from tuavdefs.logfile import LogFile, guard_stdio, mb_to_bytes

#: The interface name printed for a udp_multicast bus (candump needs a name).
MULTICAST_IFACE = "udpmc0"
#: Receive buffer [bytes] a recorder (``--interval``) asks for.
RECORDER_BUFFER_BYTES = 4 * 1024 * 1024


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``tuav-sitl candump``."""
    ap.add_argument("-L", dest="log_format", action="store_true",
                    help="log format: (timestamp) iface id#data")
    ap.add_argument("--decode", action="store_true", help="append the DBC's decoded signals")
    ap.add_argument("--can", default="auto", metavar="SPEC",
                    help="auto, socketcan:IFACE, udp_multicast[:GROUP]")
    ap.add_argument("--log", default=None, help="also write -L lines to this file")
    ap.add_argument("--log-max-mb", type=float, default=None, metavar="MB",
                    help="end --log's file when it reaches this size (default: no cap)")
    ap.add_argument("--count", type=int, default=None, help="stop after N frames")
    ap.add_argument("--timeout", type=float, default=None,
                    help="stop after this many seconds without a frame")
    ap.add_argument("-s", dest="silent", type=int, choices=(0, 2), default=0,
                    help="silent mode, as candump's: 2 prints nothing (with --log: only log)")
    ap.add_argument("--interval", type=float, default=0.0, metavar="S",
                    help="wait this long [s] between bursts of frames (a recorder's "
                         "fewer wake-ups; frames keep their receive times; also asks for "
                         "a 4 MiB receive buffer)")


def run_candump(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Print frames to ``out`` (the standard output at the call, by default) until
    interrupted (or ``--count``/``--timeout``); returns the exit code."""
    if out is None:     # read at the call: a default bound at import keeps a stale stream
        out = sys.stdout
    try:
        link = CanLink(args.can)
    except CanBusError as exc:
        print(f"tuav-sitl candump: {exc}", file=sys.stderr)
        return 1
    if args.interval > 0.0:
        link.set_receive_buffer(RECORDER_BUFFER_BYTES)
    if args.silent == 2:
        guard_stdio()   # a recorder: its stderr (a file in the run folder) may fill up
    iface = link.channel if link.interface == "socketcan" else MULTICAST_IFACE
    db = None
    if args.decode:
        import cantools

        db = cantools.database.load_file(str(dbc_path()), strict=True)
    def log_ended(why: str) -> None:
        print(f"tuav-sitl candump: {why}; the bus is still printed", file=sys.stderr,
              flush=True)

    log_file = (LogFile(args.log, text=True, append=True,
                        max_bytes=mb_to_bytes(args.log_max_mb), on_end=log_ended)
                if args.log else None)
    stop = {"now": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    show = args.silent == 0
    n = 0
    bad = 0
    last_rx = time.monotonic()
    counted = {"done": False}

    def take(frames: list) -> None:
        """Print and log a burst of frames (the log flushed at most once a second)."""
        nonlocal n, bad
        lines: list[str] = []
        logged: list[str] = []
        for f in frames:
            ts = f.timestamp if f.timestamp > 0.0 else time.time()
            try:
                log_line = (format_log(ts, iface, f.arbitration_id, f.data, f.is_remote,
                                       f.is_extended)
                            if log_file is not None or args.log_format else "")
                line = (log_line if args.log_format else format_default(
                    iface, f.arbitration_id, f.data, f.is_remote, f.is_extended,
                    len(iface))) if show else ""
            except ValueError as exc:   # a datagram no CAN frame can be: said, skipped
                bad += 1
                if bad == 1 or bad % 1000 == 0:
                    print(f"tuav-sitl candump: {bad} bad frame(s) skipped, the last: "
                          f"{exc}", file=sys.stderr, flush=True)
                continue
            if show:
                if db is not None and not f.is_remote:
                    line += _decoded(db, f.arbitration_id, f.data)
                lines.append(line)
            if log_file is not None:
                logged.append(log_line)
            n += 1
            if args.count is not None and n >= args.count:
                stop["now"] = counted["done"] = True
                break
        if lines:
            out.write("\n".join(lines) + "\n")
            out.flush()
        if log_file is not None and logged:
            log_file.write("\n".join(logged) + "\n")

    try:
        while not stop["now"]:
            rx = link.recv(timeout_s=0.1)
            now = time.monotonic()
            if rx is None:
                if args.timeout is not None and now - last_rx > args.timeout:
                    break
                continue
            last_rx = now
            take([rx, *link.recv_ready()])
            # (in steps of at most 50 ms: a SIGTERM ends the wait, as sleep resumes after
            # its handler)
            end = time.monotonic() + args.interval
            while not stop["now"] and (left := end - time.monotonic()) > 0.0:
                time.sleep(min(left, 0.05))
        if stop["now"] and not counted["done"]:
            # stopped (SIGTERM): what the bus carried until now is still queued on the
            # socket (a recorder at idle priority may be behind): logged too
            take(link.recv_ready())
    except KeyboardInterrupt:
        pass
    except BrokenPipeError:
        return 0
    finally:
        link.close()
        if log_file is not None:
            log_file.close()
    return 0


def _decoded(db, arbitration_id: int, data: bytes) -> str:  # noqa: ANN001 - cantools Database
    try:
        msg = db.get_message_by_frame_id(arbitration_id)
        values = msg.decode(data, decode_choices=True)
    except (KeyError, ValueError):
        return "  ::  (not in the DBC)"
    body = ", ".join(f"{k}: {v}" for k, v in values.items())
    return f"  ::  {msg.name}({body})"

"""MAVLink 2 message signing, as ArduPilot does it: the key, its file, its timestamps.

A key is 32 bytes. MAVProxy's ``signing setup PASSPHRASE`` makes it as the SHA-256 of the
ASCII passphrase (:func:`key_from_passphrase`); a key file holds it as 64 hexadecimal
digits (:func:`read_key_file`). A signed frame carries a link id, a 48-bit timestamp in
10 µs units since 2015-01-01 00:00 UTC, and the first 6 bytes of SHA-256(key, frame).

Once a key is set (:func:`set_key` on a ``MAVLinkSigning`` state) a link signs what it
sends and accepts only frames signed with the key whose timestamp is newer than the last
one accepted from the same stream (link id, system, component); a stream not heard from
before is accepted at most a minute behind this end's own timestamp. Unsigned frames are
refused except :data:`UNSIGNED_ALLOWED` (ArduPilot's list: what a radio modem injects).
:class:`SigningMavlink` is pymavlink's parser with the check made in the safe order: the
signature first, then the timestamp, and only a frame that passes both moves a stream's
timestamp (pymavlink's own moves it before it has checked the signature, so one forged
frame with a far-future timestamp would lock the true sender out).

An all-zero key with a zero initial timestamp in ``SETUP_SIGNING`` turns signing off
(:func:`is_disable`).
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

__all__ = ["KEY_BYTES", "NEW_STREAM_WINDOW", "SIGNING_EPOCH_UNIX_S", "UNSIGNED_ALLOWED",
           "SigningError", "SigningMavlink", "is_disable", "key_file_text",
           "key_from_hex", "key_from_passphrase", "read_key_file", "refresh_timestamp",
           "set_key", "timestamp_now"]

#: Bytes in a signing key.
KEY_BYTES = 32
#: The signing clock's epoch, 2015-01-01 00:00:00 UTC [s since the Unix epoch].
SIGNING_EPOCH_UNIX_S = 1420070400
#: Ticks of the signing clock per second (its unit is 10 µs).
TICKS_PER_S = 100_000
#: How far behind this end's timestamp a stream not heard from before may start [ticks]
#: (one minute, as MAVLink's reference implementations take it).
NEW_STREAM_WINDOW = 60 * TICKS_PER_S
#: Message ids accepted unsigned once signing is on (ArduPilot's accept list).
UNSIGNED_ALLOWED = frozenset({mavlink2.MAVLINK_MSG_ID_RADIO_STATUS})


class SigningError(ValueError):
    """A key, passphrase or key file that cannot be used, said in one line."""


def key_from_passphrase(passphrase: str) -> bytes:
    """MAVProxy's key for ``signing setup PASSPHRASE``: SHA-256 of the ASCII text."""
    if not passphrase:
        raise SigningError("the signing passphrase is empty")
    try:
        data = passphrase.encode("ascii")
    except UnicodeEncodeError:
        raise SigningError("the signing passphrase must be ASCII (as MAVProxy's)") from None
    return hashlib.sha256(data).digest()


def key_from_hex(text: str) -> bytes:
    """The key written as 64 hexadecimal digits (surrounding white space ignored)."""
    digits = text.strip()
    if len(digits) != 2 * KEY_BYTES:
        raise SigningError(f"a signing key is {2 * KEY_BYTES} hexadecimal digits "
                           f"({KEY_BYTES} bytes), not {len(digits)} characters")
    try:
        return bytes.fromhex(digits)
    except ValueError:
        raise SigningError("a signing key is hexadecimal digits only") from None


def key_file_text(key: bytes | None) -> str:
    """A key file's text: the key in hexadecimal, or all zeros for signing off."""
    return (key or bytes(KEY_BYTES)).hex() + "\n"


def read_key_file(path: Path | str) -> bytes | None:
    """The key in ``path``; None if the file does not exist, is empty or holds the
    all-zero key (signing off). Raises :class:`SigningError` for anything else."""
    p = Path(path)
    try:
        text = p.read_text(encoding="ascii")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise SigningError(f"cannot read the signing key file {p}: {exc}") from None
    if not text.strip():
        return None
    try:
        key = key_from_hex(text)
    except SigningError as exc:
        raise SigningError(f"{p}: {exc}") from None
    return None if key == bytes(KEY_BYTES) else key


def timestamp_now(now_unix_s: float | None = None) -> int:
    """The signing clock now [10 µs ticks since 2015-01-01 UTC] (from the wall clock, or
    ``now_unix_s`` [s since the Unix epoch])."""
    now = time.time() if now_unix_s is None else now_unix_s
    return max(int((now - SIGNING_EPOCH_UNIX_S) * TICKS_PER_S), 0)


def is_disable(secret_key: Any, initial_timestamp: int) -> bool:
    """Whether a SETUP_SIGNING's key and timestamp mean 'signing off' (all zeros)."""
    return initial_timestamp == 0 and not any(bytes(secret_key))


def _accept_unsigned(_mav: Any, msg_id: int) -> bool:
    return msg_id in UNSIGNED_ALLOWED


def set_key(signing: Any, key: bytes | None, initial_timestamp: int = 0) -> None:
    """Turn signing on with ``key`` (None: off) on a pymavlink ``MAVLinkSigning`` state:
    what is sent is signed, only correctly signed frames (and :data:`UNSIGNED_ALLOWED`)
    are accepted; the timestamp moves to at least ``initial_timestamp`` and the clock."""
    if key is None:
        signing.secret_key = None
        signing.sign_outgoing = False
        signing.allow_unsigned_callback = None
        return
    if len(key) != KEY_BYTES:
        raise SigningError(f"a signing key is {KEY_BYTES} bytes, not {len(key)}")
    signing.secret_key = bytes(key)
    signing.sign_outgoing = True
    signing.allow_unsigned_callback = _accept_unsigned
    signing.timestamp = max(signing.timestamp, int(initial_timestamp), timestamp_now())


def refresh_timestamp(signing: Any) -> None:
    """Keep the outgoing timestamp at least the clock's (each frame adds only one tick,
    and a peer that starts listening later refuses a stream more than a minute behind
    its own clock)."""
    if signing.secret_key is not None:
        signing.timestamp = max(signing.timestamp, timestamp_now())


class SigningMavlink(mavlink2.MAVLink):
    """pymavlink's MAVLink 2 parser and packer, the signature checked before the
    timestamp is taken (see the module docstring)."""

    def check_signature(self, msgbuf: bytearray, srcSystem: int,  # noqa: N803 - pymavlink's
                        srcComponent: int) -> bool:
        """Whether the signed frame ``msgbuf`` is good: its signature made with the key,
        its timestamp newer than its stream's last (or, for a new stream, at most
        :data:`NEW_STREAM_WINDOW` behind this end's)."""
        signing = self.signing
        key = signing.secret_key
        if key is None or len(msgbuf) < 13:
            return False
        if hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6] != bytes(msgbuf[-6:]):
            return False
        link_id = msgbuf[-13]
        timestamp = int.from_bytes(msgbuf[-12:-6], "little")
        stream = (link_id, srcSystem, srcComponent)
        last = signing.stream_timestamps.get(stream)
        if last is not None:
            if timestamp <= last:
                return False      # a replay, or an old frame
        elif timestamp + NEW_STREAM_WINDOW < signing.timestamp:
            return False
        signing.stream_timestamps[stream] = timestamp
        signing.timestamp = max(signing.timestamp, timestamp)
        return True

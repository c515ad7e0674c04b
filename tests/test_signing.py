"""MAVLink 2 signing, as ArduPilot does it: a real plant and companion driven by real
pymavlink clients over TCP. SETUP_SIGNING from a ground station turns signing on (and is
kept in the key file); from then on the vehicle signs what it sends, unsigned and wrongly
signed commands (arm, force disarm) are ignored, a correctly signed one is taken, and a
replayed signed frame is refused on its own link and on another. Then the key rules on
their own: MAVProxy's passphrase, the key file, a forged timestamp."""

from __future__ import annotations

import socket
import time

import pytest
from gcs_util import Vehicle, arm, command, wait_msg
from netns_util import netns_available, run_session
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs import signing as sg

M = mavutil.mavlink
KEY = sg.key_from_passphrase("correct-horse-battery-staple")
WRONG_KEY = sg.key_from_passphrase("not-the-key")
FORCE = 21196.0


def armed_heartbeat(m, timeout: float = 10.0):
    """The vehicle's next heartbeat (component 1)."""
    return wait_msg(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1, timeout)


def is_armed(hb) -> bool:
    return bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def no_ack(m, cmd: int, wait_s: float = 3.0) -> bool:
    """Whether no COMMAND_ACK for ``cmd`` reaches ``m`` within ``wait_s`` [s wall]."""
    return wait_msg(m, "COMMAND_ACK", lambda a: a.command == cmd, wait_s) is None


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("signing")
    key_file = tmp / "signing.key"
    veh = Vehicle(tmp, extra=("--signing-key-file", str(key_file)))
    rec = {"veh": veh, "key_file": key_file}
    try:
        yield rec
    finally:
        rec["logs"] = veh.stop()


def test_setup_signing_turns_signing_on_and_is_kept_in_the_key_file(vehicle):
    veh = vehicle["veh"]
    m = veh.connect()
    assert not armed_heartbeat(m).get_signed()          # no key yet: unsigned
    m.mav.setup_signing_send(1, 1, list(KEY), sg.timestamp_now())
    # from now on the client signs and accepts only frames signed with the key
    m.setup_signing(KEY, sign_outgoing=True)
    text = wait_msg(m, "STATUSTEXT", lambda s: "Signing" in s.text, 10)
    assert text is not None and "key set" in text.text and text.get_signed()
    hb = armed_heartbeat(m)
    assert hb is not None and hb.get_signed() and hb.get_link_id() == 0
    end = time.monotonic() + 10
    while time.monotonic() < end and vehicle["key_file"].read_text().strip() != KEY.hex():
        time.sleep(0.1)
    assert sg.read_key_file(vehicle["key_file"]) == KEY
    vehicle["m"] = m


def _client(veh, key: bytes | None):
    """Another TCP client: unsigned (``key`` None) or signing with ``key``; it reads
    whatever the vehicle sends, whatever its signature."""
    c = mavutil.mavlink_connection(f"tcp:127.0.0.1:{veh.tcp_port}", source_system=254,
                                   source_component=190)
    # (pymavlink makes a new MAVLink 2 parser, without the key, at the first frame)
    assert c.wait_heartbeat(timeout=20) is not None
    if key is not None:
        c.setup_signing(key, sign_outgoing=True, allow_unsigned_callback=lambda *_: True)
        assert c.mav.command_long_encode(1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(
            c.mav)[2] & M.MAVLINK_IFLAG_SIGNED      # what it sends is signed
    return c


def test_unsigned_and_wrongly_signed_arm_are_ignored(vehicle):
    veh, m = vehicle["veh"], vehicle["m"]
    for key in (None, WRONG_KEY):
        c = _client(veh, key)
        c.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, FORCE, 0, 0, 0,
                                0, 0)
        assert no_ack(c, M.MAV_CMD_COMPONENT_ARM_DISARM)
        c.close()
    assert not is_armed(armed_heartbeat(m))
    dropped = wait_msg(m, "STATUSTEXT", lambda s: "unsigned or badly signed" in s.text, 15)
    assert dropped is not None


def test_signed_commands_are_taken_and_a_replayed_disarm_is_refused(vehicle):
    veh, m = vehicle["veh"], vehicle["m"]
    # a signed force-disarm on the ground, captured as an attacker would capture it
    disarm = m.mav.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, FORCE,
                                       0, 0, 0, 0, 0).pack(m.mav)
    m.write(disarm)
    ack = wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_COMPONENT_ARM_DISARM)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    m.set_mode("GUIDED")
    assert wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_SET_MODE).result \
        == M.MAV_RESULT_ACCEPTED
    assert arm(m).result == M.MAV_RESULT_ACCEPTED
    ack = command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    assert wait_msg(m, "GLOBAL_POSITION_INT", lambda g: g.relative_alt > 4000, 60)
    # in the air: the captured disarm replayed on its own link and on a raw connection,
    # and a force-disarm unsigned and wrongly signed
    m.write(disarm)
    assert no_ack(m, M.MAV_CMD_COMPONENT_ARM_DISARM)
    with socket.create_connection(("127.0.0.1", veh.tcp_port)) as raw:
        raw.sendall(disarm)
        time.sleep(1.0)
    for key in (None, WRONG_KEY):
        c = _client(veh, key)
        c.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, FORCE, 0, 0, 0,
                                0, 0)
        assert no_ack(c, M.MAV_CMD_COMPONENT_ARM_DISARM)
        c.close()
    assert is_armed(armed_heartbeat(m))
    assert wait_msg(m, "GLOBAL_POSITION_INT", lambda g: g.relative_alt > 4000, 10)
    # the key's holder is obeyed
    ack = command(m, M.MAV_CMD_NAV_LAND)
    assert ack.result == M.MAV_RESULT_ACCEPTED


def test_signing_off_by_an_all_zero_key(vehicle):
    veh, m = vehicle["veh"], vehicle["m"]
    m.mav.setup_signing_send(1, 1, [0] * 32, 0)
    assert wait_msg(m, "STATUSTEXT", lambda s: "Signing: off" in s.text, 10) is not None
    m.disable_signing()
    c = _client(veh, None)
    ack = command(c, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    c.close()
    end = time.monotonic() + 10
    while time.monotonic() < end and sg.read_key_file(vehicle["key_file"]) is not None:
        time.sleep(0.1)
    assert sg.read_key_file(vehicle["key_file"]) is None


def test_the_summary_counts_the_refused_frames(vehicle):
    _, comp_log = vehicle["veh"].stop()
    assert "unsigned or badly signed)" in comp_log


@pytest.mark.skipif(not netns_available(),
                    reason="needs root (unshare) for a private network namespace")
def test_up_with_a_passphrase_signs_the_vehicle_and_the_winch(tmp_path):
    """``tuav-sitl up --signing-passphrase``: the winch's frames reach a ground station
    signed, it answers a signed DO_WINCH and ignores an unsigned LOCK; a new key set by
    SETUP_SIGNING reaches it over the component link and the run's key file."""
    s = run_session("tests.netns.signing_session", str(tmp_path), timeout_s=300)
    assert s["rc"] == 0, s["stderr"]
    assert "MAVLink 2 signing on" in s["banner"]
    assert s["key_file"] == sg.key_from_passphrase("tethered-uav-signing").hex()
    assert s["vehicle_signed"]
    assert s["winch"] == {"status_signed": True, "heartbeat_signed": True,
                          "ack": M.MAV_RESULT_ACCEPTED}
    assert not s["unsigned_ack"] and s["still_armed"] and not s["winch_locked"]
    assert s["winch_new_key"] == {"status_signed": True, "heartbeat_signed": True,
                                  "ack": M.MAV_RESULT_ACCEPTED}
    assert s["key_file_after"] == sg.key_from_passphrase("the-next-key").hex()
    assert "signing key set by the vehicle" in s["groundstation_log"]


# ----- the rules on their own


def test_passphrase_key_is_mavproxys_sha256():
    # SHA-256's published test vector (FIPS 180-2): MAVProxy's key for "abc"
    assert sg.key_from_passphrase("abc").hex() == (
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad")
    with pytest.raises(sg.SigningError):
        sg.key_from_passphrase("clé")
    with pytest.raises(sg.SigningError):
        sg.key_from_passphrase("")


def test_key_file_holds_64_hex_digits(tmp_path):
    p = tmp_path / "k"
    assert sg.read_key_file(p) is None
    p.write_text(KEY.hex().upper() + "\n")
    assert sg.read_key_file(p) == KEY
    p.write_text(sg.key_file_text(None))
    assert sg.read_key_file(p) is None
    for bad in ("abc", "zz" * 32, KEY.hex() + "00"):
        p.write_text(bad)
        with pytest.raises(sg.SigningError):
            sg.read_key_file(p)


def _pair(key: bytes):
    sender = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    sender.signing.secret_key, sender.signing.sign_outgoing = key, True
    sender.signing.timestamp = sg.timestamp_now()
    receiver = sg.SigningMavlink(None, srcSystem=1, srcComponent=1)
    receiver.robust_parsing = True
    sg.set_key(receiver.signing, KEY)
    return sender, receiver


def _hb(mav) -> bytes:
    return mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav)


def test_forged_frame_with_a_far_timestamp_does_not_lock_the_sender_out():
    sender, receiver = _pair(KEY)
    assert receiver.parse_char(_hb(sender)).get_type() == "HEARTBEAT"
    forger = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    forger.signing.secret_key, forger.signing.sign_outgoing = WRONG_KEY, True
    forger.signing.timestamp = sender.signing.timestamp + 10**12
    assert receiver.parse_char(_hb(forger)).get_type() == "BAD_DATA"
    # pymavlink's own check would now refuse every true frame as older than the forgery
    assert receiver.parse_char(_hb(sender)).get_type() == "HEARTBEAT"


def test_replay_and_unsigned_refused_radio_status_let_through():
    sender, receiver = _pair(KEY)
    frame = _hb(sender)
    assert receiver.parse_char(frame).get_type() == "HEARTBEAT"
    assert receiver.parse_char(frame).get_type() == "BAD_DATA"      # the same timestamp
    plain = mavlink2.MAVLink(None, srcSystem=3, srcComponent=68)
    assert receiver.parse_char(_hb(plain)).get_type() == "BAD_DATA"
    radio = plain.radio_status_encode(200, 190, 90, 20, 10, 0, 0).pack(plain)
    assert receiver.parse_char(radio).get_type() == "RADIO_STATUS"
    old = mavlink2.MAVLink(None, srcSystem=9, srcComponent=1)
    old.signing.secret_key, old.signing.sign_outgoing = KEY, True
    old.signing.timestamp = sg.timestamp_now() - 2 * sg.NEW_STREAM_WINDOW
    assert receiver.parse_char(_hb(old)).get_type() == "BAD_DATA"   # a new stream, too old

"""The plant's sensor batch (HIL_GPS when due, HIL_STATE_QUATERNION, HIL_SENSOR) as MAVLink
bytes in one call: the batch's one law.

:func:`batch_kernel` reads the sensor channels (:func:`sitl.sensors.channel_read`, the
channels' :class:`sitl.sensors.NoiseState`, the law :meth:`sitl.sensors.NoisyChannel.read`
runs too), converts the readings and the truth to the link's fields (units, frames and
integer resolution of :mod:`tuavdefs.simlink`) and writes the frames. Compiled by numba; the
same code interpreted without it (``TUAV_NO_JIT=1``). ``tests/test_fast_paths.py`` checks
the compiled kernel against its own Python source, bit for bit, and its batches against
the link's field builders through pymavlink's parser.

A state the link cannot carry (not finite, beyond the ISA's air, a field beyond its type)
is refused with nothing changed (:data:`REFUSALS`): :meth:`BatchPacker.pack` raises. A
signing encoder gets the kernel's frames packed again by pymavlink, which signs them.
"""

from __future__ import annotations

import math
import re

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from sitl import sensors as _sensors
from sitl._jit import njit
from sitl.plant import Plant, quat_rotate_kernel, specific_force_kernel
from sitl.pymath import hypot2
from sitl.sensors import (
    _ISA_EXP,
    _P_ENABLED,
    ISA_LAPSE_K_M,
    ISA_P0_HPA,
    ISA_R_J_KG_K,
    ISA_RHO0_KG_M3,
    ISA_T0_K,
    NoiseState,
    SensorSuite,
    TruthBuffer,
    channel_commit,
    channel_read,
)
from tuavdefs import simlink as sl
from tuavdefs.frames import Q_FLU_FROM_FRD, Q_NED_FROM_ENU, quat_multiply
from tuavdefs.jit import BOOL, F64, I64, Signature, array, entry_point, record, vec

# (the link's constants as globals of this module, so that the compiled code's cache key
# holds their values: tuavdefs.jit.dependency_digest)
_FIX_3D = sl.GPS_FIX_3D
_MILLI_G_M_S2 = sl.MILLI_G_M_S2
_FIELDS_FILLED = sl.SENSOR_FIELDS_FILLED
#: The satellites HIL_GPS reports (the plant's: hil_gps_values' default).
_SATELLITES = sl.GPS_SATELLITES_VISIBLE
round_clamp = njit(sl.round_clamp)
wrap_lon = njit(sl.wrap_lon)
_quat_multiply = njit(quat_multiply)
_truth_push = njit(_sensors.truth_push)
_truth_at = njit(_sensors.truth_at)

#: The messages' rows in the kernel's arrays, in the batch's order.
_GPS, _STATE, _SENSOR = 0, 1, 2
_MESSAGES = (mavlink2.MAVLink_hil_gps_message, mavlink2.MAVLink_hil_state_quaternion_message,
             mavlink2.MAVLink_hil_sensor_message)
#: Kinds of a payload field (a layout code is kind * 16 + size in bytes).
_FLOAT, _UNSIGNED, _SIGNED = 0, 1, 2
_STRUCT_CODES = {"f": (_FLOAT, 4), "Q": (_UNSIGNED, 8), "I": (_UNSIGNED, 4),
                 "H": (_UNSIGNED, 2), "B": (_UNSIGNED, 1), "i": (_SIGNED, 4),
                 "h": (_SIGNED, 2), "b": (_SIGNED, 1)}
_MAX_FIELDS = 20
#: The channels' slots in :class:`sitl.sensors.NoiseState` (:attr:`SensorSuite.channels`).
_ACCEL, _GYRO, _MAG, _BARO, _GPS_H, _GPS_V, _GPS_VEL = range(7)
#: The constants the kernel is handed (indices into its ``consts``).
(_K_LAT0, _K_LON0, _K_ALT0, _K_RN, _K_RECOS, _K_FIELD_E, _K_FIELD_N, _K_FIELD_U, _K_G,
 _K_TWO, _K_EPH, _K_EPV, _K_LATENCY_US, _N_CONSTS) = range(14)
#: Magnitude below which a float rounds to an int64 safely.
_ROUND_MAX = 2.0 ** 62
#: A batch's bytes at most (three frames of at most 10 + 255 + 2).
_OUT_BYTES = 3 * 267
#: What :func:`batch_kernel` returns instead of a length when the state is beyond what
#: the link carries (nothing changed then), and what each means.
NOT_FINITE, NO_AIR, NO_ATTITUDE, NEGATIVE_PRESSURE, OUT_OF_RANGE = -1, -2, -3, -4, -5
REFUSALS = {
    NOT_FINITE: "the state is not finite",
    NO_AIR: "the air at that altitude is beyond the ISA's (no positive temperature)",
    NO_ATTITUDE: "the attitude quaternion has no direction",
    NEGATIVE_PRESSURE: "the barometer would read a negative pressure",
    OUT_OF_RANGE: "a field's value is beyond what its type carries (a float32, the "
                  "integers' range)",
}


def _layout(cls: type) -> list[int]:
    """[number of fields, layout code per field] of a message's ``struct`` format."""
    codes = []
    for count, char in re.findall(r"(\d*)([a-zA-Z])", cls.unpacker.format):
        kind, size = _STRUCT_CODES[char]
        codes += [kind * 16 + size] * int(count or 1)
    return [len(codes), *codes]


@njit
def _global(consts: np.ndarray, e: float, n: float, u: float, iv: np.ndarray,
            at: int) -> bool:
    """:meth:`tuavdefs.simlink.HomeMap.global_fields` of (east, north, up) [m] into
    ``iv[at:at + 3]``; False if a value is not a finite number an int64 holds."""
    lat = consts[_K_LAT0] + math.degrees(n / consts[_K_RN])
    lon = wrap_lon(consts[_K_LON0] + math.degrees(e / consts[_K_RECOS]))
    alt = consts[_K_ALT0] + u
    ok = True
    for j, v in enumerate((lat * 1e7, lon * 1e7, alt * 1000.0)):
        if not abs(v) < _ROUND_MAX:
            ok = False
        else:
            iv[at + j] = round(v)
    return ok


@njit
def _fits(layout: np.ndarray, fv: np.ndarray, iv: np.ndarray, f32: np.ndarray) -> bool:
    """Whether a message's values pack as the interpreter packs them, without error: finite
    floats that fit a float32, integers in their field's range."""
    for k in range(layout[0]):
        code = layout[1 + k]
        kind, size = code >> 4, code & 15
        if kind == _FLOAT:
            f32[0] = fv[k]
            if not (math.isfinite(fv[k]) and math.isfinite(f32[0])):
                return False
        elif kind == _UNSIGNED:
            if iv[k] < 0 or (size < 8 and iv[k] >= 1 << (8 * size)):
                return False
        elif not -(1 << (8 * size - 1)) <= iv[k] < 1 << (8 * size - 1):
            return False
    return True


@njit
def _crc(out: np.ndarray, start: int, end: int, extra: int) -> int:
    """MAVLink's CRC-16/MCRF4XX of ``out[start:end]`` and the CRC_EXTRA byte ``extra``."""
    crc = 0xFFFF
    for i in range(start, end + 1):
        b = int(out[i]) if i < end else extra
        tmp = (b ^ (crc & 0xFF)) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


@njit
def _frame(out: np.ndarray, pos: int, seq: int, sysid: int, compid: int, msg: np.ndarray,
           layout: np.ndarray, fv: np.ndarray, iv: np.ndarray, f32: np.ndarray,
           u32: np.ndarray) -> int:
    """One unsigned MAVLink 2 frame at ``out[pos:]`` (:meth:`tuavdefs.simlink._Codec.
    pack_values`: the payload's trailing zeros dropped, one kept); returns its end."""
    start = pos + 10
    p = start
    for k in range(layout[0]):
        code = layout[1 + k]
        if code >> 4 == _FLOAT:
            f32[0] = fv[k]
            v = np.int64(u32[0])
        else:
            v = iv[k]
        for b in range(code & 15):
            out[p] = (v >> (8 * b)) & 0xFF
            p += 1
    while p > start and out[p - 1] == 0:
        p -= 1
    if p == start:
        p += 1    # (out[start] is 0)
    msg_id = msg[0]
    header = (0xFD, p - start, 0, 0, seq, sysid, compid, msg_id & 0xFF, (msg_id >> 8) & 0xFF,
              msg_id >> 16)
    for j, h in enumerate(header):
        out[pos + j] = h
    crc = _crc(out, pos + 1, p, msg[1])
    out[p] = crc & 0xFF
    out[p + 1] = crc >> 8
    return p + 2


#: :func:`batch_kernel`'s scratch: the messages' layouts and (id, CRC extra), their float
#: and integer field values, the channels' bias and Gauss-Markov error after a read, the
#: delayed truth (6), one float32 and its bits.
SCRATCH_RECORD = record(array(2, I64), array(2, I64), array(2), array(2, I64), array(2),
                        array(2), array(), array(1, "float32"), array(1, "uint32"))
#: :func:`batch_kernel`'s request: the batch's time [us], whether HIL_GPS is due and its
#: channels' interval [s], the other channels' interval [s], the first frame's sequence
#: number, the system and component ids.
REQUEST_RECORD = record(I64, BOOL, F64, F64, I64, I64, I64)
#: :func:`batch_kernel`'s arguments.
BATCH_SIGNATURE = Signature(array(1, "uint8"), REQUEST_RECORD,
                            record(array(), array(), array()), vec(3), array(),
                            NoiseState.RECORD, TruthBuffer.RECORD, SCRATCH_RECORD)


@njit
def batch_kernel(out: np.ndarray, request: tuple, plant: tuple[np.ndarray, ...],
                 wind: tuple[float, float, float], consts: np.ndarray, noise: tuple,
                 truth_buffer: tuple, scratch: tuple) -> tuple[int, int]:
    """The batch of ``request`` (:data:`REQUEST_RECORD`) into ``out``: at ``t_us`` [us],
    HIL_GPS if ``gps_due`` (its channels read ``gps_dt`` [s] after the last fix), then
    HIL_STATE_QUATERNION and HIL_SENSOR (its channels read ``dt`` [s] after the last),
    the frames numbered from ``seq``, from ``sysid``, ``compid``;
    ``plant`` = (its state ``x``, packed parameters ``p``, tether array ``warm``),
    ``wind`` its air at the UAV (east, north, up) [m/s]; the noise channels' state
    (:class:`sitl.sensors.NoiseState`) advanced, the state's position and velocity
    recorded in the truth buffer (:class:`sitl.sensors.TruthBuffer`), from which HIL_GPS
    reads the truth of ``consts[_K_LATENCY_US]`` earlier. Returns (bytes written, a bit
    for each channel whose block it used up, to be refilled now:
    :meth:`sitl.sensors.NoisyChannel.refill`), or (a negative code of :data:`REFUSALS`, 0)
    for a state the link cannot carry, nothing changed. ``scratch``: :data:`SCRATCH_RECORD`,
    :class:`BatchPacker`'s."""
    t_us, gps_due, gps_dt, dt, seq, sysid, compid = request
    x, p, warm = plant
    wind_e, wind_n, wind_u = wind
    draws, bias, gm, cursor, params = noise
    truth_t, truth_pv, truth_ring = truth_buffer
    layouts, msgs, fv, iv, new_bias, new_gm, truth, f32, u32 = scratch
    reads = 0b0001111 | (0b1110000 if gps_due else 0)
    for j in range(19):
        if not math.isfinite(x[j]):
            return NOT_FINITE, 0
    px, py, pz, vx, vy, vz = x[0], x[1], x[2], x[3], x[4], x[5]
    qw, qx, qy, qz, wx, wy, wz = x[6], x[7], x[8], x[9], x[10], x[11], x[12]
    ok = True
    r = np.empty(3)
    # the truth buffer (its slot written now, the ring committed with the rest; the
    # interpreter writes the same slot if this is left to it)
    newest, count = _truth_push(float(t_us), px, py, pz, vx, vy, vz, truth_t, truth_pv,
                                truth_ring)
    if gps_due:   # HIL_GPS, of the truth latency_us earlier
        _truth_at(float(t_us), consts[_K_LATENCY_US], truth_t, truth_pv, newest, count,
                  truth)
        channel_read(_GPS_H, 2, truth[0], truth[1], 0.0, gps_dt, draws, bias, gm, cursor, params,
              new_bias, new_gm, r)
        ge, gn = r[0], r[1]
        channel_read(_GPS_V, 1, truth[2], 0.0, 0.0, gps_dt, draws, bias, gm, cursor, params,
              new_bias, new_gm, r)
        gu = r[0]
        channel_read(_GPS_VEL, 3, truth[3], truth[4], truth[5], gps_dt, draws, bias, gm, cursor,
              params, new_bias, new_gm, r)
        vn, ve, vd = r[1], r[0], -r[2]
        g_f, g_i = fv[_GPS], iv[_GPS]
        g_i[0] = t_us
        ok = _global(consts, ge, gn, gu, g_i, 1) and ok
        vel_cm = round_clamp(hypot2(vn, ve) * 100.0, 0, 65534)
        g_i[4] = round_clamp(consts[_K_EPH] * 100.0, 0, 65534)
        g_i[5] = round_clamp(consts[_K_EPV] * 100.0, 0, 65534)
        g_i[6] = vel_cm
        g_i[7] = round_clamp(vn * 100.0, -32767, 32767)
        g_i[8] = round_clamp(ve * 100.0, -32767, 32767)
        g_i[9] = round_clamp(vd * 100.0, -32767, 32767)
        if vel_cm == 0:
            g_i[10] = 65535
        else:
            cog = math.degrees(math.atan2(ve, vn)) * 100.0
            if not abs(cog) < _ROUND_MAX:
                ok = False
            else:
                g_i[10] = round(cog) % 36000
        g_i[11], g_i[12], g_i[13], g_i[14] = _FIX_3D, _SATELLITES, 0, 0
        ok = ok and _fits(layouts[_GPS], g_f, g_i, f32)
    # the truth and the air
    fx, fy, fz = specific_force_kernel(x, p, wind_e, wind_n, wind_u, warm, consts[_K_G])
    temperature_k = ISA_T0_K - ISA_LAPSE_K_M * (consts[_K_ALT0] + pz)
    if not temperature_k > 0.0:
        return NO_AIR, 0
    pressure_hpa = ISA_P0_HPA * (temperature_k / ISA_T0_K) ** _ISA_EXP
    density = pressure_hpa * 100.0 / (ISA_R_J_KG_K * temperature_k)
    # CPython's x ** 2 is the C library's pow (not always x * x): a run-time exponent
    two = consts[_K_TWO]
    tas = math.sqrt((vx - wind_e) ** two + (vy - wind_n) ** two + (vz - wind_u) ** two)
    ias = tas * math.sqrt(density / ISA_RHO0_KG_M3)
    # HIL_STATE_QUATERNION
    s_f, s_i = fv[_STATE], iv[_STATE]
    s_i[0] = t_us
    a0, a1, a2, a3 = _quat_multiply(_quat_multiply(Q_NED_FROM_ENU, (qw, qx, qy, qz)),
                                    Q_FLU_FROM_FRD)
    n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
    if n == 0.0 or not math.isfinite(n):
        return NO_ATTITUDE, 0
    sc = 1.0 / n if a0 >= 0.0 else -1.0 / n
    s_f[1], s_f[2], s_f[3], s_f[4] = a0 * sc, a1 * sc, a2 * sc, a3 * sc
    s_f[5], s_f[6], s_f[7] = wx, -wy, -wz
    ok = _global(consts, px, py, pz, s_i, 8) and ok
    s_i[11] = round_clamp(vy * 100.0, -32767, 32767)
    s_i[12] = round_clamp(vx * 100.0, -32767, 32767)
    s_i[13] = round_clamp(-vz * 100.0, -32767, 32767)
    s_i[14] = round_clamp(ias * 100.0, 0, 65535)
    s_i[15] = round_clamp(tas * 100.0, 0, 65535)
    s_i[16] = round_clamp(fx / _MILLI_G_M_S2, -32767, 32767)
    s_i[17] = round_clamp(-fy / _MILLI_G_M_S2, -32767, 32767)
    s_i[18] = round_clamp(-fz / _MILLI_G_M_S2, -32767, 32767)
    ok = ok and _fits(layouts[_STATE], s_f, s_i, f32)
    # HIL_SENSOR
    h_f, h_i = fv[_SENSOR], iv[_SENSOR]
    h_i[0] = t_us
    channel_read(_ACCEL, 3, fx, fy, fz, dt, draws, bias, gm, cursor, params, new_bias,
          new_gm, r)
    h_f[1], h_f[2], h_f[3] = r[0], -r[1], -r[2]
    channel_read(_GYRO, 3, wx, wy, wz, dt, draws, bias, gm, cursor, params, new_bias,
          new_gm, r)
    h_f[4], h_f[5], h_f[6] = r[0], -r[1], -r[2]
    me, mn, mu = quat_rotate_kernel((qw, -qx, -qy, -qz), (consts[_K_FIELD_E],
                                                             consts[_K_FIELD_N],
                                                             consts[_K_FIELD_U]))
    channel_read(_MAG, 3, me, mn, mu, dt, draws, bias, gm, cursor, params, new_bias,
          new_gm, r)
    h_f[7], h_f[8], h_f[9] = r[0], -r[1], -r[2]
    channel_read(_BARO, 1, pressure_hpa, 0.0, 0.0, dt, draws, bias, gm, cursor, params, new_bias,
          new_gm, r)
    baro = r[0]
    if baro < 0.0:   # (a negative number's real power is not a number)
        return NEGATIVE_PRESSURE, 0
    h_f[10], h_f[11] = baro, 0.0
    h_f[12] = ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (baro / ISA_P0_HPA) ** (1.0 / _ISA_EXP))
    h_f[13] = temperature_k - 273.15
    h_i[14], h_i[15] = _FIELDS_FILLED, 0
    if not (ok and _fits(layouts[_SENSOR], h_f, h_i, f32)) or t_us < 0:
        return OUT_OF_RANGE, 0
    # the usual case: commit the channels' reads, write the frames
    used_up = 0
    truth_ring[0], truth_ring[1] = newest, count
    for c in range(7):
        if ((reads >> c) & 1 != 0 and params[c, _P_ENABLED] != 0.0
                and channel_commit(c, bias, gm, cursor, new_bias, new_gm)):
            used_up |= 1 << c
    pos = 0
    for m in range(3):
        if m != _GPS or gps_due:
            pos = _frame(out, pos, seq, sysid, compid, msgs[m], layouts[m], fv[m], iv[m],
                         f32, u32)
            seq = (seq + 1) & 0xFF
    return pos, used_up


class BatchPacker:
    """The batches of :class:`sitl.simlink_server.SimLinkServer` through
    :func:`batch_kernel`: the plant's state, the sensor channels of ``sensors`` (their
    state advanced as reading them advances it), ``home`` (lat deg, lon deg, alt m AMSL)
    and the frames' ids and sequence of ``encoder`` (updated as it updates them)."""

    def __init__(self, plant: Plant, sensors: SensorSuite, home: tuple[float, float, float],
                 encoder: sl.Encoder, period_us: int) -> None:
        self.plant = plant
        self.sensors = sensors
        self.encoder = encoder
        self.dt_s = period_us * 1e-6
        hm = sl.home_map(home)
        field = sensors.earth_field_enu_gauss
        noise = sensors.noise
        consts = np.zeros(_N_CONSTS)
        consts[[_K_LAT0, _K_LON0, _K_ALT0, _K_RN, _K_RECOS]] = (
            hm.lat0_deg, hm.lon0_deg, hm.alt0_m, hm.r_n_m, hm.r_e_cos_m)
        consts[[_K_FIELD_E, _K_FIELD_N, _K_FIELD_U]] = field
        consts[_K_G] = plant.model.g
        consts[_K_TWO] = 2.0
        consts[_K_EPH] = noise.gps_eph_m
        consts[_K_EPV] = noise.gps_epv_m
        consts[_K_LATENCY_US] = float(sensors.gps_latency_us)
        self._consts = consts
        self._layouts = np.zeros((3, 1 + _MAX_FIELDS), dtype=np.int64)
        self._msgs = np.zeros((3, 2), dtype=np.int64)
        for m, cls in enumerate(_MESSAGES):
            layout = _layout(cls)
            self._layouts[m, :len(layout)] = layout
            self._msgs[m] = (cls.id, cls.crc_extra)
        self._fv = np.zeros((3, _MAX_FIELDS))
        self._iv = np.zeros((3, _MAX_FIELDS), dtype=np.int64)
        #: HIL_SENSOR's rows of those (views, for :meth:`sensor_values`)
        self._sensor_fv, self._sensor_iv = self._fv[_SENSOR, 1:14], self._iv[_SENSOR]
        self._gps_iv = self._iv[_GPS, :self._layouts[_GPS, 0]]
        self._new_bias = np.zeros((7, 3))
        self._new_gm = np.zeros((7, 3))
        self._f32 = np.zeros(1, dtype=np.float32)
        self._u32 = self._f32.view(np.uint32)
        self._out = np.zeros(_OUT_BYTES, dtype=np.uint8)
        self._view = memoryview(self._out)   # type: ignore[arg-type]
        self._noise = tuple(sensors.noise_state)
        self._truth_buffer = tuple(sensors.truth_buffer)
        self._scratch = (self._layouts, self._msgs, self._fv, self._iv, self._new_bias,
                         self._new_gm, np.zeros(6), self._f32, self._u32)
        # HIL_SENSOR's payload: time_usec, 13 floats, fields_updated, id (sensor_values);
        # HIL_GPS's: integers only (gps_values)
        if _layout(_MESSAGES[_SENSOR]) != [16, _UNSIGNED * 16 + 8,
                                           *[_FLOAT * 16 + 4] * 13, _UNSIGNED * 16 + 4,
                                           _UNSIGNED * 16 + 1]:
            raise RuntimeError("HIL_SENSOR's layout is not the one sensor_values reads")
        if any(code >> 4 == _FLOAT for code in _layout(_MESSAGES[_GPS])[1:]):
            raise RuntimeError("HIL_GPS's layout is not the one gps_values reads")
        self._kernel = entry_point(batch_kernel, BATCH_SIGNATURE)

    def pack(self, t_us: int, gps_dt_s: float | None) -> memoryview | bytes:
        """The batch for the plant's current state at ``t_us`` [us] (with HIL_GPS, its
        channels read ``gps_dt_s`` [s] after the last fix, unless None). Raises
        ValueError for a state the link cannot carry (:data:`REFUSALS`; nothing
        changed)."""
        mav = self.encoder.mav
        p = self.plant
        m = p.model
        gps = gps_dt_s is not None
        n, used_up = self._kernel(
            self._out, (t_us, gps, gps_dt_s if gps else 0.0, self.dt_s, mav.seq,
                        mav.srcSystem, mav.srcComponent), (p.x, m.p, m.warm),
            p.wind_m_s, self._consts, self._noise, self._truth_buffer, self._scratch)
        if n <= 0:
            raise ValueError(f"no simulator-link batch at t = {t_us} us: {REFUSALS[n]}")
        if used_up:
            for c, channel in enumerate(self.sensors.channels):
                if (used_up >> c) & 1:
                    channel.refill()
        if mav.signing.sign_outgoing:
            # pymavlink signs: the frames' values packed again through it
            items = sl.whole_frames(bytes(self._view[:n]), sl.LINK_CODECS, check_crc=False)
            assert items is not None, "the kernel writes whole, unsigned frames"
            return b"".join(self.encoder.pack_values(mid, values) for mid, values in items)
        sl.count_sent(mav, 3 if gps else 2, n)
        return self._view[:n]

    def sensor_values(self) -> tuple:
        """HIL_SENSOR's field values in wire order as the last :meth:`pack` wrote them
        (its floats as the float32 the frame carries): what unpacking that frame's payload
        gives, without the frame."""
        fv = self._sensor_fv.astype(np.float32).tolist()
        iv = self._sensor_iv.tolist()
        return (iv[0], *fv, iv[14], iv[15])

    def gps_values(self) -> tuple:
        """HIL_GPS's field values in wire order as the last :meth:`pack` that held one
        wrote them (all integers): what unpacking that frame's payload gives."""
        return tuple(self._gps_iv.tolist())

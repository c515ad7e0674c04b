"""The CAN bus's health as the winch judges it from the load cell's stamped frames: the
share lost and how late they come; a degraded bus brakes the drum (``groundstation.winch``).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.winch_params import WinchParams
from groundstation.winch_report import WinchOutput, notice


class BusHealth:
    """Judges the bus over windows of ``bus_window_s`` of the load cell's stamps."""

    def __init__(self, params: WinchParams) -> None:
        self.p = params
        #: Whether the CAN bus loses or delays too much: the drum braked.
        self.degraded = False
        self._window_start = 0
        self._expected = 0
        self._lost = 0
        self._late_ms = 0x10000          # the least lateness of the window [ms]
        self._good = 0
        self._min_step = 0xFFFF          # the shortest step between stamps [ms]
        self._said: tuple[float, float] | None = None
        self._noticed = False

    def on_stamp(self, last_ms: int | None, stamp_ms: int, uav_time_ms: int | None) -> bool:
        """Take the load cell's frame stamped ``stamp_ms`` (the one before ``last_ms``;
        ``uav_time_ms`` the UAV's latest position's time, which the component link brings);
        returns whether the bus has just become good again (the axis to be re-armed).

        The share lost (from the gaps between stamps) and how late they come (the UAV's
        latest position against the sample's stamp: the least of a window, so that a busy
        machine's lags do not count). Judged once a window of ``bus_window_s`` of stamps;
        a window with more than ``bus_lost_max`` lost or later than ``bus_late_max_s``
        makes the bus degraded (said in :meth:`notice`), ``bus_good_windows`` good ones
        in a row make it good again."""
        if last_ms is None:
            self._window_start = stamp_ms
            return False
        step = (stamp_ms - last_ms) & 0xFFFF
        if step == 0 or step >= 0x8000:
            return False                             # repeated or out of order
        # the frames' period: the nominal one, or the shortest step seen if longer (a plant
        # whose control period is longer than the sensors' sends them on its own grid)
        self._min_step = min(self._min_step, step)
        period_ms = max(1e3 / self.p.sensor_rate_hz, self._min_step)
        frames = max(1, round(step / period_ms))
        self._expected += frames
        self._lost += frames - 1
        if uav_time_ms is not None:
            late = (uav_time_ms - stamp_ms) & 0xFFFF
            if late < 0x8000:
                self._late_ms = min(self._late_ms, late)
            else:
                self._late_ms = min(self._late_ms, 0)
        if ((stamp_ms - self._window_start) & 0xFFFF) < self.p.bus_window_s * 1e3:
            return False
        lost = self._lost / self._expected
        late_s = self._late_ms * 1e-3 if self._late_ms < 0x10000 else 0.0
        bad = lost > self.p.bus_lost_max or late_s > self.p.bus_late_max_s
        self._window_start = stamp_ms
        self._expected = self._lost = 0
        self._late_ms = 0x10000
        if bad:
            self._good = 0
            if not self.degraded:
                self.degraded = True
                self._said = (lost, late_s)
        elif self.degraded:
            self._good += 1
            if self._good >= self.p.bus_good_windows:
                self.degraded = False
                self._said = None
                return True
        return False

    def notice(self, out: WinchOutput) -> None:
        """Say a change of the bus's health (once each)."""
        if self.degraded and self._said is not None and not self._noticed:
            lost, late_s = self._said
            self._noticed = True
            out.notices.append(notice(
                mavlink2.MAV_SEVERITY_CRITICAL,
                f"winch: CAN bad ({lost:.0%} lost, {late_s * 1e3:.0f} ms), braked"))
        elif not self.degraded and self._noticed:
            self._noticed = False
            out.notices.append(notice(mavlink2.MAV_SEVERITY_NOTICE,
                                      "winch: CAN bus good again"))

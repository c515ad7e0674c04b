"""The vehicle's link failsafes: a lost ground station (ArduCopter's ``FS_GCS_ENABLE``,
``FS_GCS_TIMEOUT``) and a lost or failed winder.

Part of the one onboard step (:class:`companion.onboard.Companion` checks them every control
period), so the offline runner and the processes fly the same failsafes. Each acts once per
loss, says so as a :class:`companion.navigation.NavEvent` FAILSAFE (a CRITICAL STATUSTEXT in
the process), and leaves the mode to the pilot once the link is back (as ArduCopter does):

- **ground station**: armed and flying, a ground station heard at least once (its
  HEARTBEAT, MAV_TYPE_GCS) and then silent for ``gcs_timeout_s``: RTL, or LAND
  (:class:`GcsAction`, ArduCopter's values); disabled by default, as in ArduCopter (scripts
  that send no heartbeat would otherwise be flown home);
- **winder**: flying, a winch heard at least once (a vehicle flown without one, as
  ``python -m companion`` alone, has nothing to lose), then no WINCH_STATUS for
  ``winch_timeout_s``, or reports without the HEALTHY flag for as long: the drum is taken
  as braked at the last reported length (the navigator bounds every target by it), then
  RTL within that reach, or LAND
  (:class:`WinchAction`); on by default. Before that, a winch silent for
  ``winch_brake_after_s`` (its axis's watchdog has braked the drum by then: 0.1 s without
  a command) is taken as braked at its last length at once (the navigator's tether fence
  then stops a vehicle flying outward short of a taut line), until it reports again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from companion.navigation import FlightMode, Navigator
from tuavdefs.paramspec import Params, quantity


class GcsAction(IntEnum):
    """``FS_GCS_ENABLE``: what a lost ground station does (ArduCopter's values; the
    SmartRTL ones fall back as ArduCopter's do without a SmartRTL path)."""

    DISABLED = 0
    RTL = 1
    SMART_RTL_OR_RTL = 3
    SMART_RTL_OR_LAND = 4
    LAND = 5


class WinchAction(IntEnum):
    """What a lost or failed winder does."""

    DISABLED = 0
    RTL = 1
    LAND = 2


@dataclass(frozen=True)
class FailsafeParams(Params):
    """The link failsafes' settings (module docstring)."""

    gcs_action: int = quantity(int(GcsAction.DISABLED), "", "FS_GCS_ENABLE: 0 disabled, "
                               "1 RTL, 3 RTL, 4 LAND, 5 LAND")
    gcs_timeout_s: float = quantity(5.0, "s", "FS_GCS_TIMEOUT: silence of the ground "
                                    "station that triggers it", ge=2, le=120)
    winch_action: int = quantity(int(WinchAction.RTL), "", "a lost winder: 0 disabled, "
                                 "1 RTL within the tether's reach, 2 LAND")
    winch_timeout_s: float = quantity(2.0, "s", "no (healthy) WINCH_STATUS for this long "
                                      "triggers it", ge=0.5, le=60)
    winch_brake_after_s: float = quantity(0.3, "s", "no WINCH_STATUS for this long: the "
                                          "drum is taken as braked at its last length "
                                          "(the axis's watchdog brakes it after 0.1 s)",
                                          ge=0.1, le=60)

    def check(self) -> None:
        for name, kind in (("gcs_action", GcsAction), ("winch_action", WinchAction)):
            value = getattr(self, name)
            if value not in {int(a) for a in kind}:
                raise ValueError(f"{name}: must be one of "
                                 f"{', '.join(str(int(a)) for a in kind)}, got {value!r}")

    @property
    def gcs(self) -> GcsAction:
        """:attr:`gcs_action` as its enum."""
        return GcsAction(self.gcs_action)

    @property
    def winch(self) -> WinchAction:
        """:attr:`winch_action` as its enum."""
        return WinchAction(self.winch_action)


class Failsafes:
    """The link failsafes of ``nav`` (module docstring); times in seconds of the
    companion's clock."""

    def __init__(self, params: FailsafeParams, nav: Navigator) -> None:
        self.params = params
        self.nav = nav
        self._gcs_t: float | None = None       # last ground-station heartbeat
        self._winch_t: float | None = None     # last healthy winch report
        self._winch_seen_t: float | None = None   # the first report, healthy or not
        self._winch_any_t: float | None = None    # the last report, healthy or not
        #: Whether a silent winch is taken as braked now (until it reports again).
        self.winch_silent = False
        self._winch_length_m = math.nan
        #: Whether each failsafe is on now (it acts once each time it comes on).
        self.gcs_lost = False
        self.winch_lost = False

    def gcs_heard(self, t_s: float) -> None:
        """A ground station's HEARTBEAT at ``t_s``."""
        self._gcs_t = t_s
        self.gcs_lost = False

    def winch_heard(self, t_s: float, length_m: float, healthy: bool) -> None:
        """A WINCH_STATUS at ``t_s``: paid-out length [m], its HEALTHY flag."""
        if self._winch_seen_t is None:
            self._winch_seen_t = t_s
        self._winch_any_t = t_s
        self.winch_silent = False
        if math.isfinite(length_m):
            self._winch_length_m = float(length_m)
        if healthy:
            self._winch_t = t_s
            self.winch_lost = False

    def check(self, t_s: float) -> None:
        """Act on a loss that has lasted its timeout (once a control period)."""
        p, nav = self.params, self.nav
        if not (nav.armed and nav.flying):
            return
        # the timing first: the actions are enums built from the parameters
        if (not self.gcs_lost and self._gcs_t is not None
                and t_s - self._gcs_t >= p.gcs_timeout_s and p.gcs != GcsAction.DISABLED):
            self.gcs_lost = True
            land = p.gcs in (GcsAction.SMART_RTL_OR_LAND, GcsAction.LAND)
            self._act(FlightMode.LAND if land else FlightMode.RTL,
                      f"GCS Failsafe: {'landing' if land else 'RTL'}")
        if (not self.winch_silent and self._winch_any_t is not None
                and t_s - self._winch_any_t >= p.winch_brake_after_s
                and math.isfinite(self._winch_length_m)):
            self.winch_silent = True
            nav.winch_report(self._winch_length_m, None, True)
        since = self._winch_t if self._winch_t is not None else self._winch_seen_t
        if (not self.winch_lost and since is not None
                and t_s - since >= p.winch_timeout_s and p.winch != WinchAction.DISABLED):
            self.winch_lost = True
            if math.isfinite(self._winch_length_m):   # the drum holds what it paid out
                nav.winch_report(self._winch_length_m, None, True)
            land = p.winch == WinchAction.LAND
            self._act(FlightMode.LAND if land else FlightMode.RTL,
                      f"Winch Failsafe: {'landing' if land else 'RTL within the tether'}")

    def _act(self, mode: FlightMode, text: str) -> None:
        self.nav.failsafe(mode, text)


__all__ = ["FailsafeParams", "Failsafes", "GcsAction", "WinchAction"]

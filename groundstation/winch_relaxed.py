"""The winch's RELAXED mode (``WINCH_RELAXED``, the default): the drum follows L-bar
through :meth:`WinderHost.update <groundstation.winder_host.WinderHost.update>` (slack,
never taut), around it:

- the **ground pre-tension** while the UAV is on the ground by its report, or unknown
  (:class:`groundstation.winch_ground.GroundPretension`; a take-off ends it unless the law
  holds it through the climb);
- the **rejoin** of L-bar from a line longer by more than ``REJOIN_MARGIN_M`` (wound in on
  a trapezoid) and the **join** from one shorter by more than ``JOIN_MARGIN_M`` (L-bar's
  law less a gap that closes on a trapezoid);
- the **slack guard**: line paid out while nothing pulls it is counted; past
  ``slack_payout_max_m`` the drum holds and pays out only as it is pulled.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.winch_ground import GroundPretension
from groundstation.winch_modes import (
    JOIN_MARGIN_M,
    REJOIN_ACC_M_S2,
    REJOIN_MARGIN_M,
    ModeLogic,
    WinchMode,
)
from groundstation.winch_report import Notice, WinchOutput, notice
from groundstation.winder_control import WinderCommand

if TYPE_CHECKING:
    from groundstation.winch import UavState, Winch


#: How long [s] the line must pull without a break before the slack guard lets go: a
#: vehicle that takes the line pulls it on; the drum's own stop against a line lying
#: slack (110 N in one sample, a crash's runaway report followed under the tension law)
#: and a tumbling vehicle's jerks do not.
SLACK_PULL_S = 0.1


class Relaxed(ModeLogic):
    """RELAXED: follow L-bar (module docstring)."""

    mode = WinchMode.RELAXED

    def __init__(self) -> None:
        self.hold_m = math.nan              # the length held without a UAV position [m]
        self._rejoin_m = math.nan           # the reference while rejoining L-bar [m]
        self._rejoin_rate = 0.0             # its wind-in speed [m/s]
        self._join_gap_m = 0.0              # how far short of L-bar's law a join still is
        self._join_rate = 0.0               # how fast that closes [m/s]
        #: The ground pre-tension (its loop also the slack guard's).
        self.pretension = GroundPretension()
        #: Line paid out (net) since the line was last pulled [m].
        self.slack_paid_m = 0.0
        self._slack_length_m = math.nan     # the length at the last slack count [m]
        self._pulled_s = 0.0                # how long the line has pulled without a break [s]
        #: Whether the drum holds the line against a pay-out nothing pulls (the slack
        #: guard, :meth:`_check_slack`): the pre-tension's loop, paid out only as pulled.
        self.slack_hold = False

    @property
    def join_gap_m(self) -> float:
        """How far short of L-bar's law the reference still is while it joins L-bar from a
        shorter line [m] (0: not joining)."""
        return self._join_gap_m

    def reset_slack(self) -> None:
        """The operator's act: the slack guard off, its count afresh."""
        self.slack_hold = False
        self.slack_paid_m = 0.0
        self._slack_length_m = math.nan

    def start(self, w: Winch, length_m: float, speed_m_s: float) -> list[Notice]:
        # a line longer than L-bar (after a pay-out) is wound back in at a bounded rate
        self.resume_from(w, w.length_m)
        return []

    def resume_from(self, w: Winch, length_m: float) -> None:
        """RELAXED rejoins L-bar from ``length_m`` [m] (wound in on a trapezoid, or joined
        with a gap)."""
        self.hold_m = length_m
        self.pretension.reset()
        uav = w.uav_now()
        lbar_m = w.host.lbar.length(uav[0])[0] if uav is not None else math.nan
        self._start_rejoin(length_m, lbar_m)

    def after_pay_out(self, w: Winch) -> None:
        # winds back to L-bar as after any pay-out
        self._rejoin_m, self._rejoin_rate = w.ref_m, 0.0
        self._join_gap_m = self._join_rate = 0.0
        self.hold_m = w.ref_m

    def control(self, w: Winch, out: WinchOutput) -> WinderCommand:
        uav = w.uav_now()
        if uav is not None and math.isfinite(self._rejoin_m):
            # rejoining L-bar from a longer line: wound in at rejoin_rate_m_s at most on
            # a trapezoid: speeding up and slowing down at REJOIN_ACC_M_S2
            lbar_m = max(w.host.lbar.length(uav[0])[0], w.floor_need_m())
            dt = w.dt_s
            left = self._rejoin_m - lbar_m
            rate = self._trapezoid_speed(w, self._rejoin_rate, max(left, 0.0))
            if left <= max(rate * dt, 1e-3):
                self._rejoin_m = math.nan      # there: L-bar's own law from now on
            else:
                self._rejoin_rate = rate
                self._rejoin_m -= rate * dt
                w.ref_m, w.ref_rate_m_s = self._rejoin_m, -rate
        if self._check_slack(w, out, uav) or self._on_ground(w, uav):
            self.pretension.reference(w, self.slack_hold)
            return w.track(w.ref_m, w.ref_rate_m_s)
        if uav is not None and math.isfinite(self._rejoin_m):
            return w.track(w.ref_m, w.ref_rate_m_s)
        if uav is None:
            w.ref_m, w.ref_rate_m_s = self.hold_m, 0.0
            return w.track(self.hold_m, 0.0)
        pos, vel = uav
        gap, closing = self._join_step(w)
        host = w.host
        # (the winder's own fix is the length law's slack floor: the tension law has none)
        fix_m = w.measured_position_m() if host.takes_fix else None
        step = host.update(w.length_m, w.omega_rad_s, w.law_tension_n(), pos, vel,
                           w.exit_elevation_rad(), fix_m, -gap, closing)
        w.ref_m, w.ref_rate_m_s = step.lbar_m, step.lbar_rate_m_s
        if gap > 0.0:       # what the step left of it (less, where L-bar fell into it)
            self._join_gap_m = w.host.lbar.join_gap_m
        return step.command

    def _start_rejoin(self, start_m: float, lbar_m: float) -> None:
        """The reference begins at the length ``start_m`` [m]: a line longer than L-bar
        (``lbar_m`` [m], NaN: unknown) by more than :data:`REJOIN_MARGIN_M` is wound in to
        it on a trapezoid; one shorter by more than :data:`JOIN_MARGIN_M` follows L-bar's
        law less a gap that closes on a trapezoid (:meth:`_join_step`); else L-bar's law
        takes it from there."""
        self._rejoin_m, self._rejoin_rate = math.nan, 0.0
        self._join_gap_m = self._join_rate = 0.0
        if not (math.isfinite(start_m) and math.isfinite(lbar_m)):
            return
        if start_m > lbar_m + REJOIN_MARGIN_M:
            self._rejoin_m = start_m
        elif start_m < lbar_m - JOIN_MARGIN_M:
            self._join_gap_m = lbar_m - start_m

    @staticmethod
    def _trapezoid_speed(w: Winch, speed_m_s: float, left_m: float) -> float:
        """This period's speed [m/s] of a rejoin or a join moving at ``speed_m_s`` with
        ``left_m`` [m] to go: at most ``rejoin_rate_m_s``, speeding up at
        :data:`REJOIN_ACC_M_S2`, and no faster than stops in what is left at it."""
        return min(w.p.rejoin_rate_m_s, speed_m_s + REJOIN_ACC_M_S2 * w.dt_s,
                   math.sqrt(2.0 * REJOIN_ACC_M_S2 * left_m))

    def _join_step(self, w: Winch) -> tuple[float, float]:
        """This period's (gap [m], its closing speed [m/s]) of a join from a line shorter
        than L-bar: the gap closes at ``rejoin_rate_m_s`` at most, speeding up and slowing
        down at :data:`REJOIN_ACC_M_S2`, while L-bar's law moves the reference with the
        UAV (a climb away is paid out for at once); (0, 0) once closed. The gap defers a
        pay-out and never winds the line in: where the law's reference falls below the
        measured length plus the gap, it takes the gap with it (:func:`winder_step
        <groundstation.winder_host.winder_step>`)."""
        gap = self._join_gap_m
        if gap <= 0.0:
            return 0.0, 0.0
        dt = w.dt_s
        rate = self._trapezoid_speed(w, self._join_rate, gap)
        if gap <= max(rate * dt, 1e-4):
            gap, rate = 0.0, 0.0        # closed (the last step's at most this speed)
        else:
            gap -= rate * dt
        self._join_gap_m, self._join_rate = gap, rate
        return gap, rate

    def _check_slack(self, w: Winch, out: WinchOutput, uav: UavState | None) -> bool:
        """The slack guard; returns whether it holds the line now.

        The line counts as slack while the load cell reads below ``slack_tension_n`` and
        the guide arm reads no line leaving the exit above the ground: nothing pulls it.
        The line paid out (net) while it stays slack is counted (:attr:`slack_paid_m`,
        back to 0 at any pull); beyond ``slack_payout_max_m`` it lies on the ground, where
        the vehicle is not taking it (a vehicle on the ground after a failure, flipped or
        landed, whose reported position runs away with a diverged estimate: the law
        followed it and paid out the whole tether). From then the drum holds the length
        and runs the ground pre-tension's loop, which pays out only as the line is pulled
        and winds in slowly to the pre-tension, its floor from the reported position
        stopping a wind-in but paying nothing out; said once. It ends when the line has
        pulled for :data:`SLACK_PULL_S` without a break and the report agrees with what is
        out (L-bar within ``REJOIN_MARGIN_M`` of the length: a report still asking much
        more, or much less, which would wind the line in onto a vehicle elsewhere, is not
        followed), or with an operator's ``DO_WINCH``."""
        p = w.p
        length = w.length_m
        fixer = w.sensors.fixer
        ground_el = fixer.p.ground_elevation_rad if fixer is not None else 0.0
        # (a reading of this window, not a stale one)
        leaves = w.sensors.line_leaves(ground_el, p.bus_window_s)
        slack = w.sensors.tension_n < p.slack_tension_n and not leaves
        self._pulled_s = 0.0 if slack else self._pulled_s + w.dt_s
        last, self._slack_length_m = self._slack_length_m, length
        if not slack:
            self.slack_paid_m = 0.0
        elif math.isfinite(last):
            self.slack_paid_m = max(0.0, self.slack_paid_m + length - last)
        if not self.slack_hold:
            if self.slack_paid_m > p.slack_payout_max_m:
                self.slack_hold = True
                w.ref_m, w.ref_rate_m_s = length, 0.0
                self._rejoin_m, self._rejoin_rate = math.nan, 0.0
                self._join_gap_m = self._join_rate = 0.0
                out.notices.append(notice(
                    mavlink2.MAV_SEVERITY_CRITICAL,
                    f"winch: {self.slack_paid_m:.1f} m paid out slack, pay-out held"))
            return self.slack_hold
        if (self._pulled_s >= SLACK_PULL_S and uav is not None
                and abs(w.host.lbar.length(uav[0])[0] - length) <= REJOIN_MARGIN_M):
            # the slack guard off: the law takes up from the measured length
            self.slack_hold = False
            self.slack_paid_m = 0.0
            if math.isfinite(w.length_m):
                self.resume_from(w, w.length_m)
            out.notices.append(notice(mavlink2.MAV_SEVERITY_NOTICE,
                                      "winch: line pulled, following L-bar again"))
        return self.slack_hold

    def _on_ground(self, w: Winch, uav: UavState | None) -> bool:
        """Whether the ground pre-tension holds now (:class:`GroundPretension`). Taking
        hold ends a join; leaving it, a line longer than L-bar rejoins it at
        ``rejoin_rate_m_s``."""
        was = self.pretension.holding
        ground = self.pretension.update(w, uav)
        if ground and not was:
            self._join_gap_m = self._join_rate = 0.0
        elif was and not ground:
            lbar_m = w.host.lbar.length(uav[0])[0] if uav is not None else math.nan
            self._start_rejoin(w.length_m, lbar_m)
            self.hold_m = w.length_m
        return ground

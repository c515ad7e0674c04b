"""The winch's ground pre-tension (RELAXED's, :mod:`groundstation.winch_relaxed`): while
the UAV's position is unknown, or it reports a height below ``ground_height_m`` and no
climb of ``ground_climb_m_s``, the drum holds the line at ``ground_tension_n``: a loop on
the load cell's tension, winding in slowly, paying out fast (holding instead while no
position is known), never below the taut floor; without a load-cell reading it holds its
length. Taken over from the tension law, its target starts at the tension the law held and
falls to ``ground_tension_n`` on the law's set-point filter, and it reads the load cell
through the law's low-pass (a bumpless transfer).

A take-off (the UAV climbing, or above ``ground_height_m``) ends it, unless it is held
through the climb while L-bar would ask for more than ``ground_lbar_tension_ratio`` times
its tension: by the law that follows the UAV (:attr:`WinderLaw.holds_ground_tension_in_climb
<groundstation.winder_control.WinderLaw.holds_ground_tension_in_climb>`: L-bar's length
law), or by any law within ``ground_hold_near_m`` of the winder (a short line, little to
drag over the ground; without GNSS the tether fix counts on it lying straight as it
lifts).
The slack guard runs the same loop (:meth:`GroundPretension.reference`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from groundstation.tension_law import Z_TENSION
from groundstation.winder_control import WinderLaw

if TYPE_CHECKING:
    from groundstation.winch import UavState, Winch


class GroundPretension:
    """The ground pre-tension: whether it holds (:meth:`update`) and its loop's length
    reference (:meth:`reference`)."""

    def __init__(self) -> None:
        #: Whether the pre-tension holds the line now.
        self.holding = False
        self._low = False                   # ... since the UAV reported itself on the ground
        self._target_n = math.nan           # the loop's target now [N]
        self._tension_n = math.nan          # and the tension it reads (NaN: the cell's) [N]

    def reset(self) -> None:
        """Not holding (RELAXED taken up afresh)."""
        self.holding = False

    def update(self, w: Winch, uav: UavState | None) -> bool:
        """Whether the pre-tension holds in this period (module docstring): the UAV on the
        ground by its report (or none yet), a load cell to hold it with. Taking hold, the
        reference starts at the measured length, its loop's target and reading as the law
        leaves them."""
        p = w.p
        tension = w.sensors.tension_n
        ground = p.ground_tension_n > 0.0 and math.isfinite(tension)
        if ground and uav is not None:
            pos = uav[0]
            low = pos[2] < p.ground_height_m and uav[1][2] < p.ground_climb_m_s
            if low:
                self._low = True
            # a take-off held through the climb while L-bar would ask for a nearly
            # straight line (the UAV low and far: L-bar's horizontal tension a w far above
            # its target, which only an exact position keeps off taut): by L-bar's length
            # law, and by any law near the winder
            # (in the air, neither holding nor low, none of it asked)
            flat = (self.holding and self._low
                    and (w.host.controller.law.holds_ground_tension_in_climb
                         or math.hypot(pos[0], pos[1]) <= p.ground_hold_near_m)
                    and w.host.lbar.length(pos)[1]
                    > p.ground_lbar_tension_ratio * w.host.lbar.a_target)
            ground = low or flat
        if ground and not self.holding:
            w.ref_m, w.ref_rate_m_s = w.length_m, 0.0
            # taken over from the tension law (a landing), the loop's target starts at
            # the tension the law held and falls to the pre-tension on the law's
            # set-point filter, and the loop reads the tension through the law's
            # low-pass: a bumpless transfer (from 2.3 N, the step to 0.3 N paid out at
            # 2 m/s at once, and the line, slack, snapped at 26 N as the drum wound it
            # back; on the load cell's noise alone, 1.5 m/s)
            ctl = w.host.controller
            tension_law = ctl.law is WinderLaw.TENSION
            held = ctl.tension_state[Z_TENSION] if tension_law else math.nan
            self._target_n = (max(held, p.ground_tension_n) if tension_law
                              else p.ground_tension_n)
            self._tension_n = held
        self.holding = ground
        if not ground:
            self._low = False
            self._target_n = self._tension_n = math.nan
        return ground

    def reference(self, w: Winch, slack_hold: bool) -> None:
        """One period of the pre-tension's length reference: paid out or wound in at a
        speed proportional to the tension's error (wound in at most at
        ``ground_tension_rate_m_s``, paid out at most at the law's speed limit, held
        instead while no UAV position is known), never below the taut floor while one is,
        nor past the drum's ends; ``slack_hold``: the slack guard holds the line (the
        reported position not to be trusted: its floor stops a wind-in, it pays nothing
        out)."""
        p, dt = w.p, w.dt_s
        target = self._target_n
        if not math.isfinite(target):
            target = p.ground_tension_n
        elif target > p.ground_tension_n:
            target += (1.0 - math.exp(-dt / max(
                w.host.controller.g.tension_setpoint_filter_s, dt))) * (
                p.ground_tension_n - target)
        self._target_n = target
        tension = w.sensors.tension_n
        if math.isfinite(self._tension_n):
            g = w.host.controller.g
            self._tension_n += (1.0 - math.exp(-dt / max(g.tension_filter_s, dt))) * (
                tension - self._tension_n)
            tension = self._tension_n
        rate = p.ground_tension_gain_m_s_n * (tension - target)
        # a pull above the pre-tension with no position known yet is held, as the drum
        # held its length before (a vehicle in the air the filter has not found)
        high = w.max_rate_m_s if w.uav is not None else 0.0
        rate = max(-p.ground_tension_rate_m_s, min(high, rate))
        ref = w.ref_m + rate * dt
        floor, _ = w.taut_floor()
        lower = max(floor, w.length_min_m) if math.isfinite(floor) else w.length_min_m
        if ref < lower:
            if not slack_hold:
                ref, rate = lower, 0.0
            elif rate < 0.0:
                ref, rate = max(ref, min(w.ref_m, lower)), 0.0
        if ref > w.length_max_m:
            ref, rate = w.length_max_m, 0.0
        w.ref_m, w.ref_rate_m_s = ref, rate

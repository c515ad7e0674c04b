"""Mission legs: the items a leg flies to (:class:`GotoItem`, :class:`CircleItem`) and
:class:`LegFollower`, which flies one item as :mod:`companion.reference` trajectories and
says when it is reached. The navigator (:mod:`companion.navigation`) is the one sequencer:
it plans one leg per mission item, guided target or landing step. Inertial frame (z up,
x east, y north, origin at the winder), positions in m, speeds in m/s, times in s, angles
in rad.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from enum import Enum

from companion.reference import (
    DEFAULT_MAX_YAW_ACC_RAD_S2,
    DEFAULT_MAX_YAW_RATE_RAD_S,
    DEFAULT_MIN_DURATION_S,
    ZERO3,
    Circle,
    RefSample,
    Trajectory,
    Transition,
    Vec3,
    nearest_angle,
    positive,
    vec3,
)
from tuavdefs.frames import wrap_pi


@dataclass(frozen=True)
class GotoItem:
    """Fly to ``pos_m`` [m]; ``yaw_rad`` [rad] there, or keep the current yaw if None."""

    pos_m: Vec3
    yaw_rad: float | None = None


@dataclass(frozen=True)
class CircleItem:
    """Circle ``turns`` times (NAV_LOITER_TURNS) about ``centre_xy_m`` [m] at radius
    ``radius_m`` [m], altitude ``altitude_m`` [m], tangential speed ``speed_m_s`` [m/s]
    (clamped to the follower's max speed), starting at ``start_angle_rad`` (None: the point
    nearest the vehicle). ``turns`` may be ``math.inf`` (loiter until retargeted)."""

    centre_xy_m: tuple[float, float]
    radius_m: float
    altitude_m: float
    speed_m_s: float
    turns: float = 1.0
    clockwise: bool = False
    start_angle_rad: float | None = None
    lead_in_s: float = 5.0
    yaw_rad: float | None = None
    face_travel: bool = False


MissionItem = GotoItem | CircleItem


def as_mission_item(item: MissionItem | Iterable[float]) -> MissionItem:
    """A GotoItem or CircleItem from an item or an (x, y, z) / (x, y, z, yaw) tuple."""
    if isinstance(item, GotoItem | CircleItem):
        return item
    vals = tuple(float(x) for x in item)
    if len(vals) == 3:
        return GotoItem(vec3(vals, "waypoint"))
    if len(vals) == 4:
        return GotoItem(vec3(vals[:3], "waypoint"), vals[3])
    raise ValueError(f"a waypoint is (x, y, z) or (x, y, z, yaw), got {item!r}")


class LegPhase(Enum):
    """Where a leg is."""

    TRANSIT = "transit"      # flying to the item (or to a circle's start)
    CIRCLE = "circle"        # flying a circle item's circle
    HOLD = "hold"            # reached, holding for hold_s
    DONE = "done"            # reached and held: the next leg may begin


class LegFollower:
    """One leg: flies to one item and says when it is reached.

    Flies a :class:`Transition` (within ``max_speed_m_s`` [m/s], ``max_acc_m_s2``
    [m/s^2]) to the item. A goto item is reached when its transition has finished and the
    vehicle is within ``acceptance_radius_m`` [m] of it; a circle item is flown as a
    transition to the circle's start point (entered when reached the same way), then the
    :class:`Circle`, and is reached when the circle has stopped and the vehicle is within
    the radius of its end point. After ``hold_s`` [s] at the reached item the leg is done.
    Until then, and after, the reference holds (at rest) at the item, whatever the vehicle
    does. :attr:`reached_t_s` is when it was reached (None before).
    """

    def __init__(self, max_speed_m_s: float, max_acc_m_s2: float, acceptance_radius_m: float,
                 hold_s: float = 0.0, *, max_yaw_rate: float = DEFAULT_MAX_YAW_RATE_RAD_S,
                 max_yaw_acc_rad_s2: float = DEFAULT_MAX_YAW_ACC_RAD_S2,
                 min_duration_s: float = DEFAULT_MIN_DURATION_S) -> None:
        self.max_speed_m_s = positive(max_speed_m_s, "max_speed_m_s")
        self.max_acc_m_s2 = positive(max_acc_m_s2, "max_acc_m_s2")
        self.acceptance_radius_m = positive(acceptance_radius_m, "acceptance_radius_m")
        if not (hold_s >= 0.0 and math.isfinite(hold_s)):
            raise ValueError(f"hold_s must be >= 0 and finite, got {hold_s!r}")
        self.hold_s = float(hold_s)
        self._transition_kw = dict(max_yaw_rate=max_yaw_rate,
                                   max_yaw_acc_rad_s2=max_yaw_acc_rad_s2,
                                   min_duration_s=min_duration_s)
        self.item: MissionItem | None = None
        self.reached_t_s: float | None = None
        """When the item was reached [s] (None before)."""
        self._phase = LegPhase.DONE
        self._traj: Trajectory | None = None
        self._target: Vec3 | None = None
        self._hold_until = 0.0
        self._circle_kw: dict | None = None

    # -- state --

    @property
    def done(self) -> bool:
        """True once the item has been reached and its hold is over."""
        return self._phase is LegPhase.DONE

    @property
    def phase(self) -> LegPhase:
        """Where the leg is."""
        return self._phase

    @property
    def trajectory(self) -> Trajectory:
        """The trajectory being flown."""
        if self._traj is None:
            raise RuntimeError("LegFollower.start() has not been called")
        return self._traj

    @property
    def target_m(self) -> Vec3 | None:
        """Point [m] the acceptance test uses (None while on an endless circle)."""
        return self._target

    # -- control --

    def start(self, t: float, current_pos: Iterable[float], current_vel: Iterable[float],
              item: MissionItem | Iterable[float], *, current_yaw: float = 0.0,
              current_acc: Iterable[float] = ZERO3, current_yaw_rate: float = 0.0,
              current_yaw_acc: float = 0.0) -> None:
        """Start the leg at time ``t`` [s] from the reference state (position [m],
        velocity [m/s], acceleration [m/s^2], yaw [rad] and its rate and acceleration), so
        the reference stays C2. Raises ValueError on an impossible circle item."""
        it = as_mission_item(item)
        if isinstance(it, CircleItem):
            self._check_circle(it)
        state = RefSample(vec3(current_pos, "current_pos"), vec3(current_vel, "current_vel"),
                          vec3(current_acc, "current_acc"), ZERO3, wrap_pi(current_yaw),
                          float(current_yaw_rate))
        self.item = it
        self.reached_t_s = None
        self._begin(float(t), state, float(current_yaw_acc))

    def update(self, t: float, current_pos: Iterable[float]) -> RefSample:
        """Advance the leg with the vehicle at ``current_pos`` [m] at time ``t`` [s]
        (non-decreasing) and return the reference at ``t``."""
        traj = self.trajectory
        phase = self._phase
        if (t < traj.end_s and (phase is LegPhase.TRANSIT or phase is LegPhase.CIRCLE)
                or phase is LegPhase.HOLD and t < self._hold_until
                or phase is LegPhase.DONE):
            return traj.sample(t)   # nothing to decide (most calls)
        pos = tuple(current_pos)
        for _ in range(4):  # each pass changes phase or stops
            if self._phase in (LegPhase.TRANSIT, LegPhase.CIRCLE):
                if not (t >= self.trajectory.end_s and self._target is not None
                        and math.dist(pos, self._target) <= self.acceptance_radius_m):
                    break
                if self._phase is LegPhase.TRANSIT and self._circle_kw is not None:
                    circle = Circle(t0=t, **self._circle_kw)
                    self._circle_kw = None
                    self._traj, self._phase = circle, LegPhase.CIRCLE
                    self._target = circle.final_pos_m
                    continue
                self.reached_t_s = t
                self._phase, self._hold_until = LegPhase.HOLD, t + self.hold_s
            elif self._phase is LegPhase.HOLD:
                if t >= self._hold_until:
                    self._phase = LegPhase.DONE
                break
            else:
                break
        return self.trajectory.sample(t)

    def retarget(self, t: float, new_goal: MissionItem | Iterable[float]) -> RefSample:
        """Fly to ``new_goal`` instead, from the current reference state at ``t`` [s]
        (position, velocity, acceleration, yaw and its rates), so the reference stays C2.
        Returns the reference at ``t``."""
        traj = self.trajectory
        item = as_mission_item(new_goal)
        if isinstance(item, CircleItem):
            self._check_circle(item)
        self.item = item
        self.reached_t_s = None
        self._begin(float(t), traj.sample(t), traj.yaw_acc_rad_s2(t))
        return self.trajectory.sample(t)

    def remaining_item(self, t: float) -> MissionItem:
        """What is left of the item at ``t`` [s], to resume it after a pause: a circle
        being flown keeps the turns it has not flown yet (started again from the point
        nearest the vehicle, as its lead-in is flown again), or is a goto to its end point
        once less than the acceptance radius of arc is left; anything else is the whole
        item (a goto leg flies to its point from wherever it resumes)."""
        item, traj = self.item, self._traj
        if item is None:
            raise RuntimeError("LegFollower.start() has not been called")
        if not (self._phase is LegPhase.CIRCLE and isinstance(item, CircleItem)
                and isinstance(traj, Circle)):
            return item
        if math.isinf(item.turns):
            return replace(item, start_angle_rad=None)
        left_m = item.turns * 2.0 * math.pi * item.radius_m - traj.arc_m(t)
        if left_m < self.acceptance_radius_m:
            assert traj.final_pos_m is not None     # (a finite circle has an end)
            return GotoItem(traj.final_pos_m, traj.final_yaw_rad)
        return replace(item, turns=left_m / (2.0 * math.pi * item.radius_m),
                       start_angle_rad=None)

    # -- internals --

    def _circle_args(self, item: CircleItem, pos: Iterable[float], yaw: float) -> dict:
        theta0 = (nearest_angle(item.centre_xy_m, pos) if item.start_angle_rad is None
                  else float(item.start_angle_rad))
        sgn = -1.0 if item.clockwise else 1.0
        if item.face_travel:
            yaw = wrap_pi(theta0 + sgn * 0.5 * math.pi)
        elif item.yaw_rad is not None:
            yaw = item.yaw_rad
        return dict(centre_xy=item.centre_xy_m, radius_m=item.radius_m,
                    altitude_m=item.altitude_m,
                    speed_m_s=min(item.speed_m_s, self.max_speed_m_s),
                    lead_in_s=item.lead_in_s, turns=item.turns, start_angle_rad=theta0,
                    clockwise=item.clockwise, max_acc_m_s2=self.max_acc_m_s2, yaw=yaw,
                    face_travel=item.face_travel)

    def _check_circle(self, item: CircleItem) -> None:
        Circle(t0=0.0, **self._circle_args(item, (item.centre_xy_m[0] + 1.0,
                                                  item.centre_xy_m[1]), 0.0))

    def _begin(self, t: float, state: RefSample, yaw_acc: float) -> None:
        item = self.item
        if isinstance(item, CircleItem):
            self._circle_kw = self._circle_args(item, state.pos_m, state.yaw_rad)
            kw = self._circle_kw
            cx, cy = kw["centre_xy"]
            th = kw["start_angle_rad"]
            goal: Vec3 = (cx + kw["radius_m"] * math.cos(th), cy + kw["radius_m"] * math.sin(th),
                          kw["altitude_m"])
            yaw_goal = kw["yaw"]
        else:
            self._circle_kw = None
            goal = item.pos_m
            yaw_goal = state.yaw_rad if item.yaw_rad is None else item.yaw_rad
        self._traj = Transition(state.pos_m, goal, t, self.max_speed_m_s, self.max_acc_m_s2,
                                state.vel_m_s, state.acc_m_s2, state.yaw_rad, yaw_goal,
                                start_yaw_rate_rad_s=state.yaw_rate_rad_s,
                                start_yaw_acc_rad_s2=yaw_acc, **self._transition_kw)
        self._phase, self._target = LegPhase.TRANSIT, goal


__all__ = ["CircleItem", "GotoItem", "LegFollower", "LegPhase", "MissionItem",
           "as_mission_item"]

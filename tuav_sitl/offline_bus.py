"""The winder's CAN bus offline, with the scenario's faults on it (:class:`WinderBus`).

A winder period is one exchange on the bus: the plant's sensor and encoder frames to the
winch, its torque and axis-state frames back. Under the scenario's faults
(:class:`sitl.faults.FaultSchedule`) the bus can be down (no frame either way: the axis's
watchdog disarms it and the drum brakes), lose a period's exchange (the axis holds the
torque it has), or be slow (the torque applied the round trip, twice the delay, later); a
failed winder motor gives no torque whatever it is asked.
"""

from __future__ import annotations

from sitl.faults import CanChannel, FaultSchedule


class WinderBus:
    """What the winder's axis applies, as the bus delivers the winch's commands under
    ``faults`` (None: a run without faults, every exchange delivered at once)."""

    def __init__(self, faults: FaultSchedule | None) -> None:
        self._faults = faults
        # seeded draws: the same run loses the same exchanges
        self._lost = CanChannel(seed=1)
        self._late = CanChannel(seed=2)
        self.torque_n_m = 0.0
        """The torque the winder's motor gives now [N m]."""
        self.enabled = True
        """Whether the axis is in closed-loop control now (False: disarmed, the drum
        braked)."""
        #: what the axis holds (the last command delivered: a late bus applies it until
        #: the next arrives)
        self._held = (0.0, True)

    def exchange(self) -> bool:
        """Whether this winder period's frames get through: False when the bus is down
        (the axis disarms on its watchdog) or loses this exchange (the axis holds its
        torque); then the winch hears nothing and says nothing."""
        f = self._faults
        if f is None:
            return True
        if f.can_down:
            self.torque_n_m, self.enabled = 0.0, False
            return False
        return self._lost.keep(f.can)

    def deliver(self, t_s: float, torque_n_m: float, enabled: bool) -> None:
        """The winch's torque [N m] and axis state sent at ``t_s`` [s], as the axis gets
        them (a slow bus: the last that has arrived by now, else what it holds)."""
        f = self._faults
        if f is not None and (f.can.delay_s > 0.0 or self._late.pending):
            self._late.hold(t_s, (torque_n_m, enabled))
            due = self._late.due(t_s, 2.0 * f.can.delay_s)
            torque_n_m, enabled = due[-1] if due else self._held
        self.torque_n_m, self.enabled = torque_n_m, enabled

    def settle(self) -> None:
        """End the winder period: the axis holds what it applies; a failed motor gives no
        torque."""
        self._held = (self.torque_n_m, self.enabled)
        f = self._faults
        if f is not None and f.winder_motor_failed:
            self.torque_n_m = 0.0

"""STABILIZE, ALT_HOLD, LOITER, POSHOLD and BRAKE (and GUIDED as it is entered): the vehicle
holds where the mode begins (there is no pilot stick input in a simulation)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from companion.navigation import Navigator


class Hold:
    """The holding modes: entered, any mission stops and a flying vehicle holds at the
    reference's stopping point."""

    def __init__(self, nav: Navigator) -> None:
        self.nav = nav

    def enter(self) -> None:
        """The mode has just been set."""
        nav = self.nav
        nav.mission_running = False
        if nav.flying:
            nav.plan.hold()

"""The flight modes, one room each as ArduCopter's ``mode_*.cpp``: what a mode does when it
is entered and the commands only it flies. Each holds the :class:`companion.navigation.
Navigator` it belongs to and builds on the navigator's plan (its legs, velocity target or
script, the hold, the take-off, the reach check); the navigator dispatches to them.

- :mod:`companion.modes.hold`: STABILIZE, ALT_HOLD, LOITER, POSHOLD, BRAKE (and GUIDED when
  entered): hold where the mode begins.
- :mod:`companion.modes.guided`: GUIDED's commands (take-off, targets, velocity, scripts).
- :mod:`companion.modes.auto`: AUTO, the mission.
- :mod:`companion.modes.rtl`: RTL, the return home (or to a rally point).
- :mod:`companion.modes.land`: LAND, the descent and the land detector.
"""

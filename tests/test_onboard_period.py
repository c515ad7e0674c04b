"""The companion's control period in two halves (companion.onboard.Companion.begin, .finish):
the first state is announced by what ``begin`` returns, once per boot, and what a caller does
then reaches the navigator's first step; ``step`` is the two halves at once."""

from __future__ import annotations

from nav_harness import Loop

from companion.ekf import EstimatorParams
from companion.gains import FlightControlParams
from companion.navigation import MotorState, NavigationParams
from companion.onboard import Companion, OnboardInputs


def _companion(loop: Loop) -> Companion:
    """A companion flying on the truth, not yet started (the harness starts its own)."""
    return Companion(loop.params, FlightControlParams(), NavigationParams(),
                     EstimatorParams(kind="truth"))


def test_begin_says_the_first_state_once_a_boot_before_the_navigators_first_step():
    loop = Loop()
    c = _companion(loop)
    state = loop._state()
    assert c.begin(OnboardInputs(0.0, state)) is True
    assert c.nav.arm() is None          # the script's request between the halves ...
    out = c.finish()
    assert out.armed and out.motors is MotorState.IDLE   # ... flown in this very period
    assert c.begin(OnboardInputs(c.dt_s, state)) is False
    c.finish()
    c.nav.disarm()
    c.reboot()
    assert c.begin(OnboardInputs(2.0 * c.dt_s, state)) is True   # a new boot starts again
    assert not c.finish().armed


def test_step_is_begin_then_finish():
    loop = Loop()
    whole, halves = _companion(loop), _companion(loop)
    state = loop._state()
    for k in range(5):
        inputs = OnboardInputs(k * whole.dt_s, state)
        if k == 1:      # armed: the motors idle
            assert whole.nav.arm() is None and halves.nav.arm() is None
        halves.begin(inputs)
        out = whole.step(inputs)
        assert out == halves.finish()
    assert out.motors is MotorState.IDLE

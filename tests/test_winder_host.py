"""The winder host's step on its records: a gain replaced on the controller after the
records were built is the one the next step takes (the records are built once and again
only when the controller repacks)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.lbar import LBarParams
from groundstation.winder_control import WinderControlParams
from groundstation.winder_host import WinderHost
from tuavdefs.params import SystemParams

G = 9.81
#: one period's inputs: length [m], drum rate [rad/s], drum tension [N], the UAV's
#: position [m] and velocity [m/s], the exit elevation [rad] (the length near L-bar's
#: 22.8 m and the drum turning with it: the length law unsaturated)
INPUTS = (22.9, 2.0, 6.0, (12.0, -3.0, 18.0), (0.5, 0.2, -0.1), 0.4)


def _host(gains: WinderControlParams) -> WinderHost:
    p = SystemParams()
    return WinderHost(gains, LBarParams(), p.winder, p.tether, G)


def _copy_state(src: WinderHost, dst: WinderHost) -> None:
    """Every array the step advances, from ``src`` into ``dst``."""
    for a, b in ((src.lbar.state, dst.lbar.state), (src.lbar.trim_state, dst.lbar.trim_state),
                 (src.controller.state, dst.controller.state),
                 (src.controller.tension_state, dst.controller.tension_state)):
        b[:] = a


@pytest.mark.parametrize(("law", "gain", "value"), [
    ("tension", "tension_gain_m_s_n", 0.6), ("tension", "k_speed_n_m_s", 0.5),
    ("paper", "k_length_1_s", 2.0), ("paper", "k_rate_n_m_s", 1.5)])
def test_a_gain_replaced_after_a_step_is_taken(law, gain, value):
    """Three hosts a step apart: one whose controller's gains are replaced after its first
    step, one left as it was, one built with the new gains and given the first's state.
    The replaced one's next step is the newly built one's to the bit and not the old
    one's."""
    old = WinderControlParams(law=law)
    new = old.replace(**{gain: value})
    replaced, kept, built = _host(old), _host(old), _host(new)
    for h in (replaced, kept):
        h.update(*INPUTS)
    replaced.controller.g = new
    _copy_state(replaced, built)
    a, b, c = (h.update(*INPUTS) for h in (replaced, kept, built))
    assert math.isfinite(a.torque_n_m) and not a.command.saturated
    assert a == c
    assert a.command != b.command
    # and the states the steps advanced alike
    for x, y in ((replaced.controller.tension_state, built.controller.tension_state),
                 (replaced.lbar.trim_state, built.lbar.trim_state)):
        np.testing.assert_array_equal(x, y)

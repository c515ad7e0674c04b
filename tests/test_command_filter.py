"""The attitude command filter against the continuous system it discretises (scipy's exact
zero-order-hold discretisation of the same transfer function), and the property it exists
for: a noisy command reaches the second derivative it hands the law through the filter's
lag, not through the gain wn^2."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from companion.attitude import AttitudeController, CommandFilter
from companion.gains import FlightControlParams

DT_S = 1.0 / 250.0


def _run(f: CommandFilter, u: np.ndarray) -> np.ndarray:
    """(x, x', x'') of axis 0 for the input sequence ``u`` (one value a step)."""
    f.reset((0.0, 0.0, 0.0))
    out = np.empty((u.size, 3))
    for k, v in enumerate(u):
        x, xd, xdd = f.update((v, 0.0, 0.0))
        out[k] = x[0], xd[0], xdd[0]
    return out


@pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")
@pytest.mark.parametrize("pole_hz", [0.0, 12.0, 30.0])
def test_matches_the_continuous_filter_held_input(pole_hz: float) -> None:
    wn, zeta = 2 * math.pi * 6.0, 1.0
    den = np.array([1.0, 2 * zeta * wn, wn * wn])
    num = np.array([wn * wn])
    if pole_hz > 0:
        wp = 2 * math.pi * pole_hz
        den = np.polymul(den, [1.0, wp])
        num = num * wp
    t = np.arange(400) * DT_S
    rng = np.random.default_rng(3)
    u = np.cumsum(rng.normal(0, 0.01, t.size)) + (t > 0.2)   # a step on a random walk
    # x and its derivatives as transfer functions of u: s^k H(s); zero-order hold, exact
    ours = _run(CommandFilter(6.0, zeta, DT_S, pole_hz=pole_hz), u)
    for k in range(2 if pole_hz == 0 else 3):
        nk = np.polymul(num, [1.0] + [0.0] * k)
        sys_d = signal.cont2discrete((nk, den), DT_S, method="zoh")
        _, y = signal.dlsim(sys_d[:2] + (DT_S,), u)
        assert np.allclose(ours[:, k], y[:, 0], atol=1e-9 * max(1.0, np.abs(y).max())), k


def test_second_derivative_is_a_state_with_the_pole() -> None:
    # one impulse in the command: the second-order filter's x'' jumps by wn^2 at once;
    # with the pole, x'' moves only from the next step on, by Bd's share
    u = np.zeros(50)
    u[10] = 1.0
    wn2 = (2 * math.pi * 6.0) ** 2
    second = _run(CommandFilter(6.0, 1.0, DT_S), u)
    third = _run(CommandFilter(6.0, 1.0, DT_S, pole_hz=12.0), u)
    assert second[10, 2] == pytest.approx(wn2, rel=1e-12)
    assert third[10, 2] == 0.0
    assert 0 < np.abs(third[:, 2]).max() < 0.25 * wn2


def test_white_command_noise_reaches_the_torque_less() -> None:
    # the attitude loop held level while its desired attitude jitters (as a position loop
    # on an estimate makes it): the J x'' feed-forward's share of the torque noise shrinks
    rng = np.random.default_rng(11)
    noise = rng.normal(0.0, 1e-3, (2000, 3))
    rms = {}
    for pole in (0.0, 12.0):
        ac = AttitudeController(FlightControlParams(command_filter_pole_hz=pole),
                                (0.5192, 0.4929, 0.0947), 0.0, DT_S)
        ac.reset((0.0, 0.0, 0.0))
        tau = np.array([ac.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), tuple(n)).torque_n_m
                        for n in noise])
        rms[pole] = float(np.sqrt((tau[200:, :2] ** 2).mean()))
    assert rms[12.0] < 0.5 * rms[0.0]

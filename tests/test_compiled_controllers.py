"""The controllers' compiled steps are the laws they are built from: the flight controller's
one-call step equals its components stepped one by one, the L-bar bisection that compares
with a Newton root equals the bisection that evaluates every midpoint, and the compiled
closed loop equals the interpreted one (TUAV_NO_JIT=1)."""

import math

import numpy as np
import pytest
from jit_util import run_script

from companion.flight_controller import FlightController, VehicleState
from companion.gains import FlightControlParams
from companion.position import PositionController
from companion.reference import RefSample
from groundstation.lbar import (
    LBarParams,
    _a_for_exit_slope,
    _exit_slope_root,
    lead_room_from,
    lead_room_m,
    slack_floor,
    stop_lead,
    tension_trim,
)
from groundstation.winder_control import WinderControlParams
from groundstation.winder_host import WinderHost
from tuavdefs.frames import euler_to_quat, quat_to_euler, quat_to_matrix
from tuavdefs.params import SystemParams

RNG = np.random.default_rng(20261122)


def _component_step(fc: FlightController, t: float, state: VehicleState, ref: RefSample):
    """FlightController.update written out with the components' own methods."""
    est = fc.tether_model.estimate(state.pos_m, fc.winch.length_at(t), fc.winch.tension_n)
    u_ach, tau_ach = fc.actuators.wrench()
    po = fc.position.update(fc.dt_s, state.pos_m, state.vel_m_s, ref.pos_m, ref.vel_m_s,
                            ref.acc_m_s2, ref.yaw_rad, quat_to_matrix(state.quat),
                            est.force_n, u_ach)
    ao = fc.attitude.update(quat_to_euler(state.quat), state.rates_rad_s, po.attitude_rad,
                            tau_ach)
    mix = fc.mixer.mix(po.thrust_n, ao.torque_n_m)
    fc.actuators.command(mix.commands)
    fc.actuators.advance()
    return mix.commands, mix.saturated, po, ao, est.force_n


def test_the_flight_step_is_its_components_step():
    p = SystemParams()
    fcs = [FlightController(FlightControlParams(), p.vehicle, p.tether, 9.81) for _ in "ab"]
    hover = (440.0,) * 4
    for k in range(400):
        t = 0.004 * k
        pos = tuple(RNG.uniform(-1.0, 1.0, 3) + (6.0, 2.0, 12.0))
        vel = tuple(RNG.uniform(-1.0, 1.0, 3))
        quat = euler_to_quat(*RNG.uniform(-0.3, 0.3, 3))
        state = VehicleState(pos, vel, quat, tuple(RNG.uniform(-0.5, 0.5, 3)))
        ref = RefSample((6.0, 2.0, 12.0), (0.5, 0.0, 0.0), (0.0, 0.1, 0.0), (0.0, 0.0, 0.0),
                        float(RNG.uniform(-3.0, 3.0)), 0.0)
        if k == 0:
            for fc in fcs:
                fc.reset(state, hover)
        if k % 3 == 0:
            length, tension = float(RNG.uniform(13.0, 16.0)), float(RNG.uniform(0.5, 4.0))
            for fc in fcs:
                fc.winch_report(t, length, 0.1, tension)
        a = fcs[0].update(t, state, ref)
        b = _component_step(fcs[1], t, state, ref)
        assert (a.rotor_commands, a.mixer_saturated, a.position, a.attitude,
                a.tether_force_est_n) == b
    assert np.array_equal(fcs[0].actuators.speeds, fcs[1].actuators.speeds)


def _lbar_cases(n):
    tan_min = math.tan(LBarParams().min_exit_angle_rad)
    for k in range(n):
        h = float(RNG.uniform(0.5, 80.0))
        if k % 3 == 0:   # chord barely steeper than the least exit angle: a far out
            v = h * tan_min * (1.0 + 10.0 ** RNG.uniform(-10.0, -1.0))
        else:
            v = float(RNG.uniform(0.5, 60.0))
        yield h, v, tan_min


def test_the_bisection_with_a_newton_root_is_the_bisection():
    w = 0.034 * 9.81
    a_target = LBarParams().target_horizontal_tension_n / w
    checked = 0
    guess = math.nan
    for h, v, tan_min in _lbar_cases(3000):
        if v / h <= tan_min:
            continue
        root, guard = _exit_slope_root(h, v, tan_min, a_target, guess)
        plain = _a_for_exit_slope(h, v, a_target, tan_min, math.nan, math.inf)
        assert _a_for_exit_slope(h, v, a_target, tan_min, root, guard) == plain, (h, v)
        if math.isfinite(root):
            checked += 1
            guess = root
    assert checked > 2500


def test_the_stop_leads_room_does_not_depend_on_where_its_newton_starts():
    """The stop lead's room from the last period's root (the winder step's) is the room
    from no guess, to the bit, along a path of small steps and across jumps; and from the
    last root Newton converges (a finite root), which from no guess it does not far out."""
    lp = LBarParams()
    tan_min = math.tan(lp.stop_lead_min_exit_angle_rad)
    guess, converged, n = math.nan, 0, 0
    x, y, z = 20.0, 5.0, 15.0
    for k in range(3000):
        if k % 500 == 0:            # a jump elsewhere
            x, y, z = (float(RNG.uniform(-40, 40)), float(RNG.uniform(-40, 40)),
                       float(RNG.uniform(0.5, 40)))
        x, y, z = x + float(RNG.normal(0, 0.05)), y + float(RNG.normal(0, 0.05)), max(
            z + float(RNG.normal(0, 0.05)), 0.3)
        room, root = lead_room_from(x, y, z, tan_min, lp.min_slack_m, guess)
        assert room == lead_room_m(x, y, z, tan_min, lp.min_slack_m), (x, y, z)
        if math.hypot(x, y) > 1e-6 and z / math.hypot(x, y) > tan_min:
            n += 1
            converged += math.isfinite(root)
        guess = root
    assert converged > 0.99 * n


SCRIPT = """
import json
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario
from tuavdefs import jit
sc = load_scenario("circle-windy").replace(duration_s=1.5, metrics_after_s=0.0)
s = OfflineRunner(sc).run().series
print(json.dumps({"jit": jit.JIT, **{k: s[k].tolist() for k in
                  ("pos", "euler", "torque", "rotor_cmd", "lbar", "lbar_rate",
                   "winder_torque", "d_hat")}}))
"""


def _run(no_jit: bool) -> dict:
    return run_script(SCRIPT, no_jit, 600)


def test_compiled_and_interpreted_closed_loops_agree():
    compiled, interpreted = _run(False), _run(True)
    assert compiled.pop("jit") is True and interpreted.pop("jit") is False
    for name in compiled:
        a, b = np.array(compiled[name]), np.array(interpreted[name])
        assert np.allclose(a, b, rtol=1e-7, atol=1e-9), name


def test_the_winder_step_is_its_components_step():
    p = SystemParams()
    # the paper's law's step: L-bar, its trims, its lead and floor, the length law
    hosts = [WinderHost(WinderControlParams(law="paper"), LBarParams(), p.winder, p.tether,
                        9.81) for _ in "ab"]
    for _ in range(300):
        pos = tuple(RNG.uniform(-15.0, 15.0, 2)) + (float(RNG.uniform(1.0, 30.0)),)
        vel = tuple(RNG.uniform(-2.0, 2.0, 3))
        length, omega, tension = (float(RNG.uniform(5.0, 40.0)), float(RNG.uniform(-5, 5)),
                                  float(RNG.uniform(0.0, 5.0)))
        a = hosts[0].update(length, omega, tension, pos, vel)
        b = hosts[1]
        lb = b.lbar.estimate(pos, vel)
        est = b.lbar
        tp, ts = est.trim_params, est.trim_state
        tension_trim(tp, ts, b.dt_s, lb.a_m, *pos, est.w, tension)
        ref, rate = lb.length_m + ts[0], lb.rate_m_s + ts[1]
        room = lead_room_m(*pos, tp[18], est.p.min_slack_m) - ref
        stop_lead(tp, ts, b.dt_s, *pos, *vel, ref, room, math.nan)
        ref, rate = ref + ts[4], rate + ts[5]
        slack_floor(tp, ts, b.dt_s, ref, math.nan)     # no fix: no floor
        ref, rate = ref + ts[7], rate + ts[8]
        cmd = b.controller.update(b.dt_s, length, omega, tension, ref, rate)
        assert a == (cmd.torque_n_m, ref, rate, cmd)


def test_a_replaced_parameter_takes_effect():
    """The compiled laws take their parameters packed; replacing one repacks them."""
    g1 = FlightControlParams()
    g2 = g1.replace(pos_k1_1_s=(1.0, 1.2, 1.4), disturbance_limit_m_s2=2.0)
    a = PositionController(g1, 2.84, 9.81, 80.0)
    b = PositionController(g2, 2.84, 9.81, 80.0)
    a.gains = g2
    a.u_max = b.u_max = 30.0
    args = (0.004, (1.0, 2.0, 10.0), (0.1, 0.2, 0.0), (0.0, 0.0, 10.5), (0.0, 0.0, 0.0),
            (0.0, 0.0, 0.0), 0.3)
    for _ in range(3):
        assert a.update(*args) == b.update(*args)


def _fly(fcs, steps, t0=0.0):
    """Step the controllers ``fcs`` alike on the same states; returns their last outputs."""
    rng = np.random.default_rng(7)
    out = None
    for k in range(steps):
        t = t0 + 0.004 * k
        pos = tuple(rng.uniform(-0.5, 0.5, 3) + (6.0, 2.0, 12.0))
        state = VehicleState(pos, tuple(rng.uniform(-0.5, 0.5, 3)),
                             euler_to_quat(*rng.uniform(-0.2, 0.2, 3)),
                             tuple(rng.uniform(-0.3, 0.3, 3)))
        ref = RefSample((6.0, 2.0, 12.0), (0.3, 0.0, 0.0), (0.0, 0.1, 0.0), (0.0, 0.0, 0.0),
                        0.2, 0.0)
        if k == 0 and t0 == 0.0:
            for fc in fcs:
                fc.reset(state, (440.0,) * 4)
                fc.winch_report(0.0, 14.0, 0.1, 2.0)
        out = [fc.update(t, state, ref) for fc in fcs]
    return out


def _states(fc: FlightController) -> list:
    """Every internal state of a flight controller, as plain lists."""
    a = fc.attitude
    return [fc.position._state.tolist(), a.filter.state.tolist(), a.filter.initialised,
            a.xi_eta.tolist(), a.xi_w.tolist(), a.tau_hat.tolist(), fc.actuators.speeds.tolist(),
            fc.actuators._setpoints.tolist()]


def test_set_gains_keeps_the_states_and_takes_effect():
    """PARAM_SET on a running controller: the same gains leave the next outputs
    bit-identical; a new K1 changes them, exactly as a controller built with the new gains
    in the same states would fly."""
    p = SystemParams()
    g = FlightControlParams()
    a, b = (FlightController(g, p.vehicle, p.tether, 9.81) for _ in "ab")
    _fly([a, b], 60)
    a.set_gains(g.replace())                 # equal gains, another object
    assert _states(a) == _states(b)
    same = _fly([a, b], 20, t0=0.24)
    assert same[0] == same[1]
    assert _states(a) == _states(b)
    g2 = g.replace(pos_k1_1_s=(1.1, 1.3, 1.7))
    c = FlightController(g2, p.vehicle, p.tether, 9.81)
    c.position._state[:] = a.position._state
    c.attitude.filter.state[:] = a.attitude.filter.state
    c.attitude.filter.initialised = a.attitude.filter.initialised
    c.attitude.xi_eta[:], c.attitude.xi_w[:] = a.attitude.xi_eta, a.attitude.xi_w
    c.attitude.tau_hat[:] = a.attitude.tau_hat
    c.actuators.speeds[:], c.actuators._setpoints[:] = a.actuators.speeds, a.actuators._setpoints
    c.winch_report(0.0, 14.0, 0.1, 2.0)
    before = _states(a)
    a.set_gains(g2)
    assert _states(a) == before              # set_gains itself changes no state
    after = _fly([a, b, c], 20, t0=0.32)
    assert after[0] != after[1]               # the new K1 acts at once ...
    assert after[0] == after[2]               # ... as it would from these states
    with pytest.raises(ValueError, match="rate_hz"):
        a.set_gains(g2.replace(rate_hz=500.0))


def test_set_gains_changes_the_attitude_filter_keeping_its_state():
    p = SystemParams()
    g = FlightControlParams()
    a, b = (FlightController(g, p.vehicle, p.tether, 9.81) for _ in "ab")
    _fly([a, b], 30)
    state = a.attitude.filter.state.copy()
    a.set_gains(g.replace(command_filter_hz=4.0, att_k3_1_s=(6.0, 6.0, 2.5)))
    assert np.array_equal(a.attitude.filter.state, state)
    out = _fly([a, b], 5, t0=0.12)
    assert out[0].attitude != out[1].attitude


def test_the_compiled_slowing_target_is_its_python_to_the_bit():
    """The tether governor's slowing target (companion.governor.slow_target, compiled)
    gives the same bits as its own Python source interpreted, over legs moving in every
    direction near and far from the limit, with and without a margin and a paying-out
    winch; its rate is in [0, 1] and 1 for a leg moving inward."""
    from companion.governor import slow_target

    py = getattr(slow_target, "py_func", slow_target)
    rng = np.random.default_rng(7)
    seen_slow = False
    for _ in range(3000):
        p = rng.normal(0.0, 10.0, 3)
        p[2] = abs(p[2]) + 0.5
        d = float(np.linalg.norm(p))
        vectors = (rng.normal(0.0, 2.0, 3), p, rng.normal(0.0, 1.0, 3),
                   p + rng.normal(0.0, 0.2, 3), rng.normal(0.0, 1.0, 3))
        scalars = (float(rng.uniform(0.0, 1.0)), d + float(rng.uniform(-0.2, 2.0)),
                   float(rng.uniform(0.0, 0.3)), 0.4, 3.0, float(rng.uniform(-1.0, 1.0)))
        args = (*(tuple(float(c) for c in x) for x in vectors), *(float(a) for a in scalars))
        got, want = slow_target(*args), py(*args)
        assert np.float64(got).tobytes() == np.float64(want).tobytes()
        assert 0.0 <= got <= 1.0
        seen_slow |= got < 0.5
    assert seen_slow
    # moving straight in, from inside the limit: nothing to slow
    assert slow_target((-1.0, 0.0, 0.0), (10.0, 0.0, 5.0), (0.0, 0.0, 0.0), (10.0, 0.0, 5.0),
                       (-1.0, 0.0, 0.0), 1.0, 11.5, 0.02, 0.4, 3.0, 0.0) == 1.0

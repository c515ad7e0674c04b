"""The raw tether reading fused tightly with the line's states (companion/ekf/tether_line.py;
docs/estimation.md §11): the measurement's Jacobian and noise against central differences
of the line's model, and offline on the lumped truth the line's states learnt in a hover
with GNSS in the wind."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.ekf.aid_source import AidSources
from companion.ekf.layout import (
    IDX_LINE,
    IDX_P,
    IDX_TH,
    IDX_W,
    LINE_BEPS,
    LINE_BPSI,
    LINE_KC,
    LINE_KW,
    N_ERR,
    N_PRM,
    NX,
    PRM_ATTACH_X,
    PRM_LINE_C,
    PRM_LINE_EA,
    PRM_LINE_SHEAR,
    PRM_LINE_SIG_ANG,
    PRM_LINE_SIG_GUST,
    PRM_LINE_SIG_L,
    PRM_LINE_SIG_MIN,
    PRM_LINE_SIG_T,
    PRM_LINE_SIG_T_FRAC,
    PRM_LINE_STEPS,
    PRM_LINE_W,
    X_LINE,
    X_Q,
    X_W,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import OutputPredictor
from companion.ekf.params import DragFusionParams, EstimatorParams, TetherLineParams
from companion.ekf.tether_line import TetherLineControl, line_rows
from tuavdefs import line_shape as ls
from tuavdefs.frames import euler_to_quat, quat_multiply
from tuavdefs.params import TetherParams

LINE = ls.LineModel.from_tether(TetherParams(), 9.81, 1.225)
LP = TetherLineParams()
SHEAR = 1.0 / 7.0


def _prm(steps: int = LP.steps) -> np.ndarray:
    prm = np.zeros(N_PRM)
    prm[PRM_LINE_W], prm[PRM_LINE_C], prm[PRM_LINE_EA] = (LINE.weight_n_m, LINE.drag_n_s2_m3,
                                                          LINE.ea_n)
    prm[PRM_LINE_SHEAR], prm[PRM_LINE_STEPS] = SHEAR, steps
    prm[PRM_ATTACH_X:PRM_ATTACH_X + 3] = (0.02, -0.01, 0.08)
    prm[PRM_LINE_SIG_L], prm[PRM_LINE_SIG_T] = LP.length_noise_m, LP.tension_noise_n
    prm[PRM_LINE_SIG_T_FRAC], prm[PRM_LINE_SIG_ANG] = (LP.tension_noise_fraction,
                                                       LP.angle_noise_rad)
    prm[PRM_LINE_SIG_MIN] = LP.model_sigma_m
    prm[PRM_LINE_SIG_GUST] = LP.gust_sigma_m_s
    return prm


def _exp_q(th: np.ndarray) -> tuple[float, float, float, float]:
    a = float(np.linalg.norm(th))
    if a == 0.0:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(a / 2) / a
    return (math.cos(a / 2), th[0] * s, th[1] * s, th[2] * s)


def _case(seed: int):
    rng = np.random.default_rng(seed)
    x = np.zeros(NX)
    x[0:3] = rng.uniform(-5, 5, 3)
    x[X_Q:X_Q + 4] = euler_to_quat(*rng.uniform(-0.3, 0.3, 2), rng.uniform(-3, 3))
    x[X_W:X_W + 2] = rng.uniform(-8, 8, 2)
    x[X_LINE + LINE_KC], x[X_LINE + LINE_KW] = rng.uniform(0.8, 1.2, 2)
    x[X_LINE + LINE_BPSI], x[X_LINE + LINE_BEPS] = rng.uniform(-3e-3, 3e-3, 2)
    reading = (rng.uniform(12, 35), rng.uniform(1.5, 6.0), rng.uniform(-3, 3),
               rng.uniform(0.15, 0.9))
    return x, reading, float(rng.uniform(8, 25))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_jacobian_matches_central_differences(seed):
    """Every non-zero column of H (position, attitude error as ``Exp(dtheta) R``, wind,
    the line's four states) against central differences of the innovation ``f - p - R
    r_a`` (H is minus its slope), the wind's reference height held."""
    x, (L, T, az, el), z = _case(seed)
    prm = _prm()
    h = np.zeros((3, N_ERR))
    r = np.zeros((3, 3))
    line_rows(x, prm, z, L, T, az, el, h, r)
    scratch_h, scratch_r = np.zeros((3, N_ERR)), np.zeros((3, 3))

    def innov(xx):
        return np.array(line_rows(xx, prm, z, L, T, az, el, scratch_h, scratch_r))

    cols = ([(IDX_P + i, i, 1e-4) for i in range(3)]
            + [(IDX_W + i, X_W + i, 1e-4) for i in range(2)]
            + [(IDX_LINE + k, X_LINE + k, 1e-5 if k < 2 else 1e-6) for k in range(4)])
    for col, xi, eps in cols:
        xp, xm = x.copy(), x.copy()
        xp[xi] += eps
        xm[xi] -= eps
        num = -(innov(xp) - innov(xm)) / (2 * eps)
        np.testing.assert_allclose(h[:, col], num, rtol=2e-4, atol=2e-5 * max(
            1.0, float(np.abs(num).max())), err_msg=f"column {col}")
    for i in range(3):
        d = np.zeros(3)
        d[i] = 1e-6
        q = tuple(x[X_Q:X_Q + 4])
        xp, xm = x.copy(), x.copy()
        xp[X_Q:X_Q + 4] = quat_multiply(_exp_q(d), q)
        xm[X_Q:X_Q + 4] = quat_multiply(_exp_q(-d), q)
        num = -(innov(xp) - innov(xm)) / 2e-6
        np.testing.assert_allclose(h[:, IDX_TH + i], num, atol=1e-7)
    # the biases act as the angles read the other way
    assert np.any(h[:, IDX_LINE + LINE_BPSI] != 0.0)


@pytest.mark.parametrize("seed", [4, 5])
def test_noise_is_the_readings_spread(seed):
    """R against the readings' noises propagated by central differences over their
    standard deviations (the ground fix's columns), the gusts through the wind's slope,
    the model's floor added."""
    x, (L, T, az, el), z = _case(seed)
    prm = _prm()
    h, r = np.zeros((3, N_ERR)), np.zeros((3, 3))
    line_rows(x, prm, z, L, T, az, el, h, r)
    model = ls.LineModel(LINE.weight_n_m * x[X_LINE + LINE_KW],
                         LINE.drag_n_s2_m3 * x[X_LINE + LINE_KC], LINE.ea_n, z, SHEAR, 1.0,
                         LP.steps)
    inp = ls.inputs(L, T, az, el, model, tuple(x[X_W:X_W + 2]),
                    (x[X_LINE + LINE_BPSI], x[X_LINE + LINE_BEPS]))
    sig = np.zeros(ls.N_COLUMNS)
    sig[:4] = (LP.length_noise_m, math.hypot(LP.tension_noise_n, LP.tension_noise_fraction * T),
               LP.angle_noise_rad, LP.angle_noise_rad)
    out = np.zeros((3, ls.N_COLUMNS))
    ls.differences(model, inp, sig, out)
    cols = out * sig
    # the gusts through the wind's slope (linearised: the drag's curvature over 2 m/s is
    # the wind states' own, which S carries through H)
    _, J = ls.jacobian(model, inp)
    gust = J[:, 4:6] * LP.gust_sigma_m_s
    want = cols @ cols.T + gust @ gust.T + np.eye(3) * LP.model_sigma_m ** 2
    np.testing.assert_allclose(r, want, rtol=0.02, atol=1e-6)


@pytest.mark.parametrize("wind", [(0.0, 0.0), (6.0, -2.0)])
def test_end_slopes_against_central_differences(wind):
    """:func:`tuavdefs.line_shape.end_slopes` (the tangent for the length, forward
    differences, the biases as the angles negated) against small central differences of
    the end; calm air: the wind's and drag's columns zero."""
    model = ls.LineModel(LINE.weight_n_m, LINE.drag_n_s2_m3, LINE.ea_n, 15.0, SHEAR, 1.0, 32)
    inp = ls.inputs(22.0, 2.4, 0.4, 0.5, model, wind, (1e-3, -2e-3))
    end, top, J = ls.slopes(model, inp)
    e2, J2 = ls.jacobian(model, inp)
    np.testing.assert_allclose(end, e2, atol=1e-12)
    np.testing.assert_allclose(J, J2, rtol=1e-4, atol=1e-6 * float(np.abs(J2).max()))
    if wind == (0.0, 0.0):
        assert not np.any(J[:, [ls.Column.WIND_X, ls.Column.WIND_Y, ls.Column.DRAG]])


def test_fewer_steps_keep_the_end():
    """The tight fusion's 16 Runge-Kutta steps against 400, on lines of 10-36 m in
    3-12 m/s sheared: within a centimetre (a fifth of the model's error allowed for,
    ``model_sigma_m``; 7.5 mm at worst, the 36 m line in 12 m/s)."""
    for L, el, u in ((10.0, 0.6, 3.0), (18.0, 0.3, 6.0), (36.0, 0.5, 12.0), (25.0, 1.1, 9.0)):
        ends = []
        for steps in (LP.steps, 400):
            model = ls.LineModel(LINE.weight_n_m, LINE.drag_n_s2_m3, LINE.ea_n, 15.0, SHEAR,
                                 1.0, steps)
            ends.append(np.array(ls.end(model, ls.inputs(L, 2.5, 0.2, el, model, (u, 1.0)))))
        assert np.linalg.norm(ends[0] - ends[1]) < 1e-2


def _line_control(winder_weight: bool = True
                  ) -> tuple[TetherLineControl, FilterMemory, AidSources]:
    """The raw reading's control on a filter's memory, aligned (the line's priors set, the
    line's states correlated with the position as a fusion would leave them)."""
    p = EstimatorParams(drag=DragFusionParams(
        enabled=True, tether_line=TetherLineParams(enabled=True,
                                                   winder_weight=winder_weight)))
    mem = FilterMemory(p)
    src = AidSources(p, mem.aid)
    lc = TetherLineControl(p, mem, src, OutputPredictor(mem.w), lambda: None, LINE,
                           (0.0, 0.0, 0.0))
    lc.start()
    i = IDX_LINE + LINE_KW
    mem.P[IDX_P, IDX_P] = 1.0
    mem.P[IDX_P, i] = mem.P[i, IDX_P] = 0.01
    mem.x[X_LINE + LINE_KW] = 1.1
    return lc, mem, src


def test_weight_belief_from_the_winders_estimate():
    """With ``winder_weight``, the line model's weight belief ``w_b`` (what ``k_w``
    multiplies): the parameter file's until a reading carries the winder's estimate
    within the factors' bounds (without it, always the parameter file's); the
    first one taken at once, ``k_w`` started again at 1 with its prior and uncorrelated
    (it now says how far the winder's estimate is off); later ones only while a GNSS
    position is fused, each move growing ``k_w``'s deviation by its fraction of the
    belief, up to the prior's; without GNSS the belief held."""
    off, mem_off, _ = _line_control(winder_weight=False)
    off.take_weight(1.0, 2.0 * LINE.weight_n_m, True)
    assert off.weight_belief_n_m == LINE.weight_n_m and mem_off.x[X_LINE + LINE_KW] == 1.1
    lc, mem, src = _line_control()
    w0, i = LINE.weight_n_m, IDX_LINE + LINE_KW
    sig0 = LP.weight_sigma_fraction
    for bad in (math.nan, 0.1 * w0, 6.0 * w0, math.inf):
        lc.take_weight(1.0, bad, True)
        assert lc.weight_belief_n_m == w0 and not lc.weight_from_winder
    assert mem.x[X_LINE + LINE_KW] == 1.1
    lc.take_weight(1.0, 2.0 * w0, True)                 # no GNSS: the first is taken
    assert lc.weight_belief_n_m == 2.0 * w0 and lc.weight_from_winder
    assert mem.x[X_LINE + LINE_KW] == 1.0
    assert mem.P[i, i] == pytest.approx(sig0 ** 2) and mem.P[IDX_P, i] == 0.0
    lc.take_weight(2.0, 2.2 * w0, True)                 # no GNSS: held
    assert lc.weight_belief_n_m == 2.0 * w0 and mem.P[i, i] == pytest.approx(sig0 ** 2)
    src.gnss_pos.time_last_fused = 3.0
    mem.P[i, i] = 0.01 ** 2                             # k_w learnt to 1 %
    lc.take_weight(3.0, 2.02 * w0, True)                # a 1 % move: 1 % more
    assert lc.weight_belief_n_m == 2.02 * w0
    assert math.sqrt(mem.P[i, i]) == pytest.approx(0.01 + 0.02 / 2.02)
    lc.take_weight(3.1, 1.5 * w0, True)                 # a large move: the prior's
    assert math.sqrt(mem.P[i, i]) == pytest.approx(sig0)
    assert mem.x[X_LINE + LINE_KW] == 1.0               # a factor on the belief


#: chi-square(3) two-sided 95 % bounds (position NEES).
CHI2_3_LOW, CHI2_3_HIGH = 0.2158, 9.348


def _lumped_hover(duration_s: float, wind_m_s: float, loss: tuple[float, float] | None,
                  density_factor: float = 1.0, winder_weight: bool = False,
                  gnss_check: bool = True):
    """``hover-gnss-loss-windy`` (the lumped truth, moderate turbulence, the drag fusion and
    the tight fusion on) in ``wind_m_s`` from the west, the truth's line
    ``density_factor`` times as heavy as the companion believes, the line's weight belief
    the winder's estimate with ``winder_weight``; GNSS lost over ``loss`` [s].
    Rows per control period after alignment: t, the line's states (4), k_w's variance, the
    filter's wind (2), the truth's wind at the vehicle (2), the position NEES of the
    filter's state under its P_pp, the horizontal estimate error [m]."""
    from tuav_sitl.offline import OfflineRunner
    from tuav_sitl.scenario import load_scenario

    sc = load_scenario("hover-gnss-loss-windy")
    faults = () if loss is None else (sc.faults[0].replace(start_s=loss[0], end_s=loss[1]),)
    assert sc.estimator.drag.tether_line.enabled
    teth, est = sc.plant.tether, sc.estimator
    est = est.replace(drag=est.drag.replace(tether_line=est.drag.tether_line.replace(
        winder_weight=winder_weight)), tether_fix=est.tether_fix.replace(
        gnss_check=est.tether_fix.gnss_check.replace(enabled=gnss_check)))
    sc = sc.replace(estimator=est, wind=sc.wind.replace(steady_m_s=(wind_m_s, 0.0, 0.0),
                                         wind_speed_at_6m_m_s=wind_m_s),
                    duration_s=duration_s, faults=faults,
                    plant=sc.plant.replace(tether=teth.replace(
                        linear_density_kg_m=teth.linear_density_kg_m * density_factor)))
    runner = OfflineRunner(sc)
    rows = []
    record = runner._record

    def rec(t, out, fresh):
        record(t, out, fresh)
        f = runner.companion.filter
        if f.aligned:
            P = f.covariance
            e = f._mem.x[0:3] - np.asarray(runner.plant.x[0:3])
            rows.append((t, *f.line_states, P[IDX_LINE + LINE_KW, IDX_LINE + LINE_KW],
                         *f.wind_m_s[:2], *runner.plant.wind_m_s[:2],
                         float(e @ np.linalg.solve(P[0:3, 0:3], e)), math.hypot(e[0], e[1])))

    runner._record = rec
    res = runner.run()
    return runner, res, np.array(rows)


def test_the_line_is_learnt_and_holds_a_gnss_loss_on_the_lumped_line():
    """Offline on the lumped truth (its line as the companion believes it), hovering in
    6 m/s of moderate turbulence with GNSS for 25 s, then 15 s without: the weight factor
    within two of its standard deviations of 1 and its deviation below the prior's, the
    readings fused
    throughout (with GNSS and without), the wind within 1 m/s RMS of the truth's mean at
    the vehicle, the estimate within 0.5 m of the truth horizontally during the loss, and
    the filter consistent: its position NEES inside chi-square(3)'s 95 % bounds at least
    90 % of the time."""
    runner, res, a = _lumped_hover(40.0, 6.0, (25.0, 40.0))
    f = runner.companion.filter
    st = f.aid_sources.tether_line
    assert st.time_last_fused > 39.0 and st.resets == 0
    kw, sig = a[-1, 1], math.sqrt(a[-1, 5])
    late = a[:, 0] > 5.0
    inside = float(np.mean((a[late, 10] >= CHI2_3_LOW) & (a[late, 10] <= CHI2_3_HIGH)))
    loss = a[:, 0] > 25.0
    print(f"k_w {kw:.3f} +- {sig:.3f}, k_c {a[-1, 2]:.3f}, biases {a[-1, 3]:.4f} "
          f"{a[-1, 4]:.4f} rad; NEES inside {100 * inside:.1f} % (below "
          f"{100 * np.mean(a[late, 10] < CHI2_3_LOW):.1f} %, mean "
          f"{a[late, 10].mean():.2f}; in the loss {a[loss, 10].mean():.2f}); estimate off "
          f"{a[loss, 11].max():.2f} m in the loss")
    assert abs(kw - 1.0) <= 2.0 * sig
    assert sig < LP.weight_sigma_fraction
    assert inside >= 0.9
    assert a[loss, 11].max() <= 0.5
    n = int(round(10.0 / (a[1, 0] - a[0, 0])))
    mean = np.stack([np.convolve(a[:, 8 + i], np.ones(n) / n)[:len(a)] for i in range(2)],
                    axis=1)
    late = a[:, 0] > 15.0
    err = a[late, 6:8] - mean[late]
    assert np.sqrt((err ** 2).sum(axis=1).mean()) < 1.0


def test_a_line_twice_as_heavy_is_modelled_on_the_winders_estimate():
    """Offline on a lumped truth line twice as heavy as the companion's parameter file
    says, hovering in 6 m/s of moderate turbulence with GNSS for 12 s, then 4 s without,
    ``winder_weight`` on: the line model's weight belief is the winder's estimate that
    each reading carries
    (within 25 % of the truth's weight; the parameter file's is 50 % off, beyond what
    ``k_w``'s 3 % prior covers), and the estimate stays within 1 m of the truth
    horizontally from 8 s on, the GNSS loss included (on the parameter file's weight:
    1.5-2.1 m, the tight fusion pulling the position to the light line's end).

    The ground's fix is fused beside the tight fusion here without its check against the
    GNSS (``[estimator.tether_fix.gnss_check]``, on by default): with it, the winder's
    estimate in this case comes out 43 % high (0.95 against 0.67 N/m), the two not yet
    made to work together (issue 33)."""
    runner, res, a = _lumped_hover(16.0, 6.0, (12.0, 16.0), density_factor=2.0,
                                   winder_weight=True, gnss_check=False)
    f = runner.companion.filter
    truth_w = 2.0 * LINE.weight_n_m
    w_b = f.line_weight_belief_n_m
    assert abs(w_b / truth_w - 1.0) < 0.25
    assert f.aid_sources.tether_line.time_last_fused > 15.0
    late = a[:, 0] >= 8.0
    print(f"belief {w_b:.3f} N/m (truth {truth_w:.3f}), k_w {a[-1, 1]:.3f}; horizontal "
          f"error from 8 s: max {a[late, 11].max():.2f} m")
    assert a[late, 11].max() < 1.0

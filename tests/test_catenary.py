"""Tests of sitl.catenary: agreement with MoorPy, analytic limits, identities, properties."""

from __future__ import annotations

import contextlib
import io
import math
import warnings
from collections import Counter

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sitl.catenary import (
    VERTICAL_SPAN_RATIO,
    CatenaryInfo,
    CatenaryInputError,
    CatenaryRegime,
    catenary_end_forces,
    catenary_profile,
    hanging_length_m,
)

try:  # MoorPy is the reference of the comparison tests only
    from moorpy.Catenary import catenary as moorpy_catenary
except ImportError:  # pragma: no cover
    moorpy_catenary = None
needs_moorpy = pytest.mark.skipif(moorpy_catenary is None, reason="MoorPy is not installed")

G = 9.81
W_DEFAULT = 0.034 * G  # the project's default tether
EA_DEFAULT = 1.1e5

R = CatenaryRegime


def lh_textbook(h: float, ea: float, w: float) -> float:
    """Hanging length from the quadratic's textbook root (independent of the module's form)."""
    a = ea / w
    return math.sqrt(2.0 * h * a + a * a) - a


def forward(H: float, V: float, L: float, EA: float, w: float) -> tuple[float, float]:
    """Span and height reached by a line with top tensions (H, V): the elastic catenary
    equations written naively, independently of the solver's cancellation-free forms."""
    if w * L <= V:
        Va = V - w * L
        x = H / w * (math.asinh(V / H) - math.asinh(Va / H)) + H * L / EA
        z = (H / w * (math.sqrt(1 + (V / H) ** 2) - math.sqrt(1 + (Va / H) ** 2))
             + (V * L - 0.5 * w * L * L) / EA)
    else:
        x = H / w * math.asinh(V / H) + L - V / w + H * L / EA
        z = H / w * (math.sqrt(1 + (V / H) ** 2) - 1) + V * V / (2 * w * EA)
    return x, z



# --------------------------------------------------------------------------------------------
# Random cases against MoorPy
# --------------------------------------------------------------------------------------------

KINDS = ("uniform", "suspended", "stretched", "touchdown", "slack", "vertical", "nearvertical",
         "flat", "default")
N_PER_KIND = 200


def draw_cases(seed: int = 20240611, n_per_kind: int = N_PER_KIND):
    """(kind, span, height, length, EA, w) with every regime well represented. Heights are
    either exactly 0 or >= 1 mm (MoorPy snaps 0 < h < 1e-5 L to the ground, see the report)."""
    rng = np.random.default_rng(seed)
    cases = []
    for kind in KINDS:
        for _ in range(n_per_kind):
            EA = 10.0 ** rng.uniform(3.0, 7.0)
            w = rng.uniform(0.05, 2.0)
            x = rng.uniform(0.0, 60.0)
            h = rng.uniform(1e-3, 50.0)
            if kind == "uniform":  # the brief's plain ranges
                L = rng.uniform(1.0, 60.0)
                if rng.random() < 0.1:
                    x = 0.0
                if rng.random() < 0.1:
                    h = 0.0
            elif kind == "suspended":
                h = rng.uniform(5.0, 50.0)
                L = min(math.hypot(x, h) * (1.0 + 10.0 ** rng.uniform(-5.0, -1.5)), 60.0)
            elif kind == "stretched":
                L = max(math.hypot(x, h) / (1.0 + 10.0 ** rng.uniform(-4.0, math.log10(0.3))),
                        1.0)
            elif kind == "touchdown":
                h = rng.uniform(0.01, 30.0)
                x = rng.uniform(1.0, 60.0)
                d = math.hypot(x, h)
                L = d + rng.uniform(0.0, 1.0) * (x + lh_textbook(h, EA, w) - d)
            elif kind == "slack":
                lh = lh_textbook(h, EA, w)
                x = rng.uniform(0.0, max(59.0 - lh, 0.0))
                L = rng.uniform(x + lh, max(x + lh, 60.0))
            elif kind == "vertical":
                h = rng.uniform(1.0, 50.0)
                x = 0.0 if rng.random() < 0.5 else h * rng.uniform(0.0, VERTICAL_SPAN_RATIO)
                L = min(lh_textbook(h, EA, w) * rng.uniform(0.7, 1.2), 60.0)
            elif kind == "nearvertical":  # just above the vertical threshold
                h = rng.uniform(1.0, 50.0)
                x = h * 10.0 ** rng.uniform(-3.999, -1.0)
                L = math.hypot(x, h) * rng.uniform(0.9, 1.1)
            elif kind == "flat":
                h = 0.0
                L = rng.uniform(1.0, 60.0)
                x = min(L * rng.uniform(0.5, 1.3), 60.0)
            else:  # the project's default tether
                EA, w = EA_DEFAULT, W_DEFAULT
                L = rng.uniform(1.0, 50.0)
            cases.append((kind, float(x), float(h), float(L), float(EA), float(w)))
    return cases


def run_moorpy(x, h, L, EA, w, tol, hf0=0.0, vf0=0.0):
    """MoorPy's result, or None if it raised, printed, warned, did not converge or fell back
    to one of its last-resort approximations."""
    out = io.StringIO()
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out):
        warnings.simplefilter("always")
        try:
            res = moorpy_catenary(x, h, L, EA, w, CB=0, Tol=tol, MaxIter=200, HF0=hf0, VF0=vf0)
        except Exception:  # noqa: BLE001 - any MoorPy failure only skips the case
            return None
    if out.getvalue() or caught:
        return None
    info = res[4]
    cat = info.get("catenary")
    if cat is not None and (cat["iter"] >= 199 or np.linalg.norm(cat["err"]) > 10 * tol):
        return None
    if info.get("ProfileType") in (-1, -2):
        return None
    return res


def moorpy_reference(x, h, L, EA, w):
    """MoorPy at the tightest tolerance it reaches (1e-12, 1e-10 or 1e-8 m), cold or, for
    lines stretched too far for its cold start, started from the straight-spring tension."""
    d = math.hypot(x, h)
    T = max(EA * (d - L) / L, w * L)
    spring = (T * x / d, T * h / d + 0.5 * w * L) if d > 0 else (0.0, 0.0)
    for tol in (1e-12, 1e-10, 1e-8):
        for hf0, vf0 in ((0.0, 0.0), spring):
            res = run_moorpy(x, h, L, EA, w, tol, hf0, vf0)
            if res is not None:
                return res, tol
    return None, None


MOORPY_TYPE_TO_REGIME = {0: R.FLAT, 1: R.SUSPENDED, 2: R.TOUCHDOWN, 3: R.TOUCHDOWN, 4: R.SLACK,
                         6: R.VERTICAL}


def close(a: float, b: float) -> bool:
    """The agreement criterion: within max(1e-6 |b|, 1e-4 N)."""
    return abs(a - b) <= max(1e-6 * abs(b), 1e-4)


@pytest.fixture(scope="module")
def comparison():
    """Our solution and MoorPy's for every random case, sorted into compared and skipped."""
    compared, skipped = [], Counter()
    below_ground = []
    for kind, x, h, L, EA, w in draw_cases():
        ours = catenary_end_forces(x, h, L, EA, w)
        ref, tol = moorpy_reference(x, h, L, EA, w)
        if ref is None:
            skipped["moorpy failed"] += 1
            continue
        lh = lh_textbook(h, EA, w)
        if 0.0 < x < VERTICAL_SPAN_RATIO * h and lh <= L < x + lh:
            # MoorPy's vertical branch hangs such a line below end A (through the ground)
            skipped["moorpy vertical sliver"] += 1
            continue
        if h > 0.0 and ref[1] < -1e-9:
            # MoorPy forced a suspended profile whose bottom end is pulled down: the line
            # passes below the ground (its near-taut heuristic for ZF/XF > 0.2)
            skipped["moorpy below ground"] += 1
            below_ground.append(((x, h, L, EA, w), ours, ref))
            continue
        compared.append((kind, (x, h, L, EA, w), ours, ref, tol))
    return compared, skipped, below_ground


def test_moorpy_documented_example():
    fah, fav, fbh, fbv, info = catenary_end_forces(30, 20, 40, 1.2e5, 0.3335)
    assert (fah, fav, fbh, fbv) == pytest.approx((4.026, 0.0, -4.026, -9.909), abs=1e-3)
    assert info.regime == R.TOUCHDOWN
    assert isinstance(info, CatenaryInfo)


@needs_moorpy
def test_agrees_with_moorpy_on_random_cases(comparison):
    compared, skipped, _ = comparison
    n_total = len(compared) + sum(skipped.values())
    regimes, tags, worst = Counter(), Counter(), (0.0, None)
    failures = []
    for kind, case, ours, ref, tol in compared:
        x, h, L, EA, w = case
        info = ours[4]
        regimes[info.regime.name] += 1
        tags[f"tol {tol:g}"] += 1
        t_top = math.hypot(ours[2], ours[3])
        if t_top / EA >= 1e-3:
            tags["stretched (T/EA >= 1e-3)"] += 1
        if x == 0.0 and h > 0.0:
            tags["exactly vertical (span 0)"] += 1
        elif h > 0.0 and x / h < 1e-2:
            tags["near vertical (0 < span/height < 1e-2)"] += 1
        if kind == "default":
            tags["default tether"] += 1
        for a, b in zip(ours[:4], ref[:4], strict=True):
            err = abs(a - b) / max(1e-6 * abs(b), 1e-4)
            if err > worst[0]:
                worst = (err, case)
            if not close(a, b):
                failures.append((case, ours[:4], ref[:4]))
        # the regimes must match MoorPy's profile types (up to the suspended/touchdown tie)
        mp_regime = MOORPY_TYPE_TO_REGIME.get(ref[4]["ProfileType"])
        if mp_regime != info.regime:
            assert {mp_regime, info.regime} == {R.SUSPENDED, R.TOUCHDOWN}, (case, mp_regime)
            assert abs(info.va_n) <= 1e-6 * info.vf_n + 1e-6, (case, mp_regime)
    summary = (f"{len(compared)} compared of {n_total}; regimes {dict(regimes)}; "
               f"{dict(tags)}; skipped {dict(skipped)}; worst |ours - MoorPy| = "
               f"{worst[0]:.3g} x max(1e-6|f|, 1e-4 N) at {worst[1]}")
    print(summary)
    assert not failures, f"{len(failures)} disagreements, first {failures[:3]}; {summary}"
    assert len(compared) >= 1000, summary
    for regime in R:
        assert regimes[regime.name] >= 100, summary
    assert tags["stretched (T/EA >= 1e-3)"] >= 100, summary
    assert tags["exactly vertical (span 0)"] >= 50, summary
    assert tags["near vertical (0 < span/height < 1e-2)"] >= 100, summary
    assert tags["default tether"] >= 150, summary
    assert sum(skipped.values()) <= 0.02 * n_total, summary
    assert skipped["moorpy failed"] <= 0.005 * n_total, summary


@needs_moorpy
def test_cases_moorpy_puts_below_ground_are_touchdowns(comparison):
    """Where MoorPy's heuristic lets the line dip below the ground, ours lies on it instead and
    still reaches B."""
    _, _, below_ground = comparison
    for (x, h, L, EA, w), ours, ref in below_ground:
        assert ref[1] < 0.0
        assert ours[4].regime == R.TOUCHDOWN
        assert ours[1] == 0.0
        px, pz = catenary_profile(x, h, L, EA, w, n_points=20)
        assert px[-1] == pytest.approx(x, abs=1e-9 * (L + x + h))
        assert pz[-1] == pytest.approx(h, abs=1e-9 * (L + x + h))
        assert pz.min() >= -1e-12


# --------------------------------------------------------------------------------------------
# Analytic limits and exact identities
# --------------------------------------------------------------------------------------------

def test_weightless_taut_line_is_a_straight_spring():
    x, h, L, EA = 30.0, 40.0, 45.0, 1.0e5
    d = math.hypot(x, h)
    T = EA * (d - L) / L
    fah, fav, fbh, fbv, info = catenary_end_forces(x, h, L, EA, 1e-9)
    assert info.regime == R.SUSPENDED
    assert (fah, fav, fbh, fbv) == pytest.approx((T * x / d, T * h / d, -T * x / d, -T * h / d),
                                                 rel=1e-9)


@pytest.mark.parametrize("w", [0.05, W_DEFAULT, 2.0])
def test_vertical_taut_line(w):
    h, L, EA = 30.0, 29.9, 1.0e4
    T0 = EA * (h - L) / L - 0.5 * w * L  # bottom tension
    for x in (0.0, 0.5 * VERTICAL_SPAN_RATIO * h):
        fah, fav, fbh, fbv, info = catenary_end_forces(x, h, L, EA, w)
        assert info.regime == R.VERTICAL
        assert (fah, fbh) == (0.0, 0.0)
        assert fav == pytest.approx(T0, rel=1e-12)
        assert -fbv == pytest.approx(T0 + w * L, rel=1e-12)  # top = bottom + weight
        assert info.length_on_ground_m == 0.0


@pytest.mark.parametrize("x", [0.0, 12.0])
def test_slack_line_hangs_vertically(x):
    h, L, EA, w = 20.0, 45.0, 1.0e3, 1.5  # soft, so the stretch is visible
    fah, fav, fbh, fbv, info = catenary_end_forces(x, h, L, EA, w)
    lh = lh_textbook(h, EA, w)
    assert info.regime == R.SLACK
    assert (fah, fav, fbh) == (0.0, 0.0, 0.0)
    assert -fbv == pytest.approx(w * lh, rel=1e-12)  # top tension = weight hanging
    assert w * h * (1 - w * h / (2 * EA)) <= -fbv <= w * h  # the weight of h, within stretch
    assert info.length_on_ground_m == pytest.approx(L - lh, rel=1e-12)
    assert hanging_length_m(h, EA, w) == pytest.approx(lh, rel=1e-12)


def test_slack_threshold_accounts_for_stretch():
    h, EA, w, x = 20.0, 1.0e3, 1.5, 5.0
    lh = lh_textbook(h, EA, w)
    assert lh < h
    assert catenary_end_forces(x, h, x + lh * (1 + 1e-12), EA, w)[4].regime == R.SLACK
    below = catenary_end_forces(x, h, (x + lh) * (1 - 1e-6), EA, w)[4]
    assert below.regime == R.TOUCHDOWN
    assert 0.0 < below.hf_n < 1e-3


def test_flat_line():
    fah, fav, fbh, fbv, info = catenary_end_forces(30.0, 0.0, 25.0, 1.0e4, 0.5)
    assert info.regime == R.FLAT
    assert (fah, fbh) == pytest.approx((1.0e4 * 5 / 25, -1.0e4 * 5 / 25), rel=1e-12)
    assert (fav, fbv) == (0.0, 0.0)
    assert catenary_end_forces(20.0, 0.0, 25.0, 1.0e4, 0.5)[:4] == (0.0, 0.0, -0.0, -0.0)
    assert catenary_end_forces(0.0, 0.0, 25.0, 1.0e4, 0.5)[4].regime == R.FLAT


def elastic_identity_error(x, h, L, EA, w):
    """|lhs - rhs| / (w h) of (T_top - T_low) + (T_top^2 - T_low^2)/(2 EA) = w h, with T_low the
    tension where the line leaves the ground (A if it is suspended)."""
    fah, fav, fbh, fbv, info = catenary_end_forces(x, h, L, EA, w)
    t_top = math.hypot(fbh, fbv)
    t_low = math.hypot(fah, fav)  # H at a touchdown point, 0 for a slack line
    lhs = (t_top - t_low) + (t_top ** 2 - t_low ** 2) / (2 * EA)
    return abs(lhs - w * h) / (w * h), info


def test_exact_elastic_identities_on_random_cases():
    regimes = Counter()
    for _, x, h, L, EA, w in draw_cases(seed=7, n_per_kind=40):
        if h == 0.0:
            continue
        err, info = elastic_identity_error(x, h, L, EA, w)
        regimes[info.regime] += 1
        # T - T_low grows with the height like the weight; ill-conditioned only when the
        # tension is huge compared with w h
        t_top = math.hypot(info.hf_n, info.vf_n)
        assert err <= 1e-9 * (1 + t_top / (w * h)), (x, h, L, EA, w, info)
        if info.regime == R.SUSPENDED:
            # V_top - V_bot = w L (to the rounding of V_bot = V_top - w L)
            assert info.vf_n - info.va_n == pytest.approx(w * L, rel=1e-12, abs=1e-15 * info.vf_n)
            assert info.ha_n == info.hf_n
        if info.regime == R.TOUCHDOWN:
            assert info.vf_n == pytest.approx(w * (L - info.length_on_ground_m), rel=1e-12)
        assert info.lowest_point_height_m == 0.0
    assert all(regimes[r] >= 10 for r in (R.SUSPENDED, R.TOUCHDOWN, R.SLACK, R.VERTICAL))


# --------------------------------------------------------------------------------------------
# Warm starts
# --------------------------------------------------------------------------------------------

def test_warm_start_gives_the_cold_result():
    n_warm = 0
    for _, x, h, L, EA, w in draw_cases(seed=11, n_per_kind=30):
        cold = catenary_end_forces(x, h, L, EA, w)
        info = cold[4]
        # from the exact solution, from a neighbour's, and from a poor guess
        starts = [(info.hf_n, info.vf_n)]
        near = catenary_end_forces(x * 1.01 + 0.01, h * 0.99 + 0.01, L * 1.01, EA, w)[4]
        starts.append((near.hf_n, near.vf_n))
        starts.append((1e6, 1e-3))
        # agreement to the solver's accuracy: 1e-8^2 relative per component, rounding of the
        # larger one
        atol = 1e-12 * (info.hf_n + info.vf_n) + 1e-12
        for hf0, vf0 in starts:
            warm = catenary_end_forces(x, h, L, EA, w, hf0, vf0)
            for a, b in zip(warm[:4], cold[:4], strict=True):
                assert a == pytest.approx(b, rel=1e-10, abs=atol), (x, h, L, EA, w, hf0, vf0)
            assert warm[4].regime == info.regime
        if info.regime in (R.SUSPENDED, R.TOUCHDOWN):
            exact = catenary_end_forces(x, h, L, EA, w, info.hf_n, info.vf_n)[4]
            assert exact.warm_started
            assert exact.iterations <= 1
            n_warm += 1
    assert n_warm >= 100


def test_warm_start_needs_fewer_iterations_nearby():
    x, h, L, EA, w = 25.0, 30.0, 40.0, EA_DEFAULT, W_DEFAULT
    cold = catenary_end_forces(x, h, L, EA, w)[4]
    warm = catenary_end_forces(x + 1e-3, h - 1e-3, L, EA, w, cold.hf_n, cold.vf_n)[4]
    fresh = catenary_end_forces(x + 1e-3, h - 1e-3, L, EA, w)[4]
    assert warm.warm_started and not fresh.warm_started
    assert warm.iterations < fresh.iterations
    assert warm.hf_n == pytest.approx(fresh.hf_n, rel=1e-10)


# --------------------------------------------------------------------------------------------
# Properties (hypothesis)
# --------------------------------------------------------------------------------------------

spans = st.floats(0.0, 60.0)
heights = st.floats(0.0, 50.0)
lengths = st.floats(1.0, 60.0)
stiffnesses = st.floats(3.0, 7.0).map(lambda e: 10.0 ** e)
weights = st.floats(0.05, 2.0)


@settings(max_examples=400, deadline=None)
@given(spans, heights, lengths, stiffnesses, weights)
def test_forces_are_finite_and_balanced(x, h, L, EA, w):
    fah, fav, fbh, fbv, info = catenary_end_forces(x, h, L, EA, w)
    assert all(math.isfinite(f) for f in (fah, fav, fbh, fbv))
    assert fah == -fbh >= 0.0  # frictionless ground: horizontal tension is uniform
    assert fbv <= 0.0 and fav >= 0.0  # B pulled down, A never pulled into the ground
    # vertical balance: the line's weight off the ground is carried by its two ends
    suspended = L - info.length_on_ground_m
    assert fav + fbv == pytest.approx(-w * suspended, rel=1e-9, abs=1e-9 * max(w * L, -fbv))
    assert 0.0 <= info.length_on_ground_m <= L
    assert info.lowest_point_height_m == 0.0


@settings(max_examples=300, deadline=None)
@given(lengths, stiffnesses, weights, st.floats(0.1, 10.0), st.floats(0.05, 3.0))
def test_recovers_tensions_from_the_geometry_they_produce(L, EA, w, h_ratio, v_ratio):
    """Round trip: top tensions (H, V) -> end position by the catenary equations -> solver."""
    H, V = h_ratio * w * L, v_ratio * w * L
    x, z = forward(H, V, L, EA, w)
    assume(z > 0.0 and x > 2.0 * VERTICAL_SPAN_RATIO * z)
    _, _, fbh, fbv, info = catenary_end_forces(x, z, L, EA, w)
    assert -fbh == pytest.approx(H, rel=1e-7)
    assert -fbv == pytest.approx(V, rel=1e-7)
    if abs(V - w * L) > 1e-9 * w * L:  # else a tie that rounding decides
        assert info.regime == (R.SUSPENDED if w * L <= V else R.TOUCHDOWN)


def max_force_change(a, b) -> float:
    return max(abs(p - q) for p, q in zip(a[:4], b[:4], strict=True))


@settings(max_examples=200, deadline=None)
@given(stiffnesses, weights, st.floats(0.1, 50.0), st.floats(0.0, 60.0))
def test_continuous_at_slack_boundary(EA, w, h, x):
    L = x + hanging_length_m(h, EA, w)
    assume(L >= 1e-3 and x >= 2.0 * VERTICAL_SPAN_RATIO * h)
    at = catenary_end_forces(x, h, L, EA, w)
    below = catenary_end_forces(x, h, L * (1 - 1e-10), EA, w)
    assert at[4].regime == R.SLACK and below[4].regime == R.TOUCHDOWN
    assert max_force_change(at, below) <= 1e-6 * w * L + 1e-12


@settings(max_examples=200, deadline=None)
@given(lengths, stiffnesses, weights, st.floats(0.1, 5.0))
def test_continuous_between_suspended_and_touchdown(L, EA, w, h_ratio):
    H, V = h_ratio * w * L, w * L  # bottom vertical tension exactly 0: the boundary
    x, z = forward(H, V, L, EA, w)
    shorter = catenary_end_forces(x, z, L * (1 - 1e-11), EA, w)
    longer = catenary_end_forces(x, z, L * (1 + 1e-11), EA, w)
    assert shorter[4].regime == R.SUSPENDED and longer[4].regime == R.TOUCHDOWN
    assert max_force_change(shorter, longer) <= 1e-6 * math.hypot(H, V)


@settings(max_examples=200, deadline=None)
@given(stiffnesses, weights, st.floats(1.0, 50.0),
       st.one_of(st.floats(0.7, 1.3), st.floats(0.999, 1.0)))
def test_continuous_at_vertical_threshold(EA, w, h, l_ratio):
    """Across span = 1e-4 height (MoorPy's vertical threshold) the forces jump, as MoorPy's do:
    H from at most 1e-4 T (the top tangent is steeper than the chord) to 0, and the vertical
    formula misses the path the line needs to reach 1e-4 h sideways, a stretch worth at most
    about 17 EA (h/L) 1e-8 (the supremum of a random search, reached when the bottom tension
    is zero). Nothing jumps by more."""
    L = l_ratio * h
    x0 = VERTICAL_SPAN_RATIO * h
    inside = catenary_end_forces(x0 * (1 - 1e-9), h, L, EA, w)
    outside = catenary_end_forces(x0 * (1 + 1e-9), h, L, EA, w)
    assert inside[4].regime in (R.VERTICAL, R.SLACK)
    T = math.hypot(outside[2], outside[3])
    bound = 1.01 * VERTICAL_SPAN_RATIO * T + 20 * EA * h / L * VERTICAL_SPAN_RATIO ** 2
    assert max_force_change(inside, outside) <= bound


@settings(max_examples=200, deadline=None)
@given(lengths, stiffnesses, weights, st.floats(0.5, 1.2))
def test_continuous_as_height_goes_to_zero(L, EA, w, x_ratio):
    x = x_ratio * L
    flat = catenary_end_forces(x, 0.0, L, EA, w)
    eps = 1e-9
    lifted = catenary_end_forces(x, eps, L, EA, w)
    H = -flat[2]
    # a taut line lifted by eps: V ~ sqrt(2 H w eps); a slack one: V ~ w eps; one just taut
    # (H = 0) must stretch: H ~ (EA/L)^(2/3) w^(1/3) eps
    bound = (1.5 * math.sqrt(2 * H * w * eps) + 2 * w * eps + 1e-6 * H
             + 2 * (EA / L) ** (2 / 3) * w ** (1 / 3) * eps)
    assert max_force_change(flat, lifted) <= bound


# --------------------------------------------------------------------------------------------
# Profile
# --------------------------------------------------------------------------------------------

def test_profile_reaches_both_ends_and_has_the_stretched_length():
    cases = draw_cases(seed=3, n_per_kind=15)
    seen = Counter()
    for _, x, h, L, EA, w in cases:
        # fine enough to follow the bend at touchdown, whose radius H/w can be centimetres
        px, pz = catenary_profile(x, h, L, EA, w, n_points=20001)
        info = catenary_end_forces(x, h, L, EA, w)[4]
        seen[info.regime] += 1
        scale = L + x + h
        assert (px[0], pz[0]) == pytest.approx((0.0, 0.0), abs=1e-12 * scale)
        assert px[-1] == pytest.approx(x, abs=1e-9 * scale)
        assert pz[-1] == pytest.approx(h, abs=1e-9 * scale)
        assert pz.min() >= -1e-12 * scale
        assert np.all(np.diff(px) >= -1e-9 * scale) and np.all(np.diff(pz) >= -1e-9 * scale)
        if info.regime in (R.SUSPENDED, R.TOUCHDOWN):
            # polyline length vs the stretched length, L + int T/EA ds (tension along the line)
            s = np.linspace(0, L, 4001)
            v = np.where(s < info.length_on_ground_m, 0.0,
                         info.va_n + w * (s - info.length_on_ground_m))
            t = np.hypot(info.hf_n, v)
            stretched = L + np.sum((t[1:] + t[:-1]) / 2 * np.diff(s)) / EA
            poly = np.sum(np.hypot(np.diff(px), np.diff(pz)))
            assert poly == pytest.approx(stretched, rel=1e-4)
        if info.regime == R.TOUCHDOWN:
            on_ground = pz == 0.0
            assert on_ground.sum() >= 2
            assert px[on_ground].max() == pytest.approx(
                info.length_on_ground_m * (1 + info.hf_n / EA), rel=1e-12)
    assert all(seen[r] > 0 for r in R)


def test_profile_rejects_too_few_points():
    with pytest.raises(CatenaryInputError, match="n_points"):
        catenary_profile(10, 10, 20, 1e5, 0.3, n_points=1)


# --------------------------------------------------------------------------------------------
# Input errors
# --------------------------------------------------------------------------------------------

GOOD = dict(span_m=10.0, height_m=10.0, length_m=20.0, ea_n=1e5, w_n_per_m=0.3)


@pytest.mark.parametrize("name, bad", [
    ("span_m", -1.0), ("span_m", math.nan), ("span_m", math.inf),
    ("height_m", -1e-9), ("height_m", math.nan), ("height_m", -math.inf),
    ("length_m", 0.0), ("length_m", -1.0), ("length_m", math.nan), ("length_m", math.inf),
    ("ea_n", 0.0), ("ea_n", -1.0), ("ea_n", math.nan), ("ea_n", math.inf),
    ("w_n_per_m", 0.0), ("w_n_per_m", -0.3), ("w_n_per_m", math.nan), ("w_n_per_m", math.inf),
    ("hf0", math.nan), ("vf0", math.inf), ("tol", 0.0), ("tol", math.nan),
])
def test_input_errors_name_the_argument(name, bad):
    kwargs = dict(GOOD, **{name: bad})
    with pytest.raises(CatenaryInputError, match=name) as excinfo:
        catenary_end_forces(**kwargs)
    assert isinstance(excinfo.value, ValueError)


def test_negative_warm_start_is_ignored():
    cold = catenary_end_forces(**GOOD)
    warm = catenary_end_forces(**GOOD, hf0=-5.0, vf0=3.0)
    assert warm[:4] == cold[:4] and not warm[4].warm_started

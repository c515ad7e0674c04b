"""The streamed reference's compiled sampling (companion.planner.piecewise1_kernel,
companion.reference.circle_kernel): to the bit what Horner's rule on each piece and the
kernels' own Python source give."""

from __future__ import annotations

import bisect
import math
import pickle
import struct

import numpy as np

from companion.planner import Piecewise, _horner
from companion.reference import Circle, circle_kernel


def _bits(values) -> bytes:
    return struct.pack(f"{len(values)}d", *values)


def test_a_scalar_piecewise_of_mixed_degrees_is_horners_on_its_piece() -> None:
    """Pieces of different degrees (the shorter led by zeros in one table): before the
    start the first piece's start, after the end the final value at rest, between them
    Horner's rule on the piece that started last, to the bit."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        degrees = rng.integers(0, 8, 4)
        pieces = [(float(rng.uniform(0.1, 3.0)), rng.normal(0.0, 10.0, (1, int(d) + 1)))
                  for d in degrees]
        pw = Piecewise(float(rng.uniform(-5.0, 5.0)), pieces, None, 1)
        starts = [pw.t0]
        for dur, _ in pieces[:-1]:
            starts.append(starts[-1] + dur)
        last = len(pieces) - 1
        final = _horner(pw._p[last][0], pieces[last][0])
        for t in (*rng.uniform(pw.t0 - 1.0, pw.end + 1.0, 300), pw.t0, pw.end, *starts):
            t = float(t)
            if t >= pw.end:
                want = (final, 0.0, 0.0, 0.0)
            else:
                i = max(bisect.bisect_right(starts, t) - 1, 0) if t > pw.t0 else 0
                tau = t - starts[i] if t > pw.t0 else 0.0
                want = tuple(_horner(store[i][0], tau) for store in (pw._p, pw._v, pw._a,
                                                                      pw._j))
            got = tuple(v for (v,) in pw.eval(t))
            assert _bits(got) == _bits(want), (t, got, want)


def test_the_compiled_circle_is_its_python_to_the_bit() -> None:
    """circle_kernel against its own source interpreted, over circles of every size and
    sense, endless or of a few turns, before, in and after their ramps; a circle still
    pickles (a scenario's trajectory sent to a worker) and samples the same after."""
    rng = np.random.default_rng(3)
    py = getattr(circle_kernel, "py_func", circle_kernel)
    for _ in range(30):
        r = float(rng.uniform(1.0, 30.0))
        speed = float(rng.uniform(0.2, 0.9)) * math.sqrt(3.0 * r)
        turns = math.inf if rng.uniform() < 0.5 else float(rng.uniform(0.2, 3.0))
        c = Circle(rng.normal(0.0, 10.0, 2), r, float(rng.uniform(2.0, 30.0)), speed,
                   float(rng.uniform(0.0, 10.0)), lead_in_s=Circle.min_lead_in_s(
                       r, speed, 3.0) * float(rng.uniform(1.0, 2.0)),
                   turns=turns, start_angle_rad=float(rng.uniform(-4.0, 4.0)),
                   clockwise=bool(rng.uniform() < 0.5), face_travel=bool(rng.uniform() < 0.5))
        end = c.end_s if math.isfinite(c.end_s) else c.start_s + 60.0
        arc = c._arc
        for t in (*rng.uniform(c.start_s - 2.0, end + 2.0, 100), c.start_s, c.end_s):
            args = (float(t), arc.times1, arc.cols1, c._geometry)
            assert _bits(circle_kernel(*args)) == _bits(py(*args))
            s = c.sample(float(t))
            assert all(math.isfinite(x) for v in s[:4] for x in v)
        assert pickle.loads(pickle.dumps(c)).sample(end) == c.sample(end)

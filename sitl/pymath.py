"""CPython's ``math.hypot``, written so that numba compiles it to the same bits.

numba's ``math.hypot`` calls the C library's two-argument ``hypot``, and it has no
three-argument form; CPython's ``math.hypot`` (any number of arguments) computes the norm
with its own algorithm (lossless power-of-two scaling, Veltkamp-Dekker splitting,
compensated summation and a differential correction of the square root: ``vector_norm`` in
CPython's ``Modules/mathmodule.c``, 3.10 and later), which is almost always correctly
rounded but not always equal to the C library's. The truth model's Python code uses
CPython's; the compiled code that replaces it uses :func:`hypot2` and :func:`hypot3`, so
the two give the same results to the bit (``tests/test_pymath.py`` checks it on many
inputs, including the hard cases).

Plain IEEE-754 double arithmetic only: no fused multiply-adds (numba does not contract
without ``fastmath``), so the splitting is exact.
"""

from __future__ import annotations

import math

from sitl._jit import njit

#: 2^27 + 1, Veltkamp's splitting constant for doubles.
_T27 = 134217729.0


@njit
def _norm(a: float, b: float, c: float, n: int) -> float:
    """CPython's ``vector_norm`` of the ``n`` (2 or 3) magnitudes ``a, b[, c]`` (all
    finite and >= 0)."""
    mx = a
    if b > mx:
        mx = b
    if n == 3 and c > mx:
        mx = c
    if mx == 0.0:
        return mx
    _, max_e = math.frexp(mx)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    frac3 = 0.0
    if max_e >= -1023:
        scale = math.ldexp(1.0, -max_e)
        for i in range(n):
            x = a if i == 0 else (b if i == 1 else c)
            x *= scale
            t = x * _T27
            hi = t - (t - x)
            lo = x - hi
            x = hi * hi
            oldcsum = csum
            csum += x
            frac1 += (oldcsum - csum) + x
            x = 2.0 * hi * lo
            oldcsum = csum
            csum += x
            frac2 += (oldcsum - csum) + x
            frac3 += lo * lo
        h = math.sqrt(csum - 1.0 + (frac1 + frac2 + frac3))
        x = h
        t = x * _T27
        hi = t - (t - x)
        lo = x - hi
        x = -hi * hi
        oldcsum = csum
        csum += x
        frac1 += (oldcsum - csum) + x
        x = -2.0 * hi * lo
        oldcsum = csum
        csum += x
        frac2 += (oldcsum - csum) + x
        x = -lo * lo
        oldcsum = csum
        csum += x
        frac3 += (oldcsum - csum) + x
        x = csum - 1.0 + (frac1 + frac2 + frac3)
        return (h + x / (2.0 * h)) / scale
    # subnormal magnitudes: divide by the largest instead of scaling
    for i in range(n):
        x = a if i == 0 else (b if i == 1 else c)
        x /= mx
        x = x * x
        oldcsum = csum
        csum += x
        frac1 += (oldcsum - csum) + x
    return mx * math.sqrt(csum - 1.0 + frac1)


@njit
def hypot2(x: float, y: float) -> float:
    """``math.hypot(x, y)`` as CPython computes it (same units as ``x``, ``y``)."""
    a = abs(x)
    b = abs(y)
    if math.isinf(a) or math.isinf(b):
        return math.inf
    if math.isnan(a) or math.isnan(b):
        return math.nan
    return _norm(a, b, 0.0, 2)


@njit
def hypot3(x: float, y: float, z: float) -> float:
    """``math.hypot(x, y, z)`` as CPython computes it (same units as the arguments)."""
    a = abs(x)
    b = abs(y)
    c = abs(z)
    if math.isinf(a) or math.isinf(b) or math.isinf(c):
        return math.inf
    if math.isnan(a) or math.isnan(b) or math.isnan(c):
        return math.nan
    return _norm(a, b, c, 3)

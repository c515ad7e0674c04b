"""numba's ``njit`` for the plant's scalar kernels, or the plain function without numba.

The kernels are written in scalar Python that numba compiles unchanged, so there is one
source for the model whichever way it runs. ``TUAV_NO_JIT=1`` runs them as plain Python
(for debugging and coverage); compiled code is cached next to the sources.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

try:
    if os.environ.get("TUAV_NO_JIT") == "1":
        raise ImportError("TUAV_NO_JIT=1")
    from numba import njit as _njit

    JIT = True
except ImportError:  # numba absent or disabled: the same code, interpreted
    _njit = None
    JIT = False


def njit(fn: F) -> F:
    """Compile ``fn`` in nopython mode with an on-disk cache (identity without numba)."""
    if _njit is None:
        return fn
    return _njit(cache=True)(fn)  # type: ignore[no-any-return]

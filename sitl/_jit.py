"""numba's ``njit`` for the plant's scalar kernels: :mod:`tuavdefs.jit`, re-exported.

The helper lives in the shared package so that the controllers (``companion``,
``groundstation``), which never import ``sitl``, compile their laws the same way.
``TUAV_NO_JIT=1`` runs every kernel as plain Python.
"""

from __future__ import annotations

from tuavdefs.jit import JIT, njit

__all__ = ["JIT", "njit"]

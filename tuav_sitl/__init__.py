"""The ``tuav-sitl`` command: the front door that ties the plant, the companion and the
ground station together (offline runs, the three-process stack, plots, tools).

This is the only package allowed to import ``sitl``, ``companion`` and ``groundstation``
together; they never import each other.
"""

import os as _os

# One BLAS thread: the matrices here are at most 22 x 22, and OpenBLAS's worker threads,
# started by the first product, spin for 50-100 ms after each burst of work, stealing the
# other core from the simulation, a sweep's second worker or the stack's processes (which
# inherit this). Set before NumPy is first imported; a user's own setting wins.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")

"""The ``tuav-sitl`` command: the front door that ties the plant, the companion and the
ground station together (offline runs, the three-process stack, plots, tools).

This is the only package allowed to import ``sitl``, ``companion`` and ``groundstation``
together; they never import each other.
"""

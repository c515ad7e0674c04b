"""Definitions shared by the plant, the companion and the ground station.

Parameters (typed dataclasses loaded from TOML), reference frames and their conversions,
and protocol constants. Small on purpose: nothing here knows the physics or the control.
"""

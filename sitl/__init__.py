"""The SITL plant: the truth model of the tethered UAV, tether, winder and wind.

Never imports ``companion`` or ``groundstation``; shares only ``tuavdefs`` with them.
"""

"""The winch component's settings (:class:`WinchParams`), a scenario's ``[winch]`` table
and the ground station's (``groundstation/station_params.py``)."""

from __future__ import annotations

from dataclasses import dataclass

from tuavdefs.paramspec import Params, quantity

#: Encoder silence after which the drum is braked and the stream reported lost [s, wall].
ENCODER_TIMEOUT_S = 0.1


@dataclass(frozen=True)
class WinchParams(Params):
    """Settings of the winch component (rates, limits, reporting)."""

    default_rate_m_s: float = quantity(
        0.5, "m/s", "line speed of RELATIVE_LENGTH_CONTROL when param4 is 0 or NaN", gt=0)
    retract_rate_m_s: float = quantity(
        0.5, "m/s", "line speed of RETRACT when param4 is 0 or NaN", gt=0)
    rejoin_rate_m_s: float = quantity(
        1.0, "m/s", "fastest wind-in of RELAXED back to L-bar from a longer line (after "
        "a pay-out: no jerk of the UAV)", gt=0)
    status_rate_hz: float = quantity(
        20.0, "Hz", "WINCH_STATUS rate in simulated time (encoder frames)", gt=0)
    status_wall_period_s: float = quantity(
        0.09, "s", "WINCH_STATUS after this much wall time without one (a process polling "
        "every 10 ms then never leaves a gap over 0.1 s)", gt=0)
    encoder_timeout_s: float = quantity(
        ENCODER_TIMEOUT_S, "s", "wall-clock encoder silence that brakes the drum", gt=0)
    moving_speed_m_s: float = quantity(
        0.01, "m/s", "line speed above which WINCH_STATUS says MOVING", ge=0)
    retracted_tolerance_m: float = quantity(
        0.02, "m", "FULLY_RETRACTED within this of the taut floor", ge=0)
    end_margin_m: float = quantity(
        0.5, "m", "tether always left on the drum below its capacity", ge=0)
    duplicate_window_s: float = quantity(
        3.0, "s", "a retransmitted COMMAND_LONG within this [wall] is acknowledged again, "
        "not executed again", ge=0)
    tension_limit_n: float = quantity(
        30.0, "N", "load-cell tension above which the winch pays out (the over-tension "
        "failsafe), whatever the active mode but LOCK and HOLD", gt=0)
    overtension_s: float = quantity(
        0.1, "s", "the tension above its limit this long (simulated time) starts the "
        "pay-out; it ends below 90 % of the limit", ge=0)
    overtension_rate_m_s: float = quantity(
        0.5, "m/s", "line speed of the over-tension pay-out", gt=0)
    stuck_error_m: float = quantity(
        0.1, "m", "the length this far behind a reference that pays out (the law tracks "
        "within 2 cm) for stuck_s: the drum is stuck", gt=0)
    sensor_rate_hz: float = quantity(
        100.0, "Hz", "rate of the load cell's frames (Winch_Tension)", gt=0)
    bus_window_s: float = quantity(
        0.1, "s", "the CAN bus is judged over windows this long (of the load cell's "
        "stamps)", gt=0)
    bus_lost_max: float = quantity(
        0.3, "1", "a window with more of the load cell's frames lost: the bus is degraded",
        gt=0, le=1)
    bus_late_max_s: float = quantity(
        0.05, "s", "a window whose frames all came later than this (against the UAV's "
        "position): the bus is degraded", gt=0)
    bus_good_windows: int = quantity(
        10, "1", "good windows in a row that end a degraded bus", ge=1)
    stuck_speed_m_s: float = quantity(
        0.05, "m/s", "a drum whose line moves slower than this (either way) while it lags "
        "may be stuck", gt=0)
    stuck_s: float = quantity(
        0.1, "s", "how long (simulated time) the drum lags stuck_error_m before it counts "
        "as stuck", ge=0)
    stuck_tension_n: float = quantity(
        1.0, "N", "tension law: the pull this far above the set-point, the drum standing "
        "and its law asking no wind-in, for stuck_s: the drum is stuck (a free drum renders "
        "to any pull above its set-point at once; the lag of stuck_error_m tells 0.1-0.4 s "
        "later)", gt=0)
    max_extrapolation_s: float = quantity(
        0.1, "s", "the UAV's reported position is carried forward by its velocity to the "
        "winch's sample time over gaps up to this", ge=0)
    ground_tension_n: float = quantity(
        0.3, "N", "RELAXED with the UAV on the ground (or its position unknown): the drum "
        "holds this tension on the line (a pre-tension: the line lies straight, the guide "
        "arm follows it and the tether fix stays readable); 0: it holds its length", ge=0)
    ground_height_m: float = quantity(
        0.6, "m", "the UAV counts as on the ground while it reports a height below this "
        "(at rest on its gear it reports about its gear height)", ge=0)
    ground_tension_gain_m_s_n: float = quantity(
        1.0, "m/(s*N)", "the pre-tension's loop: line speed of the length reference per "
        "newton of tension off the target (paid out above it, wound in below it)", gt=0)
    ground_tension_rate_m_s: float = quantity(
        0.05, "m/s", "the pre-tension's loop: its fastest wind-in (it pays out as fast as "
        "the law allows); slow, since a line lying straight on the ground is stiff (EA/L: "
        "55 kN/m at 2 m) and the drum's overshoot when the slack runs out is all stretch",
        gt=0)
    ground_lbar_tension_ratio: float = quantity(
        2.0, "1", "under L-bar's length law a take-off goes on holding the pre-tension while "
        "L-bar at the reported position asks for more than this times its target "
        "horizontal tension (the tension law lays the line down there itself)", gt=1)
    ground_hold_near_m: float = quantity(
        3.0, "m", "a take-off this close to the winder (horizontally, as reported) goes on "
        "holding the pre-tension as L-bar's length law does (ground_lbar_tension_ratio) "
        "under any law: its short line has little to drag over the ground, and without "
        "GNSS the tether fix counts on it lying straight under the pre-tension as it lifts "
        "(docs/control.md §8.5)", ge=0)
    ground_climb_m_s: float = quantity(
        0.3, "m/s", "the UAV counts as on the ground only while it also reports climbing "
        "slower than this (a take-off ends the pre-tension at once; a landing's descent "
        "does not delay it)", gt=0)
    slack_tension_n: float = quantity(
        0.05, "N", "the line counts as slack (nothing pulls it) while the load cell reads "
        "less than this and the guide arm reads no line leaving the exit above the ground "
        "(the load cell's noise: less is nothing it can tell)", ge=0)
    slack_payout_max_m: float = quantity(
        4.0, "m", "RELAXED pays out at most this much line while it stays slack: more "
        "lies on the ground, where no vehicle pulls it (one on the ground after a failure, "
        "its reported position run away); then the drum holds and pays out only as the "
        "line is pulled. A real climb with the line's bottom lying at the exit (near the "
        "vertical, on a line whose ground friction takes the pull) pays out up to 2.6 m "
        "so between two pulls", gt=0)
    motor_torque_constant_nm_a: float = quantity(
        0.1, "N*m/A", "the winder motor's torque constant as its datasheet gives it: the "
        "current's tension T = (I dw/dt + beta w - Kt Iq) / r_w (groundstation/"
        "winch_current.py) is as good as it", gt=0)
    current_filter_s: float = quantity(
        0.05, "s", "time constant of the low-pass on the current's tension (the encoder's "
        "differenced rate in it is noisy)", ge=0)
    load_cell_silence_s: float = quantity(
        0.1, "s", "no Winch_Tension for this long (simulated time: encoder frames): the "
        "load cell is silent and the motor's current gives the tension", gt=0)
    tension_disagree_n: float = quantity(
        5.0, "N", "the load cell and the current's tension further apart than this for "
        "tension_disagree_s: the current gives the tension until they agree again", gt=0)
    tension_disagree_s: float = quantity(
        1.0, "s", "how long (simulated time) they must disagree", gt=0)

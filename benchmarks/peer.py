"""A peer side by side: RotorPy's own quadrotor on a circle against our offline loop.

RotorPy (``pip install rotorpy``, in the ``test`` extra) is a Python multirotor simulator
with aerodynamics: its ``Multirotor`` (the Hummingbird parameters it ships, rotor drag and
the motors' first-order lag on, integrated by scipy's ``solve_ivp``) flown by its
geometric SE(3) controller on its circular trajectory, through its ``Environment`` at its
default rate, with its default IMU and motion-capture models and no wind. Ours flies the
circle scenario with the onboard EKF (GNSS, IMU, baro, magnetometer) and the dynamic
(lumped) tether and its winder, which RotorPy lacks. Both fly the same simulated time in
the same run, interleaved; the figure is our simulated seconds per wall second as a ratio
of RotorPy's (absolute speeds move with the machine, the ratio much less).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

#: RotorPy's own default simulation rate [Hz] (``rotorpy.environments.Environment``).
ROTORPY_RATE_HZ = 100


def rotorpy_available() -> str | None:
    """None if RotorPy imports, else why not."""
    try:
        import rotorpy  # noqa: F401
    except ImportError as exc:
        return f"rotorpy is not installed ({exc.msg}; pip install rotorpy)"
    return None


def rotorpy_circle(duration_s: float) -> tuple[float, float]:
    """RotorPy's quadrotor flying its circle (radius 2 m, 0.2 Hz: 2.5 m/s) for
    ``duration_s`` [s]: (wall time [s], the position RMSE it reached [m])."""
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.environments import Environment
    from rotorpy.trajectories.circular_traj import ThreeDCircularTraj
    from rotorpy.vehicles.hummingbird_params import quad_params
    from rotorpy.vehicles.multirotor import Multirotor
    from rotorpy.world import World

    traj = ThreeDCircularTraj(center=np.zeros(3), radius=np.array([2.0, 2.0, 0.0]),
                              freq=np.array([0.2, 0.2, 0.0]))
    start = traj.update(0.0)
    hover = float(np.sqrt(quad_params["mass"] * 9.81 / (4 * quad_params["k_eta"])))
    x0 = {"x": np.asarray(start["x"], float), "v": np.asarray(start["x_dot"], float),
          "q": np.array([0.0, 0.0, 0.0, 1.0]), "w": np.zeros(3), "wind": np.zeros(3),
          "rotor_speeds": np.full(4, hover)}
    env = Environment(vehicle=Multirotor(quad_params, initial_state=x0),
                      controller=SE3Control(quad_params), trajectory=traj,
                      world=World.empty((-5.0, 5.0, -5.0, 5.0, -5.0, 5.0)),
                      sim_rate=ROTORPY_RATE_HZ)
    t0 = time.perf_counter()
    out = env.run(t_final=duration_s, terminate=False, plot=False, animate_bool=False,
                  verbose=False)
    wall = time.perf_counter() - t0
    err = out["state"]["x"] - out["flat"]["x"]
    return wall, float(np.sqrt(np.mean(np.sum(err * err, axis=1))))


def ours_circle(duration_s: float) -> tuple[float, float]:
    """Our offline loop on the circle with the EKF and the lumped tether for
    ``duration_s`` [s]: (wall time [s], its position RMSE [m])."""
    from tuav_sitl.offline import OfflineRunner
    from tuav_sitl.scenario import load_scenario

    sc = load_scenario("circle-rtk")
    sc = sc.replace(duration_s=duration_s,
                    metrics_after_s=min(5.0, 0.5 * duration_s)).with_tether_model("lumped")
    runner = OfflineRunner(sc)
    t0 = time.perf_counter()
    result = runner.run()
    return time.perf_counter() - t0, float(result.metrics["position_rmse_m"])


def peer_ratio(duration_s: float, repeats: int) -> dict[str, float]:
    """Both simulators ``repeats`` times, interleaved, for ``duration_s`` [s] each: the
    medians of their wall times [s], their RMSEs [m] and our speed as a ratio of
    RotorPy's."""
    ours_circle(min(duration_s, 1.0))          # compiled kernels loaded before timing
    rotorpy_circle(min(duration_s, 1.0))
    ours, peer = [], []
    for _ in range(repeats):
        ours.append(ours_circle(duration_s))
        peer.append(rotorpy_circle(duration_s))
    wall_o = statistics.median(w for w, _ in ours)
    wall_p = statistics.median(w for w, _ in peer)
    return {"ours_wall_s": wall_o, "rotorpy_wall_s": wall_p, "ratio": wall_p / wall_o,
            "ours_rmse_m": ours[-1][1], "rotorpy_rmse_m": peer[-1][1]}

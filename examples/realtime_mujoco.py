"""Close the loop around a MuJoCo arm through `robotadapt.realtime`, the way a robot driver would (docs/realtime.md).

A driver calls one function per control period with the measured state and sends back the torque it returns:
libfranka's Python bindings run a torque callback at 1 kHz, ur_rtde's loop is `initPeriod()`, read the state, send,
`waitPeriod()`. Here MuJoCo stands in for the robot: `robot_state` and `send_torque` are the only lines a real driver
replaces. The loop checks itself against the simulator: the same scenario run by `robotadapt run` gives the same motion
to round-off, since the controller's step is the simulator's tick.

    python examples/realtime_mujoco.py [SCENARIO] [SECONDS]     # default: panda-mujoco, 5 s; plant.engine=mujoco
"""

from __future__ import annotations

import sys
import time

import numpy as np

from robotadapt.realtime import RealtimeController
from robotadapt.sim.simulation import mujoco_sampling
from robotadapt.studies.scenarios import load


def main(scenario: str = "panda-mujoco", seconds: float = 5.0) -> int:
    overrides = [f"simulation.t_final={seconds}", "plant.engine=mujoco"]
    setup = load(scenario, overrides).setup
    robot = setup.plant  # a MujocoPlant: MuJoCo stepping the arm
    sampling = mujoco_sampling(robot, setup.integrator)  # MuJoCo's steps per control period
    ctrl = RealtimeController.from_scenario(scenario, overrides)
    state = np.concatenate([setup.q0, setup.dq0])
    n = robot.model.n

    def robot_state() -> tuple[np.ndarray, np.ndarray]:  # a driver: the measured q, q̇ of this period
        return state[:n], state[n:]

    def send_torque(t: float, tau: np.ndarray) -> np.ndarray:  # a driver: the command; here MuJoCo runs the period
        return robot.advance(t, state, tau, sampling.substeps, sampling.dt)

    ctrl.reset(*robot_state())
    ticks = round(seconds / ctrl.Ts)
    latency, error = np.empty(ticks), np.empty(ticks)
    for k in range(ticks):  # the 1 kHz loop
        q, dq = robot_state()
        start = time.perf_counter_ns()
        tau = ctrl.step(k * ctrl.Ts, q, dq)  # the callback's whole work
        latency[k] = (time.perf_counter_ns() - start) / 1e3
        error[k] = np.abs(ctrl.trajectory(k * ctrl.Ts).q_des - q).max()
        state = send_torque(k * ctrl.Ts, tau)
    print(f"{scenario}: {ticks} periods of {ctrl.Ts * 1e3:g} ms, backend {ctrl.backend}; step latency p50 "
          f"{np.percentile(latency, 50):.0f} µs, p99 {np.percentile(latency, 99):.0f} µs; max |e| over the last second "
          f"{error[-round(1 / ctrl.Ts):].max():.2e} rad")
    simulated = load(scenario, [*overrides, "simulation.log_every=1"]).run()
    gap = np.abs(simulated.q[ticks] - state[:n]).max()
    print(f"the simulator's run of the same scenario ends {gap:.1e} rad away")
    return 0 if gap < 1e-6 else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:2], *(float(a) for a in sys.argv[2:3])))

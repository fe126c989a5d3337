"""Least squares against output-error refinement on noisy simulated logs.

A robot (default ur5) with viscous and Coulomb friction along a random excitation, 1 kHz:
torque noise (1 % and 5 % of each joint's RMS torque) and position / velocity noise; the
accelerations are NOT the simulation's: the log is preprocessed as a real one (3 Hz
zero-phase Butterworth, ddq by central differences). For each noise level: the relative
base-parameter error against the truth and the rollout error (0.25 s) on a new motion of
the least-squares estimate and of its output-error refinement.

Usage::

    .venv/bin/python experiments/rollout_noise.py [--robot ur5] [--duration S]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from manip_id import load_robot
from manip_id.identification import (
    RefineOptions,
    RolloutOptions,
    identify,
    refine,
    rollout_validation,
)
from manip_id.signals import preprocess
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


def noisy_log(robot, theta, seed, duration, tau_noise, q_noise, dq_noise):
    traj = random_trajectory(robot, harmonics=5, seed=seed)
    noise = MeasurementNoise(tau=tau_noise, q=q_noise, dq=dq_noise)
    sim = simulate(robot, traj, duration=duration, rate=1000.0, theta=theta, noise=noise, seed=seed)
    return preprocess(dataclasses.replace(sim.dataset, ddq=None))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="ur5")
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--q-noise", type=float, default=1e-4, help="[rad]")
    parser.add_argument("--dq-noise", type=float, default=1e-3, help="[rad/s]")
    a = parser.parse_args()
    robot = load_robot(a.robot, friction="viscous,coulomb")
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = 0.5
    theta[robot.layout.joint_columns("fc")] = 1.0
    print(f"{a.robot}: position noise {a.q_noise} rad, velocity noise {a.dq_noise} rad/s")
    print(f"{'torque noise':>12} {'estimate':>10} {'param error':>12} {'rollout 0.25 s [rad]':>21}")
    for tau_noise in (0.01, 0.05):
        train = noisy_log(robot, theta, 1, a.duration, tau_noise, a.q_noise, a.dq_noise)
        new = noisy_log(robot, theta, 2, a.duration / 2, tau_noise, a.q_noise, a.dq_noise)
        ls = identify(robot, train.q, train.dq, train.ddq, train.tau)
        truth = ls.base.to_base(theta)
        ref = refine(ls, robot, [train], options=RefineOptions())
        for name, m in (("LS", ls), ("refined", ref)):
            err = np.linalg.norm(m.estimate - truth) / np.linalg.norm(truth)
            rep = rollout_validation(robot, m, [new], options=RolloutOptions(0.25, starts=50))
            e = rep.identified
            roll = float(np.sqrt(np.mean(e.position_rms**2)))
            print(f"{tau_noise:12.2f} {name:>10} {err:12.4f} {roll:14.4g} ({e.diverged} div.)")


if __name__ == "__main__":
    main()

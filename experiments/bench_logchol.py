"""The log-Cholesky consistent solver against the SDP on a simulated 6-joint problem.

    python experiments/bench_logchol.py [--seconds 60] [--blas-threads N] [--seeds 0 1 2]

ur10 with viscous and Coulomb friction; data at 200 Hz along a random 5-harmonic
trajectory, the robot's parameters perturbed by 30 % (the nominal prior is wrong, model
error) and the torques disturbed by correlated noise (white noise of 5 % of each joint's
torque RMS through a first-order low-pass of 2 Hz, so neighbouring samples share it).
For each seed, ``identify(..., consistent=True)`` with the SDP and with the log-Cholesky
solver on the same data: solve time, status, objective and fit; without the geometric
bounds by default (``--bounds geometry``: the log-Cholesky result is checked against
them and re-solved by the SDP when it breaks one). ``--blas-threads N``
runs the whole process under N BLAS threads (threadpoolctl), to see the solver's own
limit of one thread at work.
"""

from __future__ import annotations

import argparse
import contextlib
import time

import numpy as np

from manip_id import load_robot
from manip_id.identification import ConsistentOptions, identify
from manip_id.simulation import perturb_parameters, simulate
from manip_id.trajectories import random_trajectory


def correlated_noise(tau: np.ndarray, rate: float, rel: float, seed: int) -> np.ndarray:
    """White noise of ``rel`` times each joint's RMS through a 2 Hz first-order low-pass,
    scaled back to that RMS, shape of ``tau``."""
    rng = np.random.default_rng(seed)
    white = rng.standard_normal(tau.shape)
    a = np.exp(-2 * np.pi * 2.0 / rate)
    out = np.empty_like(white)
    out[0] = white[0]
    for k in range(1, white.shape[0]):
        out[k] = a * out[k - 1] + (1 - a) * white[k]
    out /= out.std(axis=0)
    return rel * np.sqrt(np.mean(tau**2, axis=0)) * out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--blas-threads", type=int, default=None)
    parser.add_argument("--bounds", default="none", help="geometry or none [default none]")
    args = parser.parse_args()
    limit = contextlib.nullcontext()
    if args.blas_threads is not None:
        from threadpoolctl import threadpool_limits  # optional: only for this switch

        limit = threadpool_limits(limits=args.blas_threads, user_api="blas")
    robot = load_robot("ur10", friction=("viscous", "coulomb"))
    rate = 200.0
    print(f"{'seed':>4s} {'solver':>8s} {'time s':>8s} {'fit':>12s} {'rel err':>8s}  status")
    with limit:
        for seed in args.seeds:
            theta = perturb_parameters(robot, 0.3, seed=seed)
            traj = random_trajectory(robot, harmonics=5, seed=seed)
            sim = simulate(robot, traj, duration=args.seconds, rate=rate, theta=theta, seed=seed)
            d = sim.dataset
            tau = d.tau + correlated_noise(d.tau, rate, 0.05, seed)
            times = {}
            for solver in ("sdp", "logchol"):
                t0 = time.perf_counter()
                res = identify(
                    robot,
                    (d.q, d.dq, d.ddq, tau),
                    consistent=ConsistentOptions(solver=solver, bounds=args.bounds),
                )
                times[solver] = time.perf_counter() - t0
                st = res.standard
                print(
                    f"{seed:4d} {solver:>8s} {st.time:8.3f} {st.fit:12.6g} "
                    f"{res.relative_error.train:8.4f}  {st.status}",
                    flush=True,
                )
            ratio = times["logchol"] / times["sdp"]
            print(f"     logchol / sdp: {ratio:.2f}x (whole identify call)")


if __name__ == "__main__":
    main()

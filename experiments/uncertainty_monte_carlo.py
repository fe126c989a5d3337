"""Do the reported standard deviations hold when the torque noise is correlated?

Run from the repository root::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python experiments/uncertainty_monte_carlo.py [--runs 60]

One ur5 excitation (a random 5-harmonic Fourier trajectory, 16384 samples at
100 Hz), its noise-free torques from the model, and for each correlation time
``T`` [samples] ``--runs`` draws of stationary AR(1) torque noise (``phi =
exp(-1/T)``, 2 % of each joint's torque RMS, joint 3 three times and joint 6 0.3
times that: unequal joints). Each draw is accumulated with per-block sums and
solved by OLS and WLS; printed per method and correlation time: the median over
the base parameters of the empirical std of the estimates over the draws divided
by the mean reported std, for the autocorrelation-consistent covariance
(``hac``, :mod:`manip_id.estimators.uncertainty`) and the white-noise one, with
the 10 % and 90 % quantiles over the parameters, the mean bandwidth [blocks] and
the mean reported inflation. 1.0 is right; the white ratio grows with ``T``.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.signal import lfilter

from manip_id import load_robot, regressor
from manip_id.estimators.batch import solve_accumulator
from manip_id.estimators.uncertainty import UncertaintyOptions, solution_uncertainty
from manip_id.identifiability import analyze
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

N_SAMPLES = 16384
RATE = 100.0  # [Hz]
JOINT_SCALE = np.array([1.0, 1.0, 3.0, 1.0, 1.0, 0.3])


def _excitation():
    robot = load_robot("ur5")
    ind = analyze(robot).base.independent
    traj = random_trajectory(robot, harmonics=5, seed=3)
    d = simulate(robot, traj, duration=(N_SAMPLES - 1) / RATE, rate=RATE).dataset
    return regressor(robot, d.q, d.dq, d.ddq)[:, :, ind], d.tau


def _noise(seed: int, n: int, nv: int, phi: float) -> np.ndarray:
    z = np.random.default_rng(seed).standard_normal((n, nv))
    z[1:] *= np.sqrt(1.0 - phi**2)  # unit stationary variance
    return lfilter([1.0], [1.0, -phi], z, axis=0)


def _row(label: str, spread: np.ndarray, reported: list) -> str:
    ratio = spread / np.mean(reported, axis=0)
    lo, hi = np.quantile(ratio, [0.1, 0.9])
    return f"{label} {np.median(ratio):6.3f} [{lo:5.2f}, {hi:5.2f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=60)
    parser.add_argument("--times", default="1e-3,5,20,50,100,200")
    args = parser.parse_args()
    Y, tau0 = _excitation()
    n, nv, r = Y.shape
    scale = 0.02 * np.sqrt((tau0**2).mean(axis=0)) * JOINT_SCALE  # [N m]
    print(f"ur5, {n} samples, {r} base parameters, {args.runs} noise draws per row")
    print("method  T [samples]   hac ratio [q10, q90]     white ratio [q10, q90]   S    infl.")
    for method in ("ols", "wls"):
        for T in (float(t) for t in args.times.split(",")):
            phi = np.exp(-1.0 / T)
            est, hac, white, bw, infl = [], [], [], [], []
            for run in range(args.runs):
                tau = tau0 + scale * _noise(100 + run, n, nv, phi)
                acc = UncertaintyOptions().accumulator(r, nv)
                acc.add(Y, tau, check=False)
                sol = solve_accumulator(acc, method=method)
                u = solution_uncertainty(acc, sol, "hac")
                est.append(sol.estimate)
                hac.append(u.std)
                white.append(u.std_white)
                bw.append(u.bandwidth)
                infl.append(u.inflation)
            spread = np.std(est, axis=0, ddof=1)
            print(
                f"{method:<6} {T:>9.3g}   {_row('', spread, hac)}   {_row('', spread, white)}"
                f"   {np.mean(bw):4.1f} {np.mean(infl):5.2f}"
            )


if __name__ == "__main__":
    main()

"""The consistent standard parameters' std holds for correlated residuals (Monte Carlo).

One ur5 excitation, 30 draws of AR(1) torque noise of correlation time 20 samples; each
draw is accumulated with its blocks, solved by least squares and by the consistent
solve, whose std come from the base covariance through the solve's sensitivity
(:mod:`manip_id.estimators.consistent.covariance`). The spread of the standard
parameters over the draws against the mean reported std: the honest one within
[0.75, 1.33] (median over the parameters the data move), the white-noise one outside
[0.5, 2]. No plausibility bounds, so no linear constraint is active (the case the
linearisation covers exactly); white noise gives an inflation of about 1.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot

from manip_id import regressor
from manip_id.estimators.batch import solve_accumulator
from manip_id.estimators.consistent import consistent_estimate
from manip_id.estimators.consistent.bounds import BoundsOptions
from manip_id.estimators.uncertainty import UncertaintyOptions, solution_uncertainty
from manip_id.identifiability import analyze
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

N_DRAWS = 30


@pytest.fixture(scope="module")
def ur5_setup():
    robot = get_robot("ur5")
    base = analyze(robot).base
    traj = random_trajectory(robot, harmonics=5, seed=3)
    d = simulate(robot, traj, duration=(8192 - 1) / 100.0, rate=100.0).dataset
    Y = regressor(robot, d.q, d.dq, d.ddq)[:, :, base.independent]
    return robot, base, Y, d.tau


def _ar1(rng, n: int, nv: int, phi: float) -> np.ndarray:
    from scipy.signal import lfilter  # optional heavy import (scipy.signal)

    z = rng.standard_normal((n, nv))
    z[1:] *= np.sqrt(1.0 - phi**2)
    return lfilter([1.0], [1.0, -phi], z, axis=0)


def _draw(setup, seed: int, phi: float):
    robot, base, Y, tau0 = setup
    n, nv, r = Y.shape
    scale = 0.02 * np.sqrt((tau0**2).mean(axis=0))  # [N m]
    tau = tau0 + scale * _ar1(np.random.default_rng(100 + seed), n, nv, phi)
    acc = UncertaintyOptions().accumulator(r, nv).add(Y, tau)
    ls = solve_accumulator(acc)
    u = solution_uncertainty(acc, ls)
    assert u.method == "hac"
    est = consistent_estimate(robot, acc, base, ls, bounds=BoundsOptions(bounds="none"))
    assert est.active == []
    return est.with_covariance(u.covariance, u.covariance_white)


def test_consistent_std_matches_the_spread_under_correlated_noise(ur5_setup):
    draws = [_draw(ur5_setup, k, np.exp(-1.0 / 20.0)) for k in range(N_DRAWS)]
    values = np.array([d.values for d in draws])
    honest = np.mean([d.std for d in draws], axis=0)
    white = np.mean([d.std_white for d in draws], axis=0)
    moved = honest > 1e-6 * np.maximum(np.abs(values.mean(axis=0)), 1e-3)  # data-moved
    assert moved.sum() >= 30
    spread = np.std(values, axis=0, ddof=1)[moved]
    ratio_honest = float(np.median(spread / honest[moved]))
    ratio_white = float(np.median(spread / white[moved]))
    assert 0.75 <= ratio_honest <= 1.33, (ratio_honest, ratio_white)
    assert not 0.5 <= ratio_white <= 2.0, (ratio_honest, ratio_white)
    rows = draws[0].to_dict()["standard_parameters"]
    data = [k for k, row in enumerate(rows) if row.get("source", "data") == "data"]
    assert len(data) >= 30  # the data set them: each carries its std
    assert all(rows[k]["std"] is not None for k in data)
    assert all(row["std"] is None for row in rows if row.get("source", "data") != "data")


def test_white_noise_consistent_std_about_white(ur5_setup):
    est = _draw(ur5_setup, 0, 0.0)
    keep = est.std_white > 0
    assert 0.8 < float(np.median(est.std[keep] / est.std_white[keep])) < 1.25

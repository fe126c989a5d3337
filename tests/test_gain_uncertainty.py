"""Drive gains' std holds for correlated current noise (Monte Carlo against the truth).

Smooth excitation (Fourier trajectories, so neighbouring samples' rows are alike),
currents ``rnea / g`` of the unloaded and loaded models, and AR(1) current noise of
correlation time 1 / (1 - 0.95) = 20 samples. Over 30 noise draws the spread of the
gains is compared with the mean reported std: the honest one within [0.75, 1.33], the
white-noise one far off (outside [0.5, 2]); on white noise the inflation is about 1.
"""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from test_payload import loaded_model, make_payload

from manip_id.identifiability import analyze
from manip_id.payload import identify_drive_gains
from manip_id.trajectories import random_trajectory, trajectory_to_configuration

GAINS = np.array([0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]
N_DRAWS = 30


def _clean(robot, model, seed: int, n: int = 3000, rate: float = 200.0):
    traj = random_trajectory(robot, harmonics=5, seed=seed)
    qj, dq, ddq = traj.sample(np.arange(n) / rate)
    q = trajectory_to_configuration(robot, qj)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(n)])
    return q, dq, ddq, tau / GAINS  # currents [A]


def _ar1(rng, shape, phi: float, sigma) -> np.ndarray:
    white = rng.standard_normal(shape) * sigma
    noise = np.empty_like(white)
    noise[0] = white[0]
    for k in range(1, shape[0]):
        noise[k] = phi * noise[k - 1] + np.sqrt(1 - phi**2) * white[k]
    return noise


@pytest.fixture(scope="module")
def setup():
    robot = get_robot("ur5")
    payload = make_payload(2.0, (0.03, -0.02, 0.1))
    m0, m1 = loaded_model(robot, "tool0", payload)
    return robot, analyze(robot).base, _clean(robot, m0, 1), _clean(robot, m1, 2), payload.mass


def _draws(setup, method: str, phi: float, n_draws: int):
    robot, base, u, ld, mass = setup
    sigma = 0.01 / GAINS  # [A]: 0.01 N m of torque on every joint
    est, std, std_w, infl = [], [], [], []
    for seed in range(n_draws):
        rng = np.random.default_rng(900 + seed)
        uu = (*u[:3], u[3] + _ar1(rng, u[3].shape, phi, sigma))
        ll = (*ld[:3], ld[3] + _ar1(rng, ld[3].shape, phi, sigma))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = identify_drive_gains(robot, uu, ll, "tool0", mass, method=method, base=base)
        est.append(res.gains)
        std.append(res.gains_std)
        std_w.append(res.gains_std_white)
        infl.append(res.uncertainty["inflation"])
        assert res.to_dict()["uncertainty"]["method"] == "hac"
    return np.array(est), np.array(std), np.array(std_w), np.array(infl)


def _pooled_ratio(est, std) -> float:
    """``sqrt(mean_j var_emp_j / mean(std_j)^2)`` over the gains: empirical / reported."""
    return float(np.sqrt(np.mean(np.var(est, axis=0, ddof=1) / np.mean(std, axis=0) ** 2)))


@pytest.mark.parametrize("method", ["ml", "ols", "wls", "tls"])
def test_correlated_current_noise_honest_std(setup, method):
    est, std, std_w, infl = _draws(setup, method, 0.95, N_DRAWS)
    honest, white = _pooled_ratio(est, std), _pooled_ratio(est, std_w)
    assert 0.75 <= honest <= 1.33, (honest, white)
    assert not 0.5 <= white <= 2.0, (honest, white)
    assert np.median(infl) > 2.0
    assert np.all(np.abs(est.mean(axis=0) - GAINS) < 4.0 * std.mean(axis=0) / np.sqrt(N_DRAWS))


def test_white_current_noise_inflation_about_one(setup):
    _, _, _, infl = _draws(setup, "ml", 0.0, 3)
    assert np.all((infl > 0.8) & (infl < 1.3)), infl

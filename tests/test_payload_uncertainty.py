"""The payload's covariance holds for correlated torque noise (the runs' per-block sums).

Smooth excitation (a Fourier trajectory, so neighbouring samples' regressor rows are
alike), torques by Pinocchio's ``rnea`` of the unloaded and loaded models, and AR(1)
noise of correlation time ~50 samples: the white-noise formula is then several times
too small, and the result must say so (``uncertainty.inflation``) and report the larger
std; on white noise it stays at the white one.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from conftest import get_robot
from test_payload import loaded_model, make_payload

from manip_id.identifiability import analyze
from manip_id.identification import identify
from manip_id.payload import identify_payload
from manip_id.trajectories import random_trajectory, trajectory_to_configuration


def _run(robot, model, seed: int, phi: float, n: int = 4000, rate: float = 200.0):
    traj = random_trajectory(robot, harmonics=5, seed=seed)
    t = np.arange(n) / rate
    qj, dq, ddq = traj.sample(t)
    q = trajectory_to_configuration(robot, qj)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(n)])
    rng = np.random.default_rng(100 + seed)
    white = rng.standard_normal(tau.shape) * 0.05  # [N m]
    noise = np.empty_like(white)
    noise[0] = white[0]
    for k in range(1, n):  # AR(1): correlation time 1 / (1 - phi) samples
        noise[k] = phi * noise[k - 1] + np.sqrt(1 - phi**2) * white[k]
    return q, dq, ddq, tau + noise


def _payload(phi: float):
    robot = get_robot("ur5")
    m0, m1 = loaded_model(robot, "tool0", make_payload())
    runs_u = [_run(robot, m0, s, phi) for s in (1, 2)]
    runs_l = [_run(robot, m1, s, phi) for s in (3, 4)]
    return identify_payload(robot, runs_u, runs_l, "tool0", base=analyze(robot).base)


def test_correlated_noise_inflates_the_payload_std():
    res = _payload(phi=0.98)
    unc = res.uncertainty
    assert unc is not None and unc["method"] == "hac", unc
    assert unc["inflation"] > 2.0, unc
    assert res.to_dict()["uncertainty"]["method"] == "hac"


def test_white_noise_keeps_the_white_std():
    res = _payload(phi=0.0)
    unc = res.uncertainty
    assert unc is not None and unc["method"] == "hac"
    assert 0.6 < unc["inflation"] < 1.5, unc


def _clean_run(robot, model, seed: int, n: int = 4000, rate: float = 200.0):
    """Noise-free ``(q, dq, ddq, tau)`` of a Fourier excitation, by ``rnea``."""
    traj = random_trajectory(robot, harmonics=5, seed=seed)
    qj, dq, ddq = traj.sample(np.arange(n) / rate)
    q = trajectory_to_configuration(robot, qj)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(n)])
    return q, dq, ddq, tau


def _ar1(rng, shape, phi: float, sigma: float) -> np.ndarray:
    white = rng.standard_normal(shape) * sigma
    noise = np.empty_like(white)
    noise[0] = white[0]
    for k in range(1, shape[0]):
        noise[k] = phi * noise[k - 1] + np.sqrt(1 - phi**2) * white[k]
    return noise


def test_known_base_payload_std_matches_the_spread_under_correlated_noise():
    """--known-base: the base comes exactly from noise-free unloaded data (its own
    covariance vanishes), 30 draws of AR(1) torque noise (correlation time 20 samples) on
    two loaded runs. The derived sums' std come from the loaded runs' blocks: the spread
    of the payload's parameters against the mean reported std within [0.75, 1.33]
    (median), and the white std is more than 2 times smaller (inflation)."""
    robot = get_robot("ur5")
    base = analyze(robot).base
    m0, m1 = loaded_model(robot, "tool0", make_payload())
    known = identify(robot, tuple(_clean_run(robot, m0, 1)), base=base)
    clean = [_clean_run(robot, m1, s, n=3000) for s in (3, 4)]
    values, std, infl = [], [], []
    for draw in range(30):
        rng = np.random.default_rng(300 + draw)
        runs = [(*c[:3], c[3] + _ar1(rng, c[3].shape, 0.95, 0.05)) for c in clean]
        res = identify_payload(robot, None, runs, "tool0", known_base=known, base=base)
        assert res.uncertainty["method"] == "hac", res.uncertainty
        values.append(res.payload.values)
        std.append(res.payload.std)
        infl.append(res.uncertainty["inflation"])
    values, std = np.array(values), np.array(std)
    keep = np.isfinite(std).all(axis=0) & (std.mean(axis=0) > 0)
    assert keep.sum() >= 5
    ratio = float(np.median(np.std(values, axis=0, ddof=1)[keep] / std.mean(axis=0)[keep]))
    assert 0.75 <= ratio <= 1.33, ratio
    assert np.median(infl) > 2.0, infl

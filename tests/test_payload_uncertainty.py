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

"""Numbers a user can act on: defaults that do not hurt (WLS), a warning when a joint is
worse than the nominal model, values that say where they come from, an honest auditor."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot

from manip_id.identification import identify, result_text, result_to_dict, verdict_text
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


def _demo_like(robot, seed: int):
    """A demo-like record (20 s at 200 Hz, torque noise 1 % of each joint's RMS)."""
    traj = random_trajectory(robot, seed=seed, harmonics=5)
    return simulate(
        robot, traj, duration=20.0, rate=200.0, noise=MeasurementNoise(tau=0.01), seed=seed
    )


@pytest.fixture(scope="module")
def panda_demo():
    robot = get_robot("panda")
    return robot, _demo_like(robot, 1), _demo_like(robot, 2)


def _arrays(sim):
    d = sim.dataset
    return d.q, d.dq, d.ddq, d.tau


def test_default_method_keeps_every_joint_at_the_noise_floor(panda_demo):
    """The noise floor of joint j, ``||tau_j - tau_true_j|| / ||tau_j||`` on the validation
    record, comes from the simulation's truth; the default fit reaches it on every joint
    (within 1.2x), while plain OLS leaves the 0.3 N m wrist far above and says so."""
    robot, train, val = panda_demo
    tau, truth = val.dataset.tau, val.tau_true
    floor = np.linalg.norm(tau - truth, axis=0) / np.linalg.norm(tau, axis=0)
    res = identify(robot, *_arrays(train), validation=_arrays(val))
    assert res.method == "wls"
    ratio = np.asarray(res.relative_error.validation_per_joint) / floor
    assert np.all(ratio < 1.2), ratio
    doc = result_to_dict(res)
    assert not [w for w in doc["warnings"] if w.startswith("worse than the nominal")]

    ols = identify(robot, *_arrays(train), validation=_arrays(val), method="ols")
    worse = np.asarray(ols.relative_error.validation_per_joint) / floor
    bad = [robot.dof_names[j] for j in np.flatnonzero(worse > 1.5)]
    assert bad, worse  # this record's OLS makes a joint worse (the wrist)
    doc = result_to_dict(ols)
    (warning,) = [w for w in doc["warnings"] if w.startswith("worse than the nominal")]
    assert all(name in warning for name in bad) and "Do: refit with --method wls" in warning
    assert "WORSE than the nominal model" in verdict_text(doc)
    assert warning in result_text(doc)

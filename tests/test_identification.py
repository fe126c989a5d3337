"""Identification of manipulators on simulated data (torques from pinocchio.rnea)."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.datasets import Dataset
from manip_id.errors import InputError, RankDeficiencyError
from manip_id.estimators import InformationAccumulator, solve_accumulator
from manip_id.identifiability import analyze
from manip_id.identification import (
    RunOptions,
    identify,
)
from manip_id.robot.regressor import iter_regressor
from manip_id.trajectories import FourierTrajectory


def _true_theta(robot, seed=0):
    """Nominal inertias with random positive armature and viscous friction."""
    rng = np.random.default_rng(seed)
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = rng.uniform(0.05, 0.5, robot.n_parameters - robot.n_rigid)
    return theta


def _torques(robot, theta, q, dq, ddq):
    """Inverse dynamics by pinocchio.rnea (inertias and armature) plus fv dq, term by term."""
    model = robot.with_parameters(theta)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])])
    if robot.terms.viscous:
        names = robot.parameter_names
        fv = np.array([theta[names.index(f"{d}.fv")] for d in robot.dof_names])
        tau += fv * dq
    return tau


def _robot(name):
    return get_robot(name, armature=True, friction="viscous")


@pytest.fixture(scope="module", params=["panda", "ur5"])
def noise_free(request):
    robot = _robot(request.param)
    theta = _true_theta(robot)
    q, dq, ddq = robot.random_states(600, seed=1)
    vq, vdq, vddq = robot.random_states(200, seed=2)
    data = (q, dq, ddq, _torques(robot, theta, q, dq, ddq))
    val = (vq, vdq, vddq, _torques(robot, theta, vq, vdq, vddq))
    return robot, theta, data, val


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_noise_free_recovery(noise_free, method):
    robot, theta, data, val = noise_free
    res = identify(robot, tuple(data), method=method, validation=val, run=RunOptions(chunk=256))
    expected = res.base.to_base(theta)
    assert np.linalg.norm(res.estimate - expected) <= 1e-8 * np.linalg.norm(expected)
    vq, vdq, vddq, vtau = val
    pred = res.predict(robot, vq, vdq, vddq)
    assert np.linalg.norm(pred - vtau) <= 1e-8 * np.linalg.norm(vtau)
    assert res.relative_error.validation <= 1e-8
    assert res.relative_error.train <= 1e-6  # from the sums: floor ~ sqrt(eps)
    assert res.n_samples == 600 and res.rank_analysis.rank == res.base.n_base
    assert set(res.timings) >= {"regressor", "accumulate", "rank_analysis", "solve", "validation"}


def test_result_is_reported(noise_free):
    robot, _, data, val = noise_free
    res = identify(robot, tuple(data), validation=val)
    d = json.loads(json.dumps(res.to_dict()))
    assert d["n_base"] == res.base.n_base == len(d["base_parameters"])
    assert d["base_parameters"][0]["expression"] == res.expressions[0]
    assert len(d["relative_error"]["per_joint_validation"]) == robot.nv == len(d["joints"])
    text = res.table(max_rows=3)
    assert res.names[0] in text and f"... {res.base.n_base - 3} more" in text


@pytest.mark.parametrize("name", ["double_pendulum"])
def test_monte_carlo_predicted_std_matches_empirical(name):
    """Torque noise: the predicted std sigma^2 (Y^T Y)^-1 matches the spread over 200 runs."""
    robot = _robot(name)
    theta = _true_theta(robot)
    q, dq, ddq = robot.random_states(300, seed=3)
    tau0 = _torques(robot, theta, q, dq, ddq)
    base = analyze(robot).base
    Yb = np.concatenate([c.Y[:, :, base.independent] for c in iter_regressor(robot, q, dq, ddq)])
    rng = np.random.default_rng(4)
    # OLS assumes one noise level for all joints; WLS estimates one per joint
    levels = {"ols": np.full(robot.nv, 0.5), "wls": np.linspace(0.2, 1.0, robot.nv)}  # N m
    for method, sig in levels.items():
        est, std = [], []
        for _ in range(200):
            noise = sig * rng.standard_normal(tau0.shape)
            acc = InformationAccumulator(base.n_base, robot.nv).add(Yb, tau0 + noise)
            sol = solve_accumulator(acc, method=method)
            est.append(sol.estimate)
            std.append(sol.std)
        ratio = np.mean(std, axis=0) / np.std(est, axis=0, ddof=1)
        assert np.all(np.abs(ratio - 1) < 0.2), (method, ratio.min(), ratio.max())
        bias = np.mean(est, axis=0) - base.to_base(theta)
        assert np.all(np.abs(bias) < 5 * np.std(est, axis=0) / np.sqrt(200))
    # identify() (WLS by default) on one noisy run gives the same numbers as the accumulator path
    tau = tau0 + 0.5 * rng.standard_normal(tau0.shape)
    res = identify(robot, (q, dq, ddq, tau), base=base)
    sol = solve_accumulator(
        InformationAccumulator(base.n_base, robot.nv).add(Yb, tau), method="wls"
    )
    np.testing.assert_allclose(res.estimate, sol.estimate, rtol=1e-10)
    np.testing.assert_allclose(res.std, sol.std, rtol=1e-8)


@pytest.fixture(scope="module")
def panda_fourier():
    robot = get_robot("panda")
    rng = np.random.default_rng(7)
    L = 5
    traj = FourierTrajectory(
        robot.neutral(), rng.normal(0, 0.25, (7, L)), rng.normal(0, 0.25, (7, L)), wf=2 * np.pi / 10
    )
    t = np.arange(0.0, 20.0, 0.01)
    q, dq, ddq = traj.sample(t)
    theta = robot.nominal_parameters
    return robot, theta, (q, dq, ddq, _torques(robot, theta, q, dq, ddq))


def test_rls_converges_to_the_batch_estimate(panda_fourier):
    robot, theta, data = panda_fourier
    batch = identify(robot, tuple(data))
    rls = identify(
        robot, tuple(data), method="rls", online={"P0": 10000.0, "record_every": 100, "dt": 0.01}
    )
    scale = np.linalg.norm(batch.estimate)
    assert np.linalg.norm(rls.estimate - batch.estimate) <= 1e-4 * scale
    assert rls.relative_error.train <= 1e-4
    h = rls.history
    err = np.linalg.norm(h.theta - batch.estimate, axis=1)
    assert err[-1] < 1e-3 * err[0]
    assert h.t[-1] == pytest.approx(20.0)
    assert "RLS" in rls.solver


def test_gradient_law_reduces_the_error(panda_fourier):
    robot, _, data = panda_fourier
    batch = identify(robot, tuple(data))
    grad = identify(robot, tuple(data), method="gradient", online={"record_every": 500})
    h = grad.history
    err = np.linalg.norm(h.theta - batch.estimate, axis=1)
    assert np.all(np.diff(err) < 0)  # slow (condition number ~200) but steady
    assert grad.relative_error.train < 0.9
    assert "normalized gradient law" in grad.solver


def test_rank_deficient_data_name_the_unexcited_directions():
    robot = get_robot("panda")
    q, _, _ = robot.random_states(200, seed=5)
    dq, ddq = np.zeros((200, 7)), np.zeros((200, 7))  # static: only gravity is excited
    tau = _torques(robot, robot.nominal_parameters, q, dq, ddq)
    with pytest.raises(RankDeficiencyError) as info:
        identify(robot, (q, dq, ddq, tau))
    err = info.value
    assert err.rank < err.n_columns and len(err.directions) == err.n_columns - err.rank
    assert "unexcited" in str(err) and err.directions[0].split()[0] in str(err)
    res = identify(robot, (q, dq, ddq, tau), minimum_norm=True)
    assert "minimum-norm" in res.solver
    assert res.relative_error.train < 1e-6  # gravity torques are still fitted
    pred = res.predict(
        robot, *robot.random_states(1, seed=9)[0:1], np.zeros((1, 7)), np.zeros((1, 7))
    )
    assert pred.shape == (1, 7)


def test_identify_dataset(noise_free):
    robot, theta, (q, dq, ddq, tau), _ = noise_free
    t = 0.01 * np.arange(q.shape[0])
    ds = Dataset(t, q, dq, tau, ddq=ddq)
    res = identify(robot, ds, validation=ds)
    assert res.relative_error.validation < 1e-8
    with pytest.raises(InputError, match="no accelerations"):
        identify(robot, Dataset(t, q, dq, tau))


def test_bad_input():
    robot = _robot("ur5")
    q, dq, ddq = robot.random_states(50, seed=0)
    tau = np.ones((50, 6))
    with pytest.raises(InputError, match=r"tau.shape=\(49, 6\) but expected \(50, robot.nv=6\)"):
        identify(robot, (q, dq, ddq, tau[:49]))
    with pytest.raises(InputError, match=r"dq.shape=\(50, 5\) but robot.nv=6"):
        identify(robot, (q, dq[:, :5], ddq, tau))
    bad = tau.copy()
    bad[17, 2] = np.nan
    with pytest.raises(InputError, match="tau holds nan at sample 17, elbow_joint"):
        identify(robot, (q, dq, ddq, bad))
    bad_q = q.copy()
    bad_q[33, 0] = np.inf
    with pytest.raises(InputError, match="q holds inf at sample 33"):
        identify(robot, (bad_q, dq, ddq, tau))
    with pytest.raises(InputError, match="method must be one of"):
        identify(robot, (q, dq, ddq, tau), method="lasso")
    with pytest.raises(InputError, match="validation"):
        identify(robot, (q, dq, ddq, tau), validation=(q, dq))


def test_progress_and_chunks_do_not_change_the_result(noise_free):
    robot, _, data, _ = noise_free
    calls = []
    a = identify(
        robot,
        tuple(data),
        run=RunOptions(chunk=64, progress=lambda done, total: calls.append((done, total))),
    )
    b = identify(robot, tuple(data), base=a.base, run=RunOptions(chunk=1000))
    assert calls[0] == (64, 600) and calls[-1] == (600, 600) and len(calls) == 10
    np.testing.assert_allclose(
        a.estimate, b.estimate, rtol=0, atol=1e-12 * np.abs(b.estimate).max()
    )

"""Physically consistent identification: the eigenvalue test, both solvers, priors, bad input.

References independent of the code under test: Pinocchio's pseudo-inertia and
log-Cholesky maps, the pseudo-inertia written out here from its definition,
noise-free data made with the regressor (exact recovery), and the residual of
plain least squares.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id import ManipIdError, identify, regressor
from manip_id.consistency import (
    PhysicalConsistencyError,
    check_consistency,
    parameters_from_pseudo_inertia,
    pseudo_inertia,
)
from manip_id.errors import InputError
from manip_id.estimators import InformationAccumulator, solve_accumulator
from manip_id.estimators.consistent import (
    SolverError,
    build_problem,
    log_cholesky,
    solve_consistent,
)
from manip_id.identifiability import analyze

FRICTION = "viscous,coulomb"


def _J(block: np.ndarray) -> np.ndarray:
    """The pseudo-inertia from its definition, written here independently of the package."""
    m, h = block[0], block[1:4]
    ixx, ixy, iyy, ixz, iyz, izz = block[4:]
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J[:3, 3] = J[3, :3] = h
    J[3, 3] = m
    return J


def _assert_physical(robot, theta, rel: float = 1e-10) -> None:
    """Every body's J positive definite, and every Ia, fv, fc >= 0 (the test's own check)."""
    for k, name in enumerate(robot.joint_names):
        lam = np.linalg.eigvalsh(_J(theta[10 * k : 10 * k + 10]))
        assert lam[0] > rel * lam[-1], f"{name}: J eigenvalues {lam}"
    for name, value in zip(robot.parameter_names, theta, strict=True):
        if name.rsplit(".", 1)[1] in ("Ia", "fv", "fc"):
            assert value >= 0.0, f"{name} = {value}"


def _truth(robot) -> np.ndarray:
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = 0.2
    return theta


def _data(robot, theta, n: int, noise: float, seed: int):
    q, dq, ddq = robot.random_states(n, seed=seed)
    tau = regressor(robot, q, dq, ddq) @ theta
    rng = np.random.default_rng(seed + 100)
    tau = tau + noise * tau.std(axis=0) * rng.standard_normal(tau.shape)
    return q, dq, ddq, tau


# ---------------------------------------------------------------- the check
def test_pseudo_inertia_matches_pinocchio_and_the_definition():
    rng = np.random.default_rng(0)
    for _ in range(20):
        pi = pin.Inertia.Random().toDynamicParameters()
        ref = pin.PseudoInertia.FromDynamicParameters(pi).toMatrix()
        np.testing.assert_allclose(pseudo_inertia(pi), ref, atol=1e-13)
        np.testing.assert_allclose(pseudo_inertia(pi), _J(pi), atol=1e-13)
        np.testing.assert_allclose(parameters_from_pseudo_inertia(ref), pi, atol=1e-13)
        eta = rng.standard_normal(10)
        J = pin.LogCholeskyParameters(eta).toPseudoInertia().toMatrix()
        np.testing.assert_allclose(log_cholesky(J), eta, atol=1e-10)


def test_check_consistency_names_bodies_and_joints():
    robot = get_robot("panda", friction=FRICTION)
    theta = _truth(robot)
    assert check_consistency(robot, theta).consistent
    bad = theta.copy()
    bad[robot.parameter_index("panda_joint2.m")] = -0.5  # negative mass
    k = 10 * robot.joint_names.index("panda_joint5")
    m = bad[k]
    bad[k + 1 : k + 4] = 0.0  # CoM at the origin, principal moments (1, 1, 3): triangle broken
    bad[k + 4 : k + 10] = [1.0, 0.0, 1.0, 0.0, 0.0, 3.0]
    bad[robot.parameter_index("panda_joint6.fv")] = -0.05
    rep = check_consistency(robot, bad)
    assert not rep.consistent
    text = "\n".join(rep.messages())
    assert "panda_joint2: mass m > 0" in text
    assert "panda_joint5: triangle inequality" in text
    assert "panda_joint6.fv: >= 0" in text
    assert "panda_joint1" not in text
    assert m > 0
    lam = [np.linalg.eigvalsh(_J(bad[10 * i : 10 * i + 10]))[0] for i in range(robot.n_bodies)]
    np.testing.assert_allclose(rep.min_eigenvalues, lam, rtol=1e-12, atol=1e-15)


# ---------------------------------------------------------------- recovery
@pytest.mark.parametrize("solver", ["sdp", "logchol"])
@pytest.mark.parametrize("friction, armature", [(FRICTION, None), ("viscous,coulomb,offset", True)])
def test_noise_free_data_recover_the_base_parameters_exactly(solver, friction, armature):
    robot = get_robot("panda", friction=friction, armature=armature)
    truth = _truth(robot)
    q, dq, ddq, tau = _data(robot, truth, 1500, 0.0, seed=1)
    res = identify(robot, q, dq, ddq, tau, consistent=True, solver=solver)
    beta_true = res.base.to_base(truth)
    err = np.linalg.norm(res.estimate - beta_true) / np.linalg.norm(beta_true)
    assert err < 1e-8
    assert res.physically_consistent
    theta = np.array([p["value"] for p in res.standard_parameters])
    _assert_physical(robot, theta)
    np.testing.assert_allclose(res.base.to_base(theta), res.estimate, rtol=0, atol=1e-12)
    assert [p["name"] for p in res.standard_parameters] == robot.parameter_names
    assert res.standard.solver == solver and res.standard.time > 0
    assert res.relative_error.train < 1e-6


def _light_wrist(robot):
    """The panda with a wrist 50 times lighter: heavy noise makes plain LS non-physical there."""
    theta = _truth(robot)
    for j in ("panda_joint6", "panda_joint7"):
        k = 10 * robot.joint_names.index(j)
        theta[k : k + 10] *= 0.02
    return theta


def test_light_wrist_under_heavy_noise_ols_is_not_physical_consistent_is():
    robot = get_robot("panda", friction=FRICTION)
    truth = _light_wrist(robot)
    _assert_physical(robot, truth)
    q, dq, ddq, tau = _data(robot, truth, 400, 0.3, seed=7)
    ols = identify(robot, q, dq, ddq, tau)
    # plain least squares: its standard vector breaks a condition, and it says so
    assert not ols.physically_consistent
    assert ols.warnings and "not physical" in ols.warnings[0]
    cons = identify(robot, q, dq, ddq, tau, consistent=True)
    theta = cons.standard.values
    _assert_physical(robot, theta)
    assert cons.physically_consistent and not cons.warnings
    # the residual of the consistent fit is within 5 % of the (unconstrained) OLS minimum
    ratio = cons.relative_error.train / ols.relative_error.train
    assert 1.0 <= ratio < 1.05


def test_real_panda_log_consistent_and_validation_close_to_ols(panda_log):
    from manip_id.datasets import load_dataset
    from manip_id.signals import preprocess

    robot = get_robot("panda", friction="viscous,coulomb,offset")
    data = load_dataset(panda_log)
    train, valid = data.split(0.7)
    train, valid = preprocess(train), preprocess(valid)
    v = (valid.q, valid.dq, valid.ddq, valid.tau)
    ols = identify(robot, train.q, train.dq, train.ddq, train.tau, validation=v)
    assert not ols.physically_consistent  # the real log: plain LS is not physical
    cons = identify(robot, train.q, train.dq, train.ddq, train.tau, validation=v, consistent=True)
    _assert_physical(robot, cons.standard.values)
    assert cons.physically_consistent
    assert cons.relative_error.validation <= 1.15 * ols.relative_error.validation
    assert cons.relative_error.validation <= 0.010


def _problem(robot, noise: float, seed: int, **kw):
    base = analyze(robot).base
    q, dq, ddq, tau = _data(robot, _truth(robot), 1500, noise, seed)
    acc = InformationAccumulator(base.n_base, robot.nv).add(
        regressor(robot, q, dq, ddq), tau, columns=base.independent
    )
    ls = solve_accumulator(acc)
    pr = build_problem(
        robot, base, acc.A, acc.b, variance=ls.sigma2, zz=acc.zz, n_rows=acc.n_rows, **kw
    )
    return pr, ls


def test_sdp_and_logchol_agree():
    robot = get_robot("panda", friction=FRICTION)
    pr, _ = _problem(robot, 0.02, seed=3)
    a = solve_consistent(robot, pr, solver="sdp")
    b = solve_consistent(robot, pr, solver="logchol")
    assert a.physically_consistent and b.physically_consistent
    assert abs(a.objective - b.objective) <= 1e-6 * abs(a.objective)
    np.testing.assert_allclose(b.beta, a.beta, rtol=0, atol=1e-7 * np.abs(a.beta).max())
    assert np.linalg.norm(b.theta - a.theta) <= 1e-3 * np.linalg.norm(a.theta)


def test_default_prior_weight_moves_a_physical_fit_by_less_than_its_std():
    robot = get_robot("panda", friction=FRICTION)
    q, dq, ddq, tau = _data(robot, _truth(robot), 1500, 0.01, seed=4)
    res = identify(robot, q, dq, ddq, tau, consistent=True)
    assert res.standard.base_shift_std < 1.0


def test_prior_none_is_feasibility_alone():
    robot = get_robot("panda", friction=FRICTION)
    pr, _ = _problem(robot, 0.3, seed=7, prior="none")
    assert pr.J0 is None and pr.weight == 0
    sol = solve_consistent(robot, pr, solver="sdp")
    _assert_physical(robot, sol.theta)


# ---------------------------------------------------------------- bad input
def test_unknown_solver_or_prior_and_bad_weight():
    robot = get_robot("ur5", friction=FRICTION)
    q, dq, ddq, tau = _data(robot, _truth(robot), 200, 0.0, seed=0)
    with pytest.raises(InputError, match="solver must be one of"):
        identify(robot, q, dq, ddq, tau, consistent=True, solver="mosek")
    with pytest.raises(InputError, match="prior must be one of"):
        identify(robot, q, dq, ddq, tau, consistent=True, prior="uniform")
    with pytest.raises(InputError, match="prior_weight"):
        identify(robot, q, dq, ddq, tau, consistent=True, prior_weight=-1.0)
    with pytest.raises(InputError, match="applies to ols and wls"):
        identify(robot, q, dq, ddq, tau, consistent=True, method="rls")


def test_non_physical_prior_names_the_body():
    robot = get_robot("panda", friction=FRICTION)
    base = analyze(robot).base
    prior = _truth(robot)
    prior[robot.parameter_index("panda_joint3.m")] = -1.0
    A, b = np.eye(base.n_base), np.zeros(base.n_base)
    with pytest.raises(PhysicalConsistencyError, match="panda_joint3") as info:
        build_problem(robot, base, A, b, variance=1.0, prior_parameters=prior)
    assert isinstance(info.value, ManipIdError)
    assert any(v.name == "panda_joint3" for v in info.value.violations)


def test_solver_failure_is_a_manip_id_error_with_the_status():
    robot = get_robot("panda", friction=FRICTION)
    pr, _ = _problem(robot, 0.02, seed=3)
    with pytest.raises(SolverError, match="status") as info:
        solve_consistent(robot, pr, solver="sdp", max_iter=1)
    assert isinstance(info.value, ManipIdError)
    assert info.value.solver == "sdp" and info.value.status

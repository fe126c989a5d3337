"""Batch least squares: accumulators, stacked and streamed solves, WLS, uncertainty, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.errors import InputError, RankDeficiencyError
from manip_id.estimators import (
    InformationAccumulator,
    format_direction,
    solve_accumulator,
    solve_normal_equations,
    solve_stacked,
)
from manip_id.identifiability import analyze


def _problem(n=400, nv=3, p=6, noise=0.0, seed=0, scales=None):
    rng = np.random.default_rng(seed)
    Y = rng.standard_normal((n, nv, p))
    if scales is not None:
        Y *= scales
    theta = rng.uniform(-2, 2, p)
    tau = Y @ theta + noise * rng.standard_normal((n, nv))
    return Y, tau, theta


def test_accumulator_matches_direct_sums():
    Y, tau, _ = _problem()
    acc = InformationAccumulator(6, 3)
    for s in range(0, 400, 64):
        acc.add(Y[s : s + 64], tau[s : s + 64])
    Phi = Y.reshape(-1, 6)
    np.testing.assert_allclose(acc.A, Phi.T @ Phi, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(acc.b, Phi.T @ tau.reshape(-1), rtol=1e-12, atol=1e-10)
    assert acc.zz == pytest.approx(float(tau.reshape(-1) @ tau.reshape(-1)), rel=1e-13)
    for j in range(3):
        np.testing.assert_allclose(acc.A_joint[j], Y[:, j].T @ Y[:, j], rtol=1e-12, atol=1e-10)
    assert acc.n == 400 and acc.n_rows == 1200


def test_merge_and_add_equal_concatenated_data():
    Y, tau, _ = _problem()
    whole = InformationAccumulator(6, 3).add(Y, tau)
    a = InformationAccumulator(6, 3).add(Y[:150], tau[:150])
    b = InformationAccumulator(6, 3).add(Y[150:], tau[150:])
    c = a + b
    assert a.n == 150  # + leaves its operands alone
    for acc in (c, a.copy().merge(b)):
        np.testing.assert_allclose(acc.A_joint, whole.A_joint, rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(acc.b_joint, whole.b_joint, rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(acc.zz_joint, whole.zz_joint, rtol=1e-12)
        assert acc.n == whole.n


def test_columns_option_accumulates_a_subset():
    Y, tau, _ = _problem(p=8)
    cols = np.array([0, 2, 3, 7])
    acc = InformationAccumulator(4, 3).add(Y, tau, columns=cols)
    ref = InformationAccumulator(4, 3).add(np.ascontiguousarray(Y[:, :, cols]), tau)
    np.testing.assert_allclose(acc.A, ref.A, rtol=1e-13)


def test_residual_from_sums_matches_direct_residual():
    Y, tau, theta = _problem(noise=0.3)
    acc = InformationAccumulator(6, 3).add(Y, tau)
    other = theta + 0.1
    direct = ((tau - Y @ other) ** 2).sum(axis=0)
    np.testing.assert_allclose(acc.residual_sum_of_squares(other), direct, rtol=1e-9)


@pytest.mark.parametrize("noise", [0.0, 0.05])
def test_streamed_and_stacked_agree(noise):
    Y, tau, theta = _problem(noise=noise, scales=np.array([1, 10, 100, 0.1, 1e-2, 3.0]))
    acc = InformationAccumulator(6, 3).add(Y, tau)
    streamed = solve_accumulator(acc)
    stacked = solve_stacked(Y.reshape(-1, 6), tau.reshape(-1), nv=3)
    ref = np.linalg.lstsq(Y.reshape(-1, 6), tau.reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(streamed.estimate, stacked.estimate, rtol=1e-9)
    np.testing.assert_allclose(stacked.estimate, ref, rtol=1e-10)
    if noise > 0:
        np.testing.assert_allclose(streamed.covariance, stacked.covariance, rtol=1e-6)
    else:
        np.testing.assert_allclose(stacked.estimate, theta, rtol=1e-12)
    assert streamed.rank == stacked.rank == 6
    assert "Cholesky" in streamed.solver and "QR" in stacked.solver


def test_uncertainty_formulas():
    Y, tau, _ = _problem(noise=0.2)
    Phi, z = Y.reshape(-1, 6), tau.reshape(-1)
    sol = solve_stacked(Phi, z, nv=3)
    res = z - Phi @ sol.estimate
    sigma2 = res @ res / (Phi.shape[0] - 6)
    assert sol.sigma2 == pytest.approx(sigma2, rel=1e-12)
    np.testing.assert_allclose(sol.covariance, sigma2 * np.linalg.inv(Phi.T @ Phi), rtol=1e-9)
    np.testing.assert_allclose(sol.std_percent, 100 * sol.std / np.abs(sol.estimate))
    assert sol.relative_error == pytest.approx(np.linalg.norm(res) / np.linalg.norm(z), rel=1e-12)
    per = np.linalg.norm(res.reshape(-1, 3), axis=0) / np.linalg.norm(tau, axis=0)
    np.testing.assert_allclose(sol.relative_error_per_joint, per, rtol=1e-12)


def test_wls_weights_joints_by_their_noise_and_matches_stacked_weighted():
    rng = np.random.default_rng(3)
    Y, tau0, theta = _problem(n=3000, seed=3)
    sig = np.array([0.01, 0.3, 3.0])
    tau = tau0 + sig * rng.standard_normal(tau0.shape)
    acc = InformationAccumulator(6, 3).add(Y, tau)
    ols = solve_accumulator(acc)
    wls = solve_accumulator(acc, method="wls")
    np.testing.assert_allclose(np.sqrt(wls.noise_variance), sig, rtol=0.1)
    assert np.sqrt(ols.noise_variance[0]) > 2 * sig[0]  # OLS residuals mix the joints' noise
    # same weights in a stacked weighted solve give the same estimate and covariance
    ref = solve_stacked(Y.reshape(-1, 6), tau.reshape(-1), nv=3, weights=wls.weights)
    np.testing.assert_allclose(wls.estimate, ref.estimate, rtol=1e-8)
    np.testing.assert_allclose(wls.covariance, ref.covariance, rtol=1e-6)
    assert wls.sigma2 == pytest.approx(1.0, abs=0.1)
    # weighting the quiet joint up shrinks the uncertainty
    assert np.all(wls.std < ols.std)
    assert np.all(np.abs(wls.estimate - theta) < 5 * wls.std)


def test_ill_conditioned_falls_back_and_says_so():
    rng = np.random.default_rng(4)
    Phi = rng.standard_normal((500, 4))
    Phi[:, 3] = Phi[:, 2] + 1e-8 * rng.standard_normal(500)  # scaled condition ~1e8
    theta = np.array([1.0, -2.0, 0.5, 0.25])
    z = Phi @ theta
    acc = InformationAccumulator(4, 1).add(Phi, z)
    sol = solve_accumulator(acc, rank_rtol=1e-12)
    assert sol.solver.startswith("eigen solve (scaled condition")
    stacked = solve_stacked(Phi, z)
    assert stacked.solver.startswith("SVD solve (scaled condition")
    np.testing.assert_allclose(stacked.estimate, theta, rtol=1e-6)


def test_rank_deficiency_names_the_direction():
    rng = np.random.default_rng(5)
    Phi = rng.standard_normal((300, 3))
    Phi[:, 2] = 2.0 * Phi[:, 0]  # only a + 2 c is excited
    z = Phi @ np.array([1.0, 2.0, 3.0])
    names = ["a", "b", "c"]
    for solve in (
        lambda **kw: solve_accumulator(InformationAccumulator(3, 1).add(Phi, z), **kw),
        lambda **kw: solve_stacked(Phi, z, **kw),
    ):
        with pytest.raises(RankDeficiencyError) as info:
            solve(names=names)
        assert info.value.rank == 2 and info.value.n_columns == 3
        # the same text as the rank analysis gives for this direction (one formatter)
        assert info.value.directions == analyze(Phi, names=names).unidentifiable == ["c - 2*a"]
        assert "c - 2*a" in str(info.value)
        sol = solve(names=names, minimum_norm=True)
        np.testing.assert_allclose(sol.estimate, np.linalg.pinv(Phi) @ z, rtol=1e-8)
        assert "minimum-norm" in sol.solver


def test_format_direction():
    assert format_direction(np.array([0.5, -1.0, 0.0]), ["x", "y", "z"]) == "y - 0.5*x"


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda acc: acc.add(np.zeros((5, 2, 4)), np.zeros((5, 2))), "Y.shape=(5, 2, 4)"),
        (lambda acc: acc.add(np.zeros((5, 2, 3)), np.zeros((4, 2))), "tau.shape=(4, 2)"),
        (lambda acc: acc.add(np.zeros((5, 2, 3)), np.zeros((5, 2)), columns=[0, 1]), "columns"),
        (lambda acc: acc.merge(InformationAccumulator(4, 2)), "p=4"),
    ],
)
def test_accumulator_shape_errors(call, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        call(InformationAccumulator(3, 2))


def test_nan_reports_the_sample_index():
    acc = InformationAccumulator(3, 2)
    acc.add(np.ones((10, 2, 3)), np.ones((10, 2)))
    Y = np.ones((10, 2, 3))
    Y[7, 1, 2] = np.nan
    with pytest.raises(InputError, match="sample 17, joint 1, column 2"):
        acc.add(Y, np.ones((10, 2)))
    tau = np.ones((10, 2))
    tau[3, 0] = np.inf
    with pytest.raises(InputError, match="tau holds inf at sample 13, joint 0"):
        acc.add(np.ones((10, 2, 3)), tau)
    with pytest.raises(InputError, match="sample 6"):
        solve_stacked(np.vstack([np.eye(3)] * 2 + [[np.nan, 0, 0]]), np.ones(7))


def test_stacked_shape_errors():
    with pytest.raises(InputError, match=r"Phi.shape=\(6, 3\) but z.shape=\(5,\)"):
        solve_stacked(np.ones((6, 3)), np.ones(5))
    with pytest.raises(InputError, match=r"A.shape=\(3, 3\) but b.shape=\(2,\)"):
        solve_normal_equations(np.eye(3), np.ones(2))

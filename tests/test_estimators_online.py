"""Online laws: the textbook mass-spring-damper numbers, RLS algebra, bounds, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manip_id.errors import InputError
from manip_id.estimators import (
    GradientEstimator,
    InformationAccumulator,
    RLSEstimator,
    solve_accumulator,
    solve_stacked,
)

# The textbook example (course numbers): m y'' + c y' + k y = b u.
M, C, K, B = 2.0, 0.8, 5.0, 1.5
THETA = np.array([K / M, C / M, B / M])
DT, N_UPDATES = 0.002, 12_500


def _msd(estimators, n=N_UPDATES):
    """The example's loop: y'' from the current state, estimator update, explicit Euler."""
    y, dy = 0.4, -0.2
    phis, zs, errs = [], [], [[] for _ in estimators]
    for k in range(n):
        t = k * DT
        phi = np.array([-y, -dy, 1.2 * np.sin(1.1 * t) + 0.7 * np.sin(2.3 * t)])
        ddy = float(phi @ THETA)
        for est, err in zip(estimators, errs, strict=True):
            est.step(phi, ddy, DT)
            err.append(abs(est.last_error))
        phis.append(phi)
        zs.append(ddy)
        y, dy = y + DT * dy, dy + DT * ddy
    return np.array(phis), np.array(zs), [np.array(e) for e in errs]


@pytest.fixture(scope="module")
def msd_run():
    grad = GradientEstimator([0.4, 0.1, 0.2], [8.0, 8.0, 4.0], record_every=10)
    rls = RLSEstimator([0.4, 0.1, 0.2], 100.0, record_every=10)
    phi, z, errs = _msd([grad, rls])
    return grad, rls, phi, z, errs


def _gradient_law_by_hand(theta0, gamma, n=N_UPDATES):
    """The example's gradient law written out in scalars, independently of the estimator.

    Plant ``y'' = phi . THETA`` and law ``theta_i <- theta_i - dt gamma_i phi_i e`` with
    ``e = phi . theta - y''``, both explicit Euler with the example's step: returns the
    final estimate and the prediction errors ``|e|`` of every step.
    """
    th = [float(v) for v in theta0]
    y, dy, errors = 0.4, -0.2, []
    for k in range(n):
        t = k * DT
        phi = (-y, -dy, 1.2 * math.sin(1.1 * t) + 0.7 * math.sin(2.3 * t))
        ddy = sum(p * c for p, c in zip(phi, THETA, strict=True))
        e = sum(p * c for p, c in zip(phi, th, strict=True)) - ddy
        th = [c - DT * g * p * e for c, g, p in zip(th, gamma, phi, strict=True)]
        errors.append(abs(e))
        y, dy = y + DT * dy, dy + DT * ddy
    return np.array(th), np.array(errors)


def test_textbook_gradient_numbers(msd_run):
    grad, _, _, _, (err, _) = msd_run
    assert grad.steps == N_UPDATES
    assert grad.t == pytest.approx(25.0)
    theta, errors = _gradient_law_by_hand([0.4, 0.1, 0.2], [8.0, 8.0, 4.0])
    np.testing.assert_allclose(grad.theta, theta, rtol=1e-12)
    np.testing.assert_allclose(err, errors, rtol=1e-9, atol=1e-15)
    # the law converges: the estimate is closer to THETA than its start, the error small
    start = np.array([0.4, 0.1, 0.2])
    assert np.linalg.norm(grad.theta - THETA) < 0.25 * np.linalg.norm(start - THETA)
    assert err[int(0.8 * N_UPDATES) :].mean() < 0.05 * err[:100].mean()  # 0.011 vs 0.44


def test_textbook_stacked_least_squares_is_exact(msd_run):
    _, _, phi, z, _ = msd_run
    np.testing.assert_allclose(solve_stacked(phi, z).estimate, THETA, rtol=1e-9)
    acc = InformationAccumulator(3, 1).add(phi, z)
    np.testing.assert_allclose(solve_accumulator(acc).estimate, THETA, rtol=1e-9)


def _time_below(history, threshold):
    rel = np.linalg.norm(history.theta - THETA, axis=1) / np.linalg.norm(THETA)
    above = np.nonzero(rel > threshold)[0]
    return None if above[-1] == rel.size - 1 else history.t[above[-1] + 1]


def test_rls_reaches_one_percent_before_the_gradient_law(msd_run):
    grad, rls, _, _, _ = msd_run
    t_rls = _time_below(rls.history, 0.01)
    assert t_rls is not None and t_rls < 5.0
    assert _time_below(grad.history, 0.01) is None  # not within the 25 s of the example
    np.testing.assert_allclose(rls.theta, THETA, rtol=1e-4)


def test_rls_without_forgetting_is_regularized_least_squares():
    rng = np.random.default_rng(0)
    Y = rng.standard_normal((200, 3, 5))
    tau = Y @ rng.standard_normal(5) + 0.1 * rng.standard_normal((200, 3))
    theta0, p0 = rng.standard_normal(5), 10.0
    vec = RLSEstimator(theta0, p0)
    sca = RLSEstimator(theta0, p0)
    for k in range(200):
        vec.step(Y[k], tau[k], 0.01)
        for j in range(3):  # independent rows one at a time: same estimate
            sca.step(Y[k, j], tau[k, j])
    Phi, z = Y.reshape(-1, 5), tau.reshape(-1)
    A = Phi.T @ Phi + np.eye(5) / p0
    expected = np.linalg.solve(A, Phi.T @ z + theta0 / p0)
    np.testing.assert_allclose(vec.theta, expected, rtol=1e-9)
    np.testing.assert_allclose(sca.theta, expected, rtol=1e-9)
    np.testing.assert_allclose(vec.P, np.linalg.inv(A), rtol=1e-7, atol=1e-12)
    assert vec.t == pytest.approx(2.0)


def test_gradient_step_is_euler_of_the_law():
    rng = np.random.default_rng(1)
    G = np.array([[2.0, 0.5, 0], [0.5, 1.0, 0.2], [0, 0.2, 3.0]])
    Y, z, th = rng.standard_normal((2, 3)), rng.standard_normal(2), rng.standard_normal(3)
    for normalized in (False, True):
        for gamma in (np.diag(G).copy(), G):
            Gm = np.diag(gamma) if gamma.ndim == 1 else gamma
            est = GradientEstimator(th, gamma, normalized=normalized)
            est.step(Y, z, 0.01)
            eps = Y @ th - z
            m2 = 1.0 + np.trace(Y @ Gm @ Y.T) if normalized else 1.0
            np.testing.assert_allclose(est.theta, th - 0.01 * Gm @ Y.T @ eps / m2, rtol=1e-13)
            np.testing.assert_allclose(est.last_error, eps)


def test_normalized_gradient_converges_with_a_large_regressor():
    """Regressor entries of size 1e3: at this step the plain law diverges, the normalized not."""
    rng = np.random.default_rng(2)
    theta = np.array([1.0, -0.5, 2.0])
    plain = GradientEstimator(np.zeros(3), 1.0)
    norm = GradientEstimator(np.zeros(3), 1.0, normalized=True)
    for _ in range(3000):
        phi = 1e3 * rng.standard_normal(3)
        norm.step(phi, phi @ theta, 0.5)
        if np.all(np.isfinite(plain.theta)) and np.abs(plain.theta).max() < 1e100:
            with np.errstate(all="ignore"):
                plain.step(phi, phi @ theta, 0.5)
    np.testing.assert_allclose(norm.theta, theta, rtol=1e-8)
    assert np.abs(plain.theta).max() > 1e10


def test_forgetting_with_covariance_bound_does_not_wind_up():
    rng = np.random.default_rng(3)
    est = RLSEstimator(np.zeros(4), 1.0, forgetting=0.95)
    assert est.p_max == pytest.approx(4.0)
    for _ in range(50):
        est.step(rng.standard_normal((2, 4)), rng.standard_normal(2))
    for _ in range(2000):  # no excitation at all
        est.step(np.zeros((2, 4)), np.zeros(2))
        assert np.trace(est.P) <= est.p_max * (1 + 1e-12)
    assert np.all(np.isfinite(est.P))
    assert np.trace(est.P) == pytest.approx(est.p_max, rel=1e-2)
    floor = RLSEstimator(np.zeros(4), 1.0, p_min=0.5)
    for _ in range(500):
        floor.step(rng.standard_normal((3, 4)), rng.standard_normal(3))
    assert np.trace(floor.P) >= 0.5 * (1 - 1e-12)


def test_forgetting_tracks_a_parameter_jump():
    rng = np.random.default_rng(4)
    est = RLSEstimator(np.zeros(2), 100.0, forgetting=0.98)
    rigid = RLSEstimator(np.zeros(2), 100.0)
    for k in range(1000):
        theta = np.array([1.0, 2.0]) if k < 500 else np.array([-1.0, 3.0])
        phi = rng.standard_normal(2)
        est.step(phi, phi @ theta)
        rigid.step(phi, phi @ theta)
    np.testing.assert_allclose(est.theta, [-1.0, 3.0], rtol=1e-3)  # 0.98^500 ~ 4e-5 left
    assert np.abs(rigid.theta - [-1.0, 3.0]).max() > 0.3  # no forgetting: the average


@pytest.mark.parametrize("cls, args", [(GradientEstimator, (5.0,)), (RLSEstimator, (5.0,))])
def test_projection_onto_bounds(cls, args):
    est = cls(np.zeros(2), *args, bounds=([-1.0, 0.0], [1.0, 0.5]))
    rng = np.random.default_rng(5)
    for _ in range(200):
        phi = rng.standard_normal(2)
        est.step(phi, phi @ np.array([3.0, 0.25]), 0.01)
        assert -1.0 <= est.theta[0] <= 1.0 and 0.0 <= est.theta[1] <= 0.5
    assert est.theta[0] == 1.0


def test_history_is_decimated():
    est = GradientEstimator(np.zeros(2), 1.0, record_every=4)
    for _ in range(10):
        est.step(np.ones(2), 1.0, 0.1)
    h = est.history
    assert h.theta.shape == (3, 2) and np.allclose(h.t, [0.0, 0.4, 0.8])
    assert np.isnan(h.error[0]) and h.error[1] > 0


@pytest.mark.parametrize("cls", [GradientEstimator, RLSEstimator])
def test_bad_input(cls):
    est = cls(np.zeros(3), 1.0)
    with pytest.raises(InputError, match=r"Y.shape=\(2, 4\) but the estimator has p=3"):
        est.step(np.ones((2, 4)), np.ones(2), 0.1)
    with pytest.raises(InputError, match=r"Y.shape=\(4,\) but the estimator has p=3"):
        est.step(np.ones(4), 1.0, 0.1)
    with pytest.raises(InputError, match=r"Y.shape=\(2, 3\) but z.shape=\(3,\)"):
        est.step(np.ones((2, 3)), np.ones(3), 0.1)
    est.step(np.ones((2, 3)), np.ones(2), 0.1)
    before = est.theta
    est.step(np.array([1.0, np.nan, 0.0]), 1.0, 0.1)  # a dropout: skipped
    assert est.skipped and est.dropouts == 1
    np.testing.assert_array_equal(est.theta, before)


def test_bad_gains():
    with pytest.raises(InputError, match="positive"):
        GradientEstimator(np.zeros(2), [1.0, -1.0])
    with pytest.raises(InputError, match="symmetric"):
        GradientEstimator(np.zeros(2), [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(InputError, match="positive definite"):
        GradientEstimator(np.zeros(2), [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(InputError, match=r"gamma.shape=\(3,\)"):
        GradientEstimator(np.zeros(2), [1.0, 1.0, 1.0])
    with pytest.raises(InputError, match="forgetting"):
        RLSEstimator(np.zeros(2), 1.0, forgetting=1.5)
    with pytest.raises(InputError, match="P0"):
        RLSEstimator(np.zeros(2), -1.0)

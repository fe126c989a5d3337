"""Concurrent learning: convergence without persistent excitation, the stack's selection."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.errors import InputError
from manip_id.estimators import ConcurrentLearningEstimator, GradientEstimator

M, C, K, B = 2.0, 0.8, 5.0, 1.5
THETA = np.array([K / M, C / M, B / M])
THETA0 = np.array([0.4, 0.1, 0.2])
GAMMA = np.array([8.0, 8.0, 4.0])
DT, N_UPDATES, HOLD = 0.002, 12_500, 5.0


def _u(t):
    t = min(t, HOLD)  # the input is held constant after 5 s
    return 1.2 * np.sin(1.1 * t) + 0.7 * np.sin(2.3 * t)


def _msd(estimators, n=N_UPDATES):
    y, dy = 0.4, -0.2
    phis = []
    for k in range(n):
        phi = np.array([-y, -dy, _u(k * DT)])
        ddy = float(phi @ THETA)
        for est in estimators:
            est.step(phi, ddy, DT)
        phis.append(phi)
        y, dy = y + DT * dy, dy + DT * ddy
    return np.array(phis)


@pytest.fixture(scope="module")
def runs():
    cl = ConcurrentLearningEstimator(THETA0, GAMMA, record_every=10)
    grad = GradientEstimator(THETA0, GAMMA, record_every=10)
    phi = _msd([cl, grad])
    return cl, grad, phi


def _rel(theta):
    return np.linalg.norm(theta - THETA) / np.linalg.norm(THETA)


def test_input_held_constant_gradient_stalls_concurrent_learning_converges(runs):
    cl, grad, phi = runs
    # after the hold the regressor tends to one constant direction (the decaying
    # transient of the plant, rate c/2m = 0.2 1/s, is all that is left of the rest)
    s = np.linalg.svd(phi[-5000:], compute_uv=False)
    assert s[1] / s[0] < 0.02
    assert cl.stack_rank == 3
    assert _rel(cl.theta) < 1e-6
    assert _rel(grad.theta) > 0.2
    # the gradient law's error hardly moves over the last 10 s: it has stalled
    h = grad.history
    k = np.searchsorted(h.t, 15.0)
    assert abs(_rel(h.theta[k]) - _rel(h.theta[-1])) < 0.02


def test_stack_maximizes_the_minimum_singular_value():
    rng = np.random.default_rng(0)
    cl = ConcurrentLearningEstimator(np.zeros(3), 1.0, stack_size=4, novelty=0.0)
    sig = []
    for _ in range(300):
        phi = rng.standard_normal(3) * np.array([1.0, 0.1, 3.0])
        cl.step(phi, 0.0, 1e-3)
        sig.append(cl.sigma_min)
    Ys, zs = cl.stack
    assert Ys.shape == (4, 1, 3) and zs.shape == (4, 1)
    stacked = Ys.reshape(4, 3)
    smin = np.linalg.svd(stacked, compute_uv=False)[-1]
    assert cl.sigma_min == pytest.approx(smin, rel=1e-9)
    assert np.all(np.diff(sig[4:]) >= -1e-12)  # never decreases once full
    # and it beats a stack of the first four samples
    rng = np.random.default_rng(0)
    first = np.array([rng.standard_normal(3) * np.array([1.0, 0.1, 3.0]) for _ in range(4)])
    assert smin >= np.linalg.svd(first, compute_uv=False)[-1]


def test_step_is_euler_of_the_law():
    rng = np.random.default_rng(1)
    cl = ConcurrentLearningEstimator(np.zeros(2), [2.0, 0.5], stack_size=2, novelty=0.0)
    Y1, Y2, Y3 = rng.standard_normal((3, 3, 2))
    th_true = np.array([0.3, -1.2])
    cl.step(Y1, Y1 @ th_true, 0.01)
    cl.step(Y2, Y2 @ th_true, 0.01)
    th = cl.theta.copy()
    z3 = Y3 @ th_true
    cl.step(Y3, z3, 0.01)
    Ys, zs = cl.stack
    S = sum(Yj.T @ (Yj @ th - zj) for Yj, zj in zip(Ys, zs, strict=True))
    expected = th - 0.01 * np.diag([2.0, 0.5]) @ (Y3.T @ (Y3 @ th - z3) + S)
    np.testing.assert_allclose(cl.theta, expected, rtol=1e-12)


def test_bad_input():
    with pytest.raises(InputError, match="stack_size"):
        ConcurrentLearningEstimator(np.zeros(2), 1.0, stack_size=0)
    with pytest.raises(InputError, match="novelty"):
        ConcurrentLearningEstimator(np.zeros(2), 1.0, novelty=-1.0)
    est = ConcurrentLearningEstimator(np.zeros(3), 1.0)
    with pytest.raises(InputError, match=r"Y.shape=\(2, 4\) but the estimator has p=3"):
        est.step(np.ones((2, 4)), np.ones(2), 0.1)
    est.step(np.array([1.0, np.nan, 0.0]), 1.0, 0.1)  # a dropout: skipped
    assert est.skipped and est.dropouts == 1

"""DREM: element-wise monotone parameter errors on the lesson's mass-spring-damper, algebra."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.errors import InputError
from manip_id.estimators import DREMEstimator, GradientEstimator

# The lesson's plant m y'' + c y' + k y = b u, theta = [k/m, c/m, b/m].
M, C, K, B = 2.0, 0.8, 5.0, 1.5
THETA = np.array([K / M, C / M, B / M])
THETA0 = np.array([0.4, 0.1, 0.2])
DT, N_UPDATES = 0.002, 12_500


def _msd(estimators, n=N_UPDATES):
    y, dy = 0.4, -0.2
    for k in range(n):
        t = k * DT
        phi = np.array([-y, -dy, 1.2 * np.sin(1.1 * t) + 0.7 * np.sin(2.3 * t)])
        ddy = float(phi @ THETA)
        for est in estimators:
            est.step(phi, ddy, DT)
        y, dy = y + DT * dy, dy + DT * ddy


def _time_below(history, threshold=0.01):
    rel = np.linalg.norm(history.theta - THETA, axis=1) / np.linalg.norm(THETA)
    above = np.nonzero(rel > threshold)[0]
    return None if above[-1] == rel.size - 1 else float(history.t[above[-1] + 1])


@pytest.fixture(scope="module")
def runs():
    drem = DREMEstimator(THETA0, gamma=1e6, alpha=0.5, normalized=False, record_every=1)
    grad = GradientEstimator(THETA0, [8.0, 8.0, 4.0], record_every=1)
    default = DREMEstimator(THETA0, record_every=1)  # the normalized law, its default gain
    _msd([drem, grad, default])
    return drem, grad, default


@pytest.mark.parametrize("law", [0, 2], ids=["plain", "normalized-default"])
def test_every_parameter_error_is_non_increasing(runs, law):
    drem = runs[law]
    err = np.abs(drem.history.theta - THETA)  # (12501, 3)
    assert err.shape == (N_UPDATES + 1, 3)
    assert drem.t == pytest.approx(25.0)
    # element-wise, at every one of the 12,500 steps (round-off allowance 1e-12)
    assert np.all(np.diff(err, axis=0) <= 1e-12)
    assert np.all(err[-1] < 1e-6 * np.abs(THETA))


def test_drem_converges_where_the_gradient_law_has_not(runs):
    drem, grad, _ = runs
    t_drem = _time_below(drem.history)
    assert t_drem is not None and t_drem < 10.0
    assert _time_below(grad.history) is None  # the lesson's point: not within 25 s
    # the gradient law's individual errors are not monotone (the contrast)
    g_err = np.abs(grad.history.theta - THETA)
    assert np.any(np.diff(g_err, axis=0) > 1e-6)


def test_mixing_is_determinant_and_adjugate():
    rng = np.random.default_rng(0)
    theta = np.array([1.0, -2.0, 0.5])
    est = DREMEstimator(np.zeros(3), 1.0, alpha=2.0, normalized=False)
    norm = DREMEstimator(np.zeros(3), 1.0, alpha=2.0)
    for _ in range(40):
        Y = rng.standard_normal((2, 3))
        est.step(Y, Y @ theta, 0.01)
        norm.step(1e3 * Y, 1e3 * Y @ theta, 0.01)  # scaled data: the same Delta_n
    Phi = est.extended_regressor
    # independent: the filter written out as a sum of geometric weights
    a, g = np.exp(-2.0 * 0.01), (1 - np.exp(-2.0 * 0.01)) / 2.0
    rng = np.random.default_rng(0)
    ref = np.zeros((3, 3))
    for _ in range(40):
        Y = rng.standard_normal((2, 3))
        ref = a * ref + g * Y.T @ Y
    np.testing.assert_allclose(Phi, ref, rtol=1e-12)
    delta, Z = est.mixed()
    assert delta == pytest.approx(np.linalg.det(ref), rel=1e-10)
    adj = np.linalg.det(ref) * np.linalg.inv(ref)
    np.testing.assert_allclose(Z, adj @ (ref @ theta), rtol=1e-9)
    np.testing.assert_allclose(Z, delta * theta, rtol=1e-9)  # Z_i = Delta theta_i
    # normalized: Delta_n = det(Phi_e / s), s = tr(Phi_e) / p, whatever the data's scale
    dn, Zn = norm.mixed()
    s = np.trace(ref) / 3
    assert dn == pytest.approx(np.linalg.det(ref / s), rel=1e-9)
    assert 0 < dn <= 1
    np.testing.assert_allclose(Zn, dn * theta, rtol=1e-9)


def test_default_gain_converges_at_any_data_scale():
    # the lesson's plant with the regression scaled by 1e-3 and 1e3: the plain law's
    # Delta scales like 1e-18 / 1e18, the normalized one does not move
    times = []
    for scale in (1e-3, 1.0, 1e3):
        est = DREMEstimator(THETA0, record_every=1)
        y, dy = 0.4, -0.2
        for k in range(N_UPDATES):
            phi = np.array([-y, -dy, 1.2 * np.sin(1.1 * k * DT) + 0.7 * np.sin(2.3 * k * DT)])
            ddy = float(phi @ THETA)
            est.step(scale * phi, scale * ddy, DT)
            y, dy = y + DT * dy, dy + DT * ddy
        times.append(_time_below(est.history))
    assert all(t is not None and t < 15.0 for t in times)
    assert max(times) - min(times) < 1e-6  # the same law at every scale


def test_no_excitation_no_update_and_bad_input():
    est = DREMEstimator(np.ones(2), 5.0)
    for _ in range(10):
        est.step(np.array([1.0, 0.0]), 3.0, 0.1)  # rank one: Delta = 0
    assert est.delta == 0.0
    np.testing.assert_array_equal(est.theta, [1.0, 1.0])
    with pytest.raises(InputError, match=r"Y.shape=\(3,\) but the estimator has p=2"):
        est.step(np.ones(3), 1.0, 0.1)
    est.step(np.array([np.nan, 1.0]), 1.0, 0.1)  # a dropout: skipped
    assert est.skipped and est.dropouts == 1
    with pytest.raises(InputError, match="alpha"):
        DREMEstimator(np.zeros(2), 1.0, alpha=0.0)
    with pytest.raises(InputError, match="positive"):
        DREMEstimator(np.zeros(2), [1.0, -1.0])

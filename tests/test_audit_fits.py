"""The audit's small least squares against numpy's SVD-based lstsq."""

from __future__ import annotations

import numpy as np

from manip_id.audit.fits import least_squares


def test_least_squares_equals_svd_lstsq():
    rng = np.random.default_rng(0)
    for _ in range(20):
        n, p = int(rng.integers(50, 5000)), int(rng.integers(1, 6))
        X = rng.standard_normal((n, p)) * rng.uniform(1e-3, 1e3, p)
        y = X @ rng.standard_normal(p) + 0.1 * rng.standard_normal(n)
        ref = np.linalg.lstsq(X, y, rcond=None)[0]
        np.testing.assert_allclose(least_squares(X, y), ref, rtol=1e-10, atol=1e-12)


def test_least_squares_minimum_norm_with_a_zero_column():
    rng = np.random.default_rng(1)
    X = np.column_stack([rng.standard_normal(300), np.zeros(300), np.ones(300)])
    y = 2.0 * X[:, 0] - 0.5 + 0.01 * rng.standard_normal(300)
    got = least_squares(X, y)
    np.testing.assert_allclose(got, np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-10, atol=1e-14)
    assert got[1] == 0.0

"""The named result of a least-squares solve: estimate, uncertainty, residual statistics."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..metrics import relative_error


@dataclass(frozen=True)
class LeastSquaresSolution:
    """Estimate of ``p`` parameters from ``n_rows`` stacked equations, with its uncertainty.

    Attributes
    ----------
    estimate
        theta_hat, shape (p,)
    covariance
        covariance of theta_hat, shape (p, p): ``sigma2 (Phi^T Phi)^-1`` for
        ordinary least squares, ``(Phi^T W Phi)^-1`` with ``W = diag(1/sigma_j^2)`` for
        weighted least squares (pseudo-inverse on the excited subspace for a
        minimum-norm solution).
    sigma2
        residual variance ``RSS / (n_rows - rank)`` [(N m)^2]; for weighted
        least squares the weighted one, ``sum_j RSS_j / sigma_j^2 / dof`` (about 1).
    noise_variance
        per-output residual variance ``RSS_j / (n - rank / nv)``, shape (nv,)
    rss_per_joint
        residual sum of squares per output, shape (nv,) [(N m)^2]
    zz_per_joint
        sum of squared outputs per output, shape (nv,) [(N m)^2]
    n_rows
        number of stacked equations; dof: ``n_rows - rank``
    rank
        numerical rank; condition_number: 2-norm condition number of the
        regressor (unscaled); scaled_condition_number: the same after scaling
        every column to unit norm (what the solver sees).
    solver
        how it was solved, including any fallback and why.
    weights
        per-output weights ``1/sigma_j^2`` of weighted least squares, else None.
    """

    estimate: np.ndarray
    covariance: np.ndarray
    sigma2: float
    noise_variance: np.ndarray
    rss_per_joint: np.ndarray
    zz_per_joint: np.ndarray
    n_rows: int
    rank: int
    condition_number: float
    scaled_condition_number: float
    solver: str
    weights: np.ndarray | None = None

    @property
    def dof(self) -> int:
        """Residual degrees of freedom ``n_rows - rank``."""
        return self.n_rows - self.rank

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of each estimate, shape (p,)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @property
    def std_percent(self) -> np.ndarray:
        """Relative standard deviation ``100 std / |theta_hat|`` [%], shape (p,) (inf at 0)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            out = 100.0 * self.std / np.abs(self.estimate)
        return np.where(np.isnan(out), np.inf, out)

    @property
    def rss(self) -> float:
        """Residual sum of squares ``||z - Phi theta_hat||^2``."""
        return float(self.rss_per_joint.sum())

    @property
    def relative_error(self) -> float:
        """``||z - Phi theta_hat|| / ||z||`` over all rows."""
        return relative_error(self.rss_per_joint, self.zz_per_joint).total

    @property
    def relative_error_per_joint(self) -> np.ndarray:
        """``||z_j - Phi_j theta_hat|| / ||z_j||`` per output, shape (nv,)."""
        return relative_error(self.rss_per_joint, self.zz_per_joint).per_joint

"""The honest covariance of drive gains: from the runs' per-block sums, for every method.

The accumulated system ``[D(i), -X] x = c`` of :mod:`manip_id.payload.gains` records
its blocks of contiguous samples per run (:func:`~manip_id.payload.runs.run_sums`), so
the autocorrelation-consistent (Newey-West, Andrews bandwidth) sandwich of
:mod:`manip_id.estimators.uncertainty` needs no second pass and Dask partitions still
add. Per method, with ``H`` the estimator's bread and ``s_k`` its block scores:

- **ols / wls**: ``s_k = sum_j w_j (b_kj - A_kj x)``, ``H = A_w``
  (:func:`~manip_id.estimators.uncertainty.solution_uncertainty`).
- **ml**: ``s_k`` the block gradients of ``sum_j w_j ||i_j - k_j X~_j theta~||^2 / 2`` in
  ``xi = [k, theta]``, ``H`` its Gauss-Newton matrix, mapped to ``g = 1/k``
  (:func:`~manip_id.payload.gain_estimators.ml_sandwich`).
- **tls**: its white covariance is the OLS one rescaled by the TLS residual variance;
  each parameter's std is multiplied by the OLS ratio ``std_hac / std_white`` of the
  same sums (the same correlation structure of the residual rows).

The headline covariance keeps the white-noise correlations with the honest standard
deviations, never below the white ones
(:func:`~manip_id.estimators.uncertainty.correlations_scaled`), as the payload's; with
too few blocks (``auto``) it stays white and says why. ``inflation`` is the median over
the determined parameters of ``std / std_white``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..estimators import InformationAccumulator
from ..estimators.results import LeastSquaresSolution
from ..estimators.uncertainty import (
    HAC,
    correlations_scaled,
    inflation,
    solution_uncertainty,
)
from .gain_estimators import ml_sandwich


@dataclass(frozen=True)
class GainUncertainty:
    """The drive-gain system's covariance, honest and white.

    Attributes
    ----------
    covariance : numpy.ndarray
        The headline covariance of ``[g, beta, psi_u]``, shape (p, p).
    covariance_white : numpy.ndarray
        The white-noise covariance of the method, shape (p, p).
    summary : dict
        The JSON ``uncertainty``: ``method``, ``bandwidth``, ``inflation``, ``n_blocks``, ...
    """

    covariance: np.ndarray
    covariance_white: np.ndarray
    summary: dict

    @property
    def std(self) -> np.ndarray:
        """Honest standard deviations, shape (p,)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def std_white(self) -> np.ndarray:
        """White-noise standard deviations, shape (p,)."""
        return np.sqrt(np.clip(np.diag(self.covariance_white), 0.0, None))


def gain_uncertainty(
    acc: InformationAccumulator,
    ls: LeastSquaresSolution,
    f: float,
    method: str,
    x: np.ndarray,
    white: np.ndarray,
    n_rows: np.ndarray,
    determined: np.ndarray,
) -> GainUncertainty:
    """The honest covariance of the drive-gain estimate ``x`` of ``method`` (module docstring).

    Parameters
    ----------
    acc : InformationAccumulator
        The system's sums with their blocks, ``p`` columns.
    ls : LeastSquaresSolution
        The OLS/WLS solve of those sums; ``f``: its deadband dof factor.
    method : str
        ``"ols"``, ``"wls"``, ``"tls"`` or ``"ml"``; ``x`` its estimate, shape (p,),
        ``white`` its white-noise covariance, shape (p, p).
    n_rows : numpy.ndarray
        Rows per joint in the fit (the deadband's left out), shape (nv,).
    determined : numpy.ndarray
        Per joint, whether the data fix its gain, shape (nv,) bool.
    """
    nv = determined.size
    white_ls = ls.covariance * f
    unc = solution_uncertainty(acc, ls, white_covariance=white_ls)
    if unc.method != HAC:
        return GainUncertainty(white, white, unc.to_dict())
    summary = unc.to_dict()
    if method in ("ols", "wls"):
        std = unc.std
    elif method == "tls":
        sw = unc.std_white
        ratio = np.divide(unc.std, sw, out=np.ones_like(sw), where=sw > 0)
        std = np.sqrt(np.clip(np.diag(white), 0.0, None)) * ratio
    else:
        cov_ml, hac = ml_sandwich(acc, nv, x, n_rows, determined)
        std = np.sqrt(np.clip(np.diag(cov_ml), 0.0, None))
        summary.update(bandwidth=float(f"{hac.bandwidth:.6g}"), n_blocks=int(hac.n_blocks))
    cov = correlations_scaled(white, std)
    sw = np.sqrt(np.clip(np.diag(white), 0.0, None))
    keep = np.r_[determined, np.ones(x.size - nv, dtype=bool)]
    infl = inflation(np.sqrt(np.diag(cov))[keep], sw[keep])
    summary["inflation"] = None if infl is None else float(f"{infl:.6g}")
    return GainUncertainty(cov, white, summary)

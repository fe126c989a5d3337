"""Estimators of theta in the linear-in-parameters model.

Every estimator here solves the same regression, sample by sample or in a batch::

    z_k = Y_k theta + e_k        Y_k of shape (nv, p), z_k of shape (nv,)
                                 (scalar case: phi_k of shape (p,), z_k scalar)

stacked sample-major into ``z = Phi theta + e`` (row ``k*nv + j`` is output
``j`` of sample ``k``). The prediction error of an estimate is
``eps = Phi theta_hat - z`` and the parameter error ``theta_tilde = theta_hat - theta``.

Batch least squares minimise ``||z - Phi theta||^2`` (weighted: per output
``j`` by ``1/sigma_j^2``). Everything they need is the information

    A = Phi^T Phi (p, p),   b = Phi^T z (p,),   z^T z,   number of rows,

kept per output by :class:`InformationAccumulator` (memory O(nv p^2) whatever
the number of samples; accumulators of disjoint data add). The estimate is
``theta_hat = A^-1 b``; with white noise of variance ``sigma^2`` its
covariance is ``sigma^2 A^-1`` with ``sigma^2 = RSS / (n_rows - p)`` and
``RSS = z^T z - 2 b^T theta_hat + theta_hat^T A theta_hat``.

Online laws (:class:`GradientEstimator`, :class:`RLSEstimator`) update
``theta_hat`` from one sample at a time; RLS with no forgetting converges to
the batch estimate (it *is* the batch estimate, regularized by ``P0^-1``).
:class:`DREMEstimator` mixes a filtered extension into one scalar regression per
parameter (each parameter error non-increasing); :class:`ConcurrentLearningEstimator`
adds a recorded history stack (convergence without persistent excitation).
"""

from typing import Any

from .._lazy import LazyExports

#: Public name -> the submodule that defines it (imported on first use, PEP 562).
_WHERE: dict[str, str] = {
    "InformationAccumulator": ".accumulator",
    "ScoreBlocks": ".blocks",
    "Uncertainty": ".uncertainty",
    "UncertaintyOptions": ".uncertainty",
    "estimate_uncertainty": ".uncertainty",
    "solution_uncertainty": ".uncertainty",
    "COND_LIMIT": ".batch",
    "INFO_RANK_RTOL": ".batch",
    "STACKED_RANK_RTOL": ".batch",
    "format_direction": ".batch",
    "solve_accumulator": ".batch",
    "solve_normal_equations": ".batch",
    "solve_stacked": ".batch",
    "GradientEstimator": ".online",
    "OnlineHistory": ".online",
    "RLSEstimator": ".online",
    "LeastSquaresSolution": ".results",
    "ConsistentSolution": ".consistent",
    "SolverError": ".consistent",
    "StandardEstimate": ".consistent",
    "build_problem": ".consistent",
    "solve_consistent": ".consistent",
    "DREMEstimator": ".drem",
    "ConcurrentLearningEstimator": ".concurrent",
}


_LAZY = LazyExports(__name__, {name: (module, name) for name, module in _WHERE.items()})
__all__ = _LAZY.names


def __getattr__(name: str) -> Any:
    """Import the submodule that defines ``name`` on first access (PEP 562)."""
    return _LAZY.load(name, globals())


def __dir__() -> list[str]:
    return _LAZY.listing(globals())

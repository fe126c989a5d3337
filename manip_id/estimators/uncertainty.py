"""Covariance of least-squares estimates that holds for correlated residuals.

From accumulated sums the estimate is ``theta_hat = A^-1 b`` with
``A = sum_j w_j A_j`` and ``b = sum_j w_j b_j`` (``w_j = 1`` for ordinary least
squares, ``1 / sigma_j^2`` for weighted), so with ``e_t`` the noise of sample ``t``::

    theta_hat - theta = A^-1 s,      s = sum_t Y_t^T W e_t        (the score)
    Cov(theta_hat)    = A^-1 Omega A^-1,      Omega = Var(s)

**white** (:data:`WHITE`): the residuals are independent from sample to sample with
variance ``sigma^2`` (OLS) or ``sigma_j^2 = 1 / w_j`` (WLS), so ``Omega = sigma^2 A``
(``A``) and ``Cov = sigma^2 A^-1`` (``A^-1``). On real logs it is far too small:
torques low-pass filtered at a few Hz and model error make the residuals of
neighbouring samples alike, and ``Omega`` then holds the cross terms
``Y_t^T W E[e_t e_u^T] W Y_u`` of every pair of samples closer than the
correlation time (on the real Panda log, about 16x in standard deviation).

**hac** (:data:`HAC`, heteroskedasticity and autocorrelation consistent): the
samples are cut into ``B`` blocks of contiguous samples, recorded while the sums
are accumulated (:class:`~manip_id.estimators.blocks.ScoreBlocks`), and
``s = sum_k s_k`` with the block scores ``s_k = b_k - A_k theta``. Then::

    Omega = sum_{h=-(B-1)}^{B-1} Gamma_h,      Gamma_h = sum_k E[s_k s_{k+h}^T]

estimated at the estimate (``s_hat_k = b_k - A_k theta_hat = Y_k^T W e_hat_k``, no
second pass) with Bartlett (Newey-West) weights over block lags::

    Omega_hat = sum_{|h| < S} (1 - |h| / S) Gamma_hat_h,   Gamma_hat_{-h} = Gamma_hat_h^T

    Cov_hac = c A^-1 Omega_hat A^-1

- ``S`` [blocks] is the bandwidth. Blocks much longer than the correlation time
  are nearly independent and ``S <= 1`` keeps lag 0 alone (batch means); shorter
  blocks leave correlation between neighbours, which the lags ``h < S`` take in. The
  Bartlett weights make ``Omega_hat`` positive semi-definite.
- Automatic ``S`` (Andrews 1991, AR(1) plug-in for the Bartlett kernel): per
  parameter ``a`` the block influences ``g_k = A^-1 s_hat_k`` are fit by an AR(1)
  with coefficient ``rho_a`` (clipped to ``[-0.97, 0.97]``), weighted by
  ``sigma_a^-4`` so that the units of the parameters drop out::

      alpha = sum_a 4 rho_a^2 / ((1 - rho_a)^6 (1 + rho_a)^2) / sum_a (1 - rho_a)^-4
      S     = 1.1447 (alpha B)^(1/3),      at most B / 2

- ``c = 1 / (1 - v^T K v)`` corrects the scores for being taken at ``theta_hat``
  (they sum to zero): for independent blocks with ``Var(s_k) = v_k Omega``,
  ``E[Omega_hat] = (1 - v^T K v) Omega``, ``K_kl = kernel(|k - l|)``. The block
  shares are ``v_k = tr(A_k A^-1) / tr(A A^-1)`` (``1 / B`` for equal blocks,
  where lag 0 alone gives the familiar ``B / (B - 1)``).

The honest standard deviation is ``sqrt(diag Cov_hac)``. Its own error falls as the
number of blocks grows (about ``sqrt(1 / (2 B_eff))`` relative, ``B_eff`` of order
``B / S``); it is biased low only by the correlation beyond ``S`` blocks. The
accumulator keeps 64 to 128 blocks by default; with fewer than
:attr:`UncertaintyOptions.min_blocks` (short records) ``"auto"`` falls back to the
white covariance and says why. The Monte Carlo of ``tests/test_uncertainty.py``
(ur5, AR(1) torque noise of correlation time 20 samples) checks the choice: the
spread of the estimates over noise draws against the mean reported std.

**auto** (:data:`AUTO`, the default): ``hac`` when the sums carry blocks and there
are at least ``min_blocks`` of them, else ``white`` with the reason.

The result (:class:`Uncertainty`) also gives ``inflation``, the median over the
parameters of ``std / std_white``: about 1 for white residuals, the factor by
which the white-noise formula understates the uncertainty otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float_array
from ..errors import InputError
from .accumulator import InformationAccumulator
from .blocks import BLOCK_LENGTH, MAX_BLOCKS, ScoreBlocks
from .results import LeastSquaresSolution

AUTO, WHITE, HAC = "auto", "white", "hac"
#: The covariance methods (``"auto"`` picks one of the other two).
METHODS = (AUTO, WHITE, HAC)
#: Fewest blocks for which ``"auto"`` uses the autocorrelation-consistent covariance.
MIN_BLOCKS = 16
#: AR(1) coefficients of the bandwidth plug-in are clipped to this magnitude.
RHO_CLIP = 0.97


@dataclass(frozen=True)
class UncertaintyOptions:
    """How the covariance of an estimate is computed (see the module docstring).

    Attributes
    ----------
    method : str
        ``"auto"`` (default: ``"hac"`` when possible, else ``"white"``), ``"white"``
        or ``"hac"``.
    bandwidth : float or None
        Bartlett bandwidth ``S`` [blocks] of ``"hac"``; None: automatic (Andrews).
    min_blocks : int
        Fewest blocks for which ``"auto"`` picks ``"hac"``.
    block_length : int
        Samples per recorded block before the first doubling.
    max_blocks : int
        Cap on the recorded blocks (between half of it and it are kept).
    """

    method: str = AUTO
    bandwidth: float | None = None
    min_blocks: int = MIN_BLOCKS
    block_length: int = BLOCK_LENGTH
    max_blocks: int = MAX_BLOCKS

    def __post_init__(self):
        if self.method not in METHODS:
            raise InputError(f"uncertainty must be one of {METHODS}, got {self.method!r}")
        if self.bandwidth is not None and not (np.isfinite(self.bandwidth) and self.bandwidth > 0):
            raise InputError(f"bandwidth must be a positive number, got {self.bandwidth!r}")
        if int(self.min_blocks) < 2:
            raise InputError(f"min_blocks must be >= 2, got {self.min_blocks!r}")
        if int(self.block_length) < 1 or int(self.max_blocks) < 2:
            raise InputError(
                f"block_length must be >= 1 and max_blocks >= 2, got "
                f"{self.block_length!r} and {self.max_blocks!r}"
            )

    @classmethod
    def from_value(cls, value: UncertaintyOptions | str | dict | None) -> UncertaintyOptions:
        """Options from themselves, a method name, a dict of fields, or None (defaults)."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            return cls(method=value)
        if isinstance(value, dict):
            unknown = set(value) - set(cls.__dataclass_fields__)
            if unknown:
                raise InputError(
                    f"unknown uncertainty option(s) {sorted(unknown)}; expected some of "
                    f"{sorted(cls.__dataclass_fields__)}"
                )
            return cls(**value)
        raise InputError(
            f"uncertainty must be a method name, a dict or UncertaintyOptions, got "
            f"{type(value).__name__}"
        )

    @property
    def records_blocks(self) -> bool:
        """Whether the accumulation should record blocks (not for ``"white"``)."""
        return self.method != WHITE

    def blocks(self, p: int, nv: int, *, stream: int = 0, offset: int = 0) -> ScoreBlocks | None:
        """An empty block record of ``p`` columns and ``nv`` joints for the samples of
        ``stream`` from ``offset`` on (:class:`~manip_id.estimators.blocks.ScoreBlocks`);
        None for ``"white"``, which needs none."""
        if not self.records_blocks:
            return None
        return ScoreBlocks(p, nv, self.block_length, self.max_blocks, stream=stream, offset=offset)

    def accumulator(
        self, p: int, nv: int, *, stream: int = 0, offset: int = 0
    ) -> InformationAccumulator:
        """An empty accumulator that records blocks as these options need."""
        blocks = self.blocks(p, nv, stream=stream, offset=offset)
        return InformationAccumulator(p, nv, blocks=False if blocks is None else blocks)


@dataclass(frozen=True)
class Uncertainty:
    """The covariance of an estimate, honest and white.

    Attributes
    ----------
    covariance : numpy.ndarray
        The covariance of ``method``, shape (p, p).
    std : numpy.ndarray
        ``sqrt(diag covariance)``, shape (p,).
    covariance_white : numpy.ndarray
        The white-noise covariance, shape (p, p); std_white its std, shape (p,).
    method : str
        ``"white"`` or ``"hac"`` (what was used); requested: what was asked.
    bandwidth : float or None
        Bartlett bandwidth ``S`` [blocks] of ``"hac"``, None for ``"white"``.
    inflation : float or None
        Median over parameters of ``std / std_white`` (None when no white std > 0).
    n_blocks : int
        Blocks of contiguous samples behind ``"hac"`` (0 when none were recorded).
    block_samples : float or None
        Mean samples per block.
    correction : float
        The factor ``c`` of the module docstring (1 for ``"white"``).
    reason : str
        Why ``"auto"`` fell back to ``"white"`` ("" otherwise).
    """

    covariance: np.ndarray
    std: np.ndarray
    covariance_white: np.ndarray
    std_white: np.ndarray
    method: str
    requested: str
    bandwidth: float | None = None
    inflation: float | None = None
    n_blocks: int = 0
    block_samples: float | None = None
    correction: float = 1.0
    reason: str = field(default="")

    def to_dict(self) -> dict:
        """The JSON ``uncertainty`` section (numbers rounded to 6 significant digits)."""

        def num(x):
            return None if x is None or not np.isfinite(x) else float(f"{x:.6g}")

        return {
            "method": self.method,
            "requested": self.requested,
            "bandwidth": num(self.bandwidth),
            "inflation": num(self.inflation),
            "n_blocks": int(self.n_blocks),
            "block_samples": num(self.block_samples),
            "reason": self.reason,
        }


# ------------------------------------------------------------------ pieces
def bartlett_weights(bandwidth: float, n_lags: int) -> np.ndarray:
    """Bartlett weights ``max(0, 1 - h / S)`` for lags ``h = 0 .. n_lags - 1``, shape (n_lags,)."""
    h = np.arange(int(n_lags), dtype=float)
    return np.maximum(1.0 - h / float(bandwidth), 0.0)


def andrews_bandwidth(series) -> float:
    """Andrews' (1991) AR(1) plug-in bandwidth [lags] for the Bartlett kernel.

    Parameters
    ----------
    series : array_like
        ``B`` observations of ``m`` series, shape (B, m), mean about zero (block
        influences). Series that are identically zero are left out.

    Returns
    -------
    float
        ``S = 1.1447 (alpha B)^(1/3)`` with ``alpha`` of the module docstring, at most
        ``B / 2``; 0.0 when no series varies (lag 0 alone).
    """
    g = as_float_array(series, "series", ndim=2)
    B = g.shape[0]
    if B < 3:
        return 0.0
    den = np.einsum("ka,ka->a", g[:-1], g[:-1])
    ok = den > 0
    if not ok.any():
        return 0.0
    rho = np.einsum("ka,ka->a", g[1:, ok], g[:-1, ok]) / den[ok]
    rho = np.clip(rho, -RHO_CLIP, RHO_CLIP)
    num = np.sum(4.0 * rho**2 / ((1.0 - rho) ** 6 * (1.0 + rho) ** 2))
    alpha = float(num / np.sum((1.0 - rho) ** -4))
    return float(min(1.1447 * (alpha * B) ** (1.0 / 3.0), B / 2.0))


def long_run_covariance(scores, bandwidth: float) -> np.ndarray:
    """``sum_{|h| < S} (1 - |h| / S) Gamma_h`` of block scores, shape (p, p).

    Parameters
    ----------
    scores : array_like
        Block scores ``s_k`` in sample order, shape (B, p).
    bandwidth : float
        ``S`` [blocks]; ``S <= 1`` keeps lag 0 alone (batch means).
    """
    s = as_float_array(scores, "scores", ndim=2)
    B = s.shape[0]
    n_lags = min(B, int(np.ceil(bandwidth))) if bandwidth > 1 else 1
    w = bartlett_weights(max(bandwidth, 1.0), n_lags)
    omega = s.T @ s
    for h in range(1, n_lags):
        gamma = s[h:].T @ s[:-h]  # sum_k s_{k+h} s_k^T
        omega += w[h] * (gamma + gamma.T)
    return 0.5 * (omega + omega.T)


def _correction(shares: np.ndarray, bandwidth: float) -> float:
    """``1 / (1 - v^T K v)``: the bias of scores taken at the estimate (module docstring)."""
    B = shares.size
    n_lags = min(B, int(np.ceil(bandwidth))) if bandwidth > 1 else 1
    w = bartlett_weights(max(bandwidth, 1.0), n_lags)
    quad = float(shares @ shares)
    for h in range(1, n_lags):
        quad += 2.0 * w[h] * float(shares[h:] @ shares[:-h])
    return 1.0 / max(1.0 - quad, 1.0 / B)


@dataclass(frozen=True)
class HacEstimate:
    """The autocorrelation-consistent covariance and how it was made.

    Attributes
    ----------
    covariance : numpy.ndarray
        ``c A^-1 Omega_hat A^-1``, shape (p, p).
    bandwidth : float
        Bartlett bandwidth ``S`` [blocks].
    correction : float
        ``c`` (module docstring).
    n_blocks : int
        Number of blocks ``B``.
    """

    covariance: np.ndarray
    bandwidth: float
    correction: float
    n_blocks: int


def hac_covariance(
    blocks: ScoreBlocks,
    estimate,
    information_inverse,
    *,
    weights=None,
    bandwidth: float | None = None,
) -> HacEstimate:
    """The sandwich ``c A^-1 Omega_hat A^-1`` from block scores at ``estimate``.

    Parameters
    ----------
    blocks : ScoreBlocks
        The per-block sums of the data behind the estimate (at least 2 blocks).
    estimate : array_like
        ``theta_hat``, shape (p,).
    information_inverse : array_like
        ``A^-1`` of the solve (pseudo-inverse for a minimum-norm solution), shape (p, p).
    weights : array_like or None
        Per-joint weights ``w_j`` of the solve, shape (nv,); None: all 1 (OLS).
    bandwidth : float or None
        ``S`` [blocks]; None: automatic (:func:`andrews_bandwidth`).
    """
    Ainv = as_float_array(information_inverse, "information_inverse", ndim=2)
    if Ainv.shape != (blocks.p, blocks.p):
        raise InputError(f"information_inverse.shape={Ainv.shape} but p={blocks.p}")
    B = blocks.n_blocks
    if B < 2:
        raise InputError(
            f"an autocorrelation-consistent covariance needs >= 2 blocks of samples, got {B}"
        )
    return sandwich_covariance(
        blocks.scores(estimate, weights), Ainv, blocks.information(weights), bandwidth=bandwidth
    )


def sandwich_covariance(
    scores, bread, block_information, *, bandwidth: float | None = None
) -> HacEstimate:
    """``c H^-1 Omega_hat H^-1`` of any estimator defined by block estimating functions.

    An estimate ``x_hat`` that zeroes ``sum_k s_k(x)`` (least squares: ``s_k = b_k -
    A_k x``; a Gauss-Newton fit: the blocks' gradients) with ``H = -d sum_k s_k / dx``
    has ``Cov = H^-1 Omega H^-1``, ``Omega`` the long-run covariance of the block scores
    (module docstring: Bartlett weights, Andrews bandwidth on the influences
    ``H^-1 s_k``, correction ``c`` from the block shares ``tr(H_k H^-1) / tr(I)``).

    Parameters
    ----------
    scores : array_like
        Block scores ``s_k`` at the estimate in sample order, shape (B, p).
    bread : array_like
        ``H^-1`` (a pseudo-inverse where ``H`` is singular), shape (p, p), symmetric.
    block_information : array_like
        Each block's ``H_k`` (``sum_k H_k = H``), shape (B, p, p).
    bandwidth : float or None
        ``S`` [blocks]; None: automatic (:func:`andrews_bandwidth`).
    """
    s = as_float_array(scores, "scores", ndim=2)
    Hinv = as_float_array(bread, "bread", ndim=2)
    Hk = as_float_array(block_information, "block_information", ndim=3)
    B, p = s.shape
    if Hinv.shape != (p, p) or Hk.shape != (B, p, p):
        raise InputError(
            f"scores.shape={s.shape}, bread.shape={Hinv.shape} and "
            f"block_information.shape={Hk.shape} do not agree"
        )
    g = s @ Hinv  # block influences H^-1 s_k (H^-1 symmetric)
    S = andrews_bandwidth(g) if bandwidth is None else float(bandwidth)
    omega = long_run_covariance(s, S)
    lev = np.einsum("kab,ab->k", Hk, Hinv)  # tr(H_k H^-1)
    shares = lev / lev.sum() if lev.sum() > 0 else np.full(B, 1.0 / B)
    c = _correction(shares, S)
    cov = c * (Hinv @ omega @ Hinv)
    return HacEstimate(covariance=0.5 * (cov + cov.T), bandwidth=S, correction=c, n_blocks=B)


def correlations_scaled(white, std, *, floor: bool = True) -> np.ndarray:
    """The white covariance's correlations with the standard deviations ``std``.

    ``C_ab = W_ab f_a f_b``, ``f_a = std_a / sqrt(W_aa)`` (at least 1 with ``floor``):
    the honest std on the diagonal, the white-noise correlations off it (the full
    block-score matrix of a few runs is noisy off the diagonal). Shapes (p, p), (p,).
    """
    W = as_float_array(white, "white", ndim=2)
    sw = np.sqrt(np.clip(np.diag(W), 0.0, None))
    sd = as_float_array(std, "std", ndim=1)
    f = np.divide(sd, sw, out=np.ones_like(sw), where=sw > 0)
    f = np.maximum(f, 1.0) if floor else f
    return W * np.outer(f, f)


# ------------------------------------------------------------------ entry points
def _std(cov: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def inflation(std, std_white) -> float | None:
    """Median over parameters of ``std / std_white`` (those with ``std_white > 0``)."""
    std, std_white = np.asarray(std, float), np.asarray(std_white, float)
    ok = (std_white > 0) & np.isfinite(std_white) & np.isfinite(std)
    return float(np.median(std[ok] / std_white[ok])) if ok.any() else None


def _fallback(blocks: ScoreBlocks | None, min_blocks: int) -> str:
    """Why ``"auto"`` cannot use ``"hac"`` ("" when it can)."""
    if blocks is None:
        return "the accumulated sums hold no per-block record (blocks were not recorded)"
    if blocks.n_blocks < min_blocks:
        return (
            f"{blocks.n_blocks} blocks of contiguous samples, fewer than the {min_blocks} "
            "an autocorrelation-consistent covariance needs (too few samples)"
        )
    return ""


def estimate_uncertainty(
    acc: InformationAccumulator,
    estimate,
    white_covariance,
    information_inverse,
    *,
    weights=None,
    options: UncertaintyOptions | str | dict | None = None,
) -> Uncertainty:
    """The covariance of ``estimate`` by the method of ``options`` (module docstring).

    Parameters
    ----------
    acc : InformationAccumulator
        The sums behind the estimate; ``acc.blocks`` for ``"hac"``.
    estimate : array_like
        ``theta_hat``, shape (p,).
    white_covariance : array_like
        The white-noise covariance of the solve, shape (p, p).
    information_inverse : array_like
        ``A^-1`` of the solve, shape (p, p).
    weights : array_like or None
        Per-joint weights of a weighted solve, shape (nv,).
    options : UncertaintyOptions, str, dict or None
        The method and its settings; default ``"auto"``.
    """
    opts = UncertaintyOptions.from_value(options)
    white = as_float_array(white_covariance, "white_covariance", ndim=2)
    std_white = _std(white)
    reason = _fallback(acc.blocks, int(opts.min_blocks)) if opts.method != WHITE else ""
    if opts.method == HAC and acc.blocks is None:
        raise InputError(f"uncertainty='hac' but {reason}")
    if opts.method == WHITE or (opts.method == AUTO and reason):
        return Uncertainty(
            covariance=white,
            std=std_white,
            covariance_white=white,
            std_white=std_white,
            method=WHITE,
            requested=opts.method,
            inflation=inflation(std_white, std_white),
            n_blocks=0 if acc.blocks is None else acc.blocks.n_blocks,
            reason=reason,
        )
    assert acc.blocks is not None  # by _fallback / the check above
    hac = hac_covariance(
        acc.blocks, estimate, information_inverse, weights=weights, bandwidth=opts.bandwidth
    )
    std = _std(hac.covariance)
    return Uncertainty(
        covariance=hac.covariance,
        std=std,
        covariance_white=white,
        std_white=std_white,
        method=HAC,
        requested=opts.method,
        bandwidth=hac.bandwidth,
        inflation=inflation(std, std_white),
        n_blocks=hac.n_blocks,
        block_samples=float(acc.blocks.counts.mean()),
        correction=hac.correction,
    )


def solution_uncertainty(
    acc: InformationAccumulator,
    solution: LeastSquaresSolution,
    options: UncertaintyOptions | str | dict | None = None,
    *,
    estimate=None,
    white_covariance=None,
) -> Uncertainty:
    """:func:`estimate_uncertainty` of a :func:`~manip_id.estimators.batch.solve_accumulator`
    solution on the same sums (OLS: ``A^-1 = covariance / sigma2``; WLS: the covariance
    is ``A_w^-1`` with the solution's weights).

    ``estimate`` and ``white_covariance``: another estimate on the same data and its
    white-noise covariance (an online law's final estimate); default the solution's.
    """
    if solution.weights is not None:
        Ainv = solution.covariance
    elif solution.sigma2 > 0:
        Ainv = solution.covariance / solution.sigma2
    else:  # a noise-free fit: the scores vanish, any A^-1 gives zero
        Ainv = np.linalg.pinv(acc.A)
    return estimate_uncertainty(
        acc,
        solution.estimate if estimate is None else estimate,
        solution.covariance if white_covariance is None else white_covariance,
        Ainv,
        weights=solution.weights,
        options=options,
    )
